"""Multi-agent RL on ``TorchRLFleetEnv``: BenchMARL tasks, residual envs by name, saved policies.

- ``agents.marl.envs.make_env``: a ``TorchRLFleetEnv`` whose base policy is given
  by name (``"nn_dsc"``), resolved here because the env layer imports no policy.
- ``agents.marl.tasks``: the BenchMARL ``CpfTask`` enum (the paper's scenarios
  and the benchmark suite), its ``CpfTaskClass`` and task YAML configs; importing
  it also registers the tasks under ``cpf/<name>`` for BenchMARL's Hydra loader.
- ``agents.marl.compat``: imports BenchMARL 1.5 beside TorchRL 0.14 (one alias).
- ``agents.marl.policy_folder``: a trained BenchMARL actor saved as data
  (safetensors and JSON) and loaded as a ``cpf-bench`` policy.

Nothing here is imported by ``import agents``; the modules need the ``torchrl``
extra, and ``tasks`` also BenchMARL (``docs/marl.md`` gives the install lines).
"""
