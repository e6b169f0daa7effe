"""Training a residual (or from-scratch) agent with Stable-Baselines3, as ``cpf-train`` does.

- ``config``: ``TrainConfig``, everything that defines a run, checked before it runs;
- ``trainer``: ``train``, one run from a configuration to an agent folder;
- ``algorithms``: the SB3 algorithms by name, the vector env and the model;
- ``run_folder``, ``schedule``, ``checkpoint``, ``snapshot``: a run in its folder, what
  happens between rollouts, and resuming bit for bit from data-only checkpoints;
- ``evaluation``: the held-out evaluation on the validation seeds;
- ``init_from``: starting from an agent folder (fine-tuning a distilled student);
- ``device``: the torch device from the user's ``--device``.
"""
