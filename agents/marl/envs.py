"""``make_env``: a ``TorchRLFleetEnv`` with its base policy given by name.

The env layer (``cpf_env.envs.torchrl_env``) takes a base policy object and
imports no policy code; names resolve in ``agents.resolve``, as on every
learning route, with ``FleetVecEnv``'s defaults (residual on ``"nn_dsc"``,
stagger on).

Example:
    >>> env = make_env("bench_lossy_links", num_fleets=2, seed=0, max_steps=50)
    >>> env.full_action_spec["vessel", "action"].shape  # force residual, k = 3
    torch.Size([2, 5, 3])
"""

from __future__ import annotations

from typing import Any

from agents.resolve import resolve_base_policy
from cpf_env.envs.core import DEFAULT_INFO_LEVEL
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.torchrl_env import TorchRLFleetEnv
from cpf_env.scenarios import Scenario, make_scenario

__all__ = ["make_env"]


def make_env(
    scenario: str | Scenario = "wang2014",
    num_fleets: int = 64,
    base_policy: str | FleetPolicy | None = "nn_dsc",
    residual: ResidualConfig | None = None,
    stagger: bool = True,
    info_level: str = DEFAULT_INFO_LEVEL,
    policy_options: dict[str, Any] | None = None,
    **options: Any,
) -> TorchRLFleetEnv:
    """A residual ``TorchRLFleetEnv`` over a base policy given by name (``FleetVecEnv``'s).

    Args:
        scenario: A registered name or a ``Scenario``.
        num_fleets: B.
        base_policy: A name of ``baselines.POLICIES``, a policy object, or None /
            ``"none"``: the learner commands forces and theta_dot itself, as
            fractions of their limits (``cpf_env.envs.residual.learner_config``).
        residual: The residual composition (default: forces, scale 0.2, no extras).
        stagger: Spread the horizons over the fleets (``EpisodeCore``).
        info_level: ``"none"`` (default), ``"minimal"`` or ``"full"``.
        policy_options: Options (gains) of a base policy given by name.
        **options: ``TorchRLFleetEnv``'s own (``device``, ``seed``, ``normalize``,
            ``normalization_steps``, ``state``) and ``Scenario`` field overrides.

    Raises:
        ValueError: An unknown base policy name (or any error of ``TorchRLFleetEnv``).
    """
    env_options = {"device", "seed", "normalize", "normalization_steps", "state"}
    own = {key: value for key, value in options.items() if key in env_options}
    overrides = {key: value for key, value in options.items() if key not in env_options}
    resolved = make_scenario(scenario, **overrides)
    return TorchRLFleetEnv(
        resolved,
        num_fleets,
        resolve_base_policy(base_policy, resolved, policy_options),
        ResidualConfig() if residual is None else residual,
        stagger,
        info_level,
        **own,
    )
