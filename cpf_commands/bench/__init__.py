"""``cpf-bench``: policies x scenarios x paired seeds, batched, with statistics.

``run`` holds ``run_bench``, the Python entry point, and ``cli`` the command around it;
``episodes`` runs every seed of one (policy, scenario) cell in one batched
simulator and reduces each episode to its metrics; ``stats`` holds the
interval estimators; ``report`` builds the summary rows and ``views`` the
markdown tables and figures; ``cache`` keeps the receding-horizon planners'
cells, keyed on the code ``sources`` finds they come from.

What it may import: ``cpf_env``, ``baselines``, ``agents`` and
``cpf_commands.common``.
"""
