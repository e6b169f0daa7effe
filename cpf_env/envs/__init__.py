"""The environments users step: views of one ``FleetSim`` in each ecosystem's API.

What lives here: the PettingZoo ``ParallelEnv`` (``parallel``) and its AEC
form (``aec``), the Gymnasium single-agent views and their registration
(``gym_envs``), the batched views they share (``views``), rendering
(``render``), the policy contract every policy implements (``policy``), the
residual composition of a base policy and a learned correction
(``residual``) with its ParallelEnv wrapper (``wrappers``), and
the native TorchRL env (``torchrl_env``, needs the ``torchrl`` extra and is
not imported by ``cpf_env``).

What it may import: ``cpf_env.model``, ``cpf_env.scenarios`` and
``cpf_env.sim``. No policy code: a base policy reaches ``residual`` as an
object that meets the contract of ``policy``.
"""
