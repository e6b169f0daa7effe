"""``make_env``: a ``TorchRLFleetEnv`` with its base policy given by name.

The env layer (``cpf_env.envs.torchrl_env``) takes a base policy object and
imports no policy code; this is the layer that may import ``baselines``.

Example:
    >>> env = make_env("bench_lossy_links", num_fleets=2, base="nn_dsc", seed=0, max_steps=50)
    >>> env.full_action_spec["vessel", "action"].shape  # force residual, k = 3
    torch.Size([2, 5, 3])
"""

from __future__ import annotations

from typing import Any

import torch

from agents.vec_env import resolve_base_policy
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.parallel import make_scenario
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.torchrl_env import TorchRLFleetEnv
from cpf_env.scenarios import Scenario

__all__ = ["make_env"]


def make_env(
    scenario: str | Scenario,
    num_fleets: int,
    base: str = "nn_dsc",
    residual: ResidualConfig | None = None,
    policy_options: dict[str, Any] | None = None,
    seed: int | None = None,
    device: str | torch.device = "cpu",
    normalize: bool | InputStatistics = False,
    normalization_steps: int = 200,
    state: bool = False,
    info_level: str = "none",
    stagger: bool = False,
    **overrides: Any,
) -> TorchRLFleetEnv:
    """A residual ``TorchRLFleetEnv`` over a named base policy (``FleetVecEnv``'s arguments).

    Args:
        scenario: A registered name or a ``Scenario``.
        num_fleets: B.
        base: A name of ``baselines.POLICIES``, or ``"none"``: the learner commands
            forces and theta_dot itself, as fractions of their limits
            (``mode="force_and_rate"``, scale 1), as ``FleetVecEnv`` does.
        residual: The residual composition (default: forces, scale 0.2, no extras).
        policy_options: Options (gains) of the base policy.
        seed: Fleet k starts from seed + k (``TorchRLFleetEnv.set_seed``).
        device: Where the outputs live.
        normalize: See ``TorchRLFleetEnv``.
        normalization_steps: See ``TorchRLFleetEnv``.
        state: Output the global ``"state"`` for centralized critics.
        info_level: ``"none"`` or ``"minimal"``.
        stagger: Spread the first episodes' ends over the fleets (``TorchRLFleetEnv``).
        **overrides: ``Scenario`` field overrides (e.g. ``max_steps``).

    Raises:
        ValueError: An unknown base policy name (or any error of ``TorchRLFleetEnv``).
    """
    resolved = make_scenario(scenario, **overrides)
    base_policy = resolve_base_policy(None if base == "none" else base, resolved, policy_options)
    if base_policy is None:
        residual = ResidualConfig(mode="force_and_rate", scale=1.0)
    return TorchRLFleetEnv(
        resolved,
        num_fleets=num_fleets,
        info_level=info_level,
        device=device,
        seed=seed,
        base_policy=base_policy,
        residual=residual if residual is not None else ResidualConfig(),
        normalize=normalize,
        normalization_steps=normalization_steps,
        state=state,
        stagger=stagger,
    )
