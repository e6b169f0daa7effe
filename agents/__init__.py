"""The learning side: residual RL with Stable-Baselines3 on top of the analytic policies.

- ``FleetVecEnv``: a native SB3 ``VecEnv`` over one batched ``FleetSim``, one slot
  per vessel (parameter sharing), the base policy run batched underneath.
- ``MixtureVecEnv``: fleets of several scenarios in one vector env (training over a
  distribution of conditions), every slot with the same padded input.
- ``train`` / ``TrainConfig``: PPO or SAC, residual or from scratch (``cpf-train``).
- ``load_policy``: a ``cpf-train`` output folder as a policy with the analytic
  policies' interface (``reset``, ``act``, ``act_batch``, ``predict``), so trained
  and analytic controllers are evaluated by the same code.

Each name is imported from its module on first use, so reading an agent folder
(``from agents import load_policy``) imports no learning algorithm: neither
Stable-Baselines3 nor the training envs.

See ``docs/residual_rl.md``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# cpf_env first: it sets OMP_WAIT_POLICY=PASSIVE (unless set) before Stable-Baselines3 loads
# torch, whose OpenMP runtime reads the variable once, when it loads. With torch's idle
# threads spinning, the simulator's threads waited for a core (docs/scaling.md, "Threads").
import cpf_env  # noqa: F401

if TYPE_CHECKING:
    from agents.envs.mixture_env import MixtureVecEnv
    from agents.envs.vec_env import FleetVecEnv
    from agents.folder.loading import TrainedPolicy, load_policy
    from agents.training.config import TrainConfig
    from agents.training.trainer import train

__all__ = ["FleetVecEnv", "MixtureVecEnv", "TrainConfig", "TrainedPolicy", "load_policy", "train"]

#: The module of each exported name, imported on first use.
_HOMES = {
    "FleetVecEnv": "agents.envs.vec_env",
    "MixtureVecEnv": "agents.envs.mixture_env",
    "TrainConfig": "agents.training.config",
    "TrainedPolicy": "agents.folder.loading",
    "load_policy": "agents.folder.loading",
    "train": "agents.training.trainer",
}


def __getattr__(name: str) -> Any:
    """The exported ``name``, imported from its module (PEP 562)."""
    if name not in _HOMES:
        raise AttributeError(f"module 'agents' has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)
