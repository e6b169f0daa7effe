"""The environments users step: adapters of one episode core to each library's API.

What lives here: the episode core every route stands on (``core``:
seeding, horizons, stagger, per-fleet resets, residual composition, terminal
observations, infos as arrays), the PettingZoo ``ParallelEnv`` (``parallel``)
and its AEC form (``aec``), the Gymnasium single-agent views and their
registration (``gym_envs``), render plumbing (``views``, ``render``), the
policy contract every policy implements (``policy``), the residual
composition of a base policy and a learned correction (``residual``), the
frozen input statistics of a learner (``input_statistics``) and the native
TorchRL env (``torchrl_env``, ``torchrl_specs``; need the ``torchrl`` extra and
are not imported by ``cpf_env``).

What it may import: ``cpf_env.infra``, ``cpf_env.model``,
``cpf_env.scenarios`` and ``cpf_env.sim``. No policy code: a base policy
reaches the core as an object that meets the contract of ``policy``.
"""
