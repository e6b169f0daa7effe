"""Evaluation: what the benchmark and the commands measure on top of the simulator.

What lives here: trajectories and the paper's episode metrics
(``metrics``), the benchmark's per-episode physical metrics accumulated in
compiled passes over the fleets (``fleet_metrics``), the step records those
passes read (``recording``), and the privileged views of the true state that
the headroom references read (``privileged``, not deployable).

Why here: these modules serve the bench and the commands, not the task, so
they sit beside the simulator rather than inside it; and
``baselines.closed_loop`` records metrics from compiled code (and the
privileged references read the true state), so they must sit below
``baselines``. This layer sits above ``cpf_env.sim`` and below ``baselines``.

What it may import: ``cpf_env.infra``, ``cpf_env.model``,
``cpf_env.scenarios`` and ``cpf_env.sim``; never ``cpf_env.envs`` or any
policy.
"""
