"""``cpf-sweep``: a grid of training runs on Ray Tune, resumable, summarized.

``cli`` is the command and holds ``run_sweep``, its Python entry point; ``spec``
expands and checks the grid; ``trial`` is one Tune trial (train, then
evaluate against the base policy); ``report`` reads what the trials left on
disk and writes the summary.

What it may import: ``cpf_env``, ``baselines``, ``agents``,
``cpf_commands.common`` and ``cpf_commands.bench`` (a trial's evaluation is
a bench cell).
"""
