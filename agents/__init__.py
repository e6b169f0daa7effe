"""The learning side: residual RL with Stable-Baselines3 on top of the analytic policies.

- ``FleetVecEnv``: a native SB3 ``VecEnv`` over one batched ``FleetSim``, one slot
  per vessel (parameter sharing), the base policy run batched underneath.
- ``train`` / ``TrainConfig``: PPO or SAC, residual or from scratch (``cpf-train``).
- ``load_policy``: a ``cpf-train`` output folder as a policy with the analytic
  policies' interface (``reset``, ``act``, ``act_batch``, ``predict``), so trained
  and analytic controllers are evaluated by the same code.

See ``docs/residual_rl.md``.
"""

from __future__ import annotations

from agents.loading import TrainedPolicy, load_policy
from agents.training import TrainConfig, train
from agents.vec_env import FleetVecEnv

__all__ = ["FleetVecEnv", "TrainConfig", "TrainedPolicy", "load_policy", "train"]
