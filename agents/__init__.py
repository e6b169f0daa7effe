"""Stable-Baselines3 side of cpf_env: residual RL on top of the reference policy.

Planned (docs/residual_rl.md): ``FleetVecEnv``, a native SB3
``VecEnv`` over B fleets x n vessels with parameter sharing, training
(``cpf-train``) and loading of trained residual policies. Not built yet.
"""
