"""``cpf-run``: one scenario with one policy, the paper's figures and claims.

``cli`` is the command; ``experiment`` runs an episode and records its
trajectory; ``figures`` draws the equivalents of the paper's Figs. 3-7;
``reproduce`` checks the paper's claims against a recorded run.

What it may import: ``cpf_env``, ``baselines``, ``agents`` and
``cpf_commands.common``.
"""
