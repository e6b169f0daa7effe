"""Name resolution for the learning routes, in one place: scenario, base policy, residual.

Every route of ``agents`` (``FleetVecEnv`` and its mixture, the TorchRL env by
name, the BenchMARL tasks, the PettingZoo task route, loaded policies) builds
its episodes through ``make_core``:

- the scenario: a registered name or a ``Scenario``, with field overrides
  (``cpf_env.scenarios.make_scenario``);
- the base policy: a name of ``baselines.DEPLOYABLE`` (built with
  ``policy_options``; a base of ``agents.envs.fleetwise.WHOLE_BATCH_BASES``, ``mpc``,
  as a ``FleetwiseBase``, one instance per fleet, since the vector envs restart
  single fleets), ``None`` or ``"none"`` (no base: the learner commands
  everything), or a policy object;
- the residual: ``ResidualConfig()`` unless given; with no base policy the
  rule of ``cpf_env.envs.residual.learner_config`` (forces and rate as
  fractions of their limits, ``mode="force_and_rate"``, ``scale=1``).

One rule on every learning route, of either layer: the base policy defaults
to None (the learner commands everything, a plain task as Gymnasium and
PettingZoo users expect), and a policy object is accepted everywhere. Names
are resolved here; the env layer (``cpf_env.envs``) imports no policy code,
so it refuses a name with a message pointing to this layer.

Example:
    >>> core = make_core("wang2014", 2, base_policy="none", max_steps=50)
    >>> core.controller.config.mode, core.action_size
    ('force_and_rate', 4)
"""

from __future__ import annotations

from typing import Any

from agents.envs.fleetwise import WHOLE_BATCH_BASES, FleetwiseBase
from baselines import DEPLOYABLE, make_policy
from cpf_env.envs.core import EpisodeCore
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.scenarios import Scenario, make_scenario

__all__ = ["learner_base", "make_core", "resolve_base_policy"]


def resolve_base_policy(
    base_policy: str | FleetPolicy | None,
    scenario: Scenario,
    policy_options: dict[str, Any] | None = None,
) -> FleetPolicy | None:
    """A base policy from a name of ``baselines.DEPLOYABLE``, an object, or None/``"none"``.

    Raises:
        ValueError: An unknown name (the valid ones are listed).
        TypeError: Neither a name, None nor a policy object.
    """
    if base_policy is None or base_policy == "none":
        return None
    if isinstance(base_policy, str):
        if base_policy not in DEPLOYABLE:
            raise ValueError(
                f"unknown base policy {base_policy!r}; choose one of {sorted(DEPLOYABLE)} "
                "or None (the agent commands everything)."
            )
        return make_policy(base_policy, scenario, **(policy_options or {}))
    if not isinstance(base_policy, FleetPolicy):
        raise TypeError(
            "base_policy must be a name, None, or a policy object (act_batch, reset, "
            f"reset_fleets, diagnostics); got {type(base_policy).__name__}."
        )
    return base_policy


def learner_base(
    base_policy: str | FleetPolicy | None,
    scenario: Scenario,
    num_fleets: int,
    policy_options: dict[str, Any] | None = None,
) -> FleetPolicy | None:
    """The base of a learner's env of ``num_fleets`` fleets, which restarts single fleets.

    A name of ``WHOLE_BATCH_BASES`` runs as a ``FleetwiseBase`` (one instance per
    fleet); anything else as ``resolve_base_policy`` gives it.
    """
    if isinstance(base_policy, str) and base_policy in WHOLE_BATCH_BASES:
        return FleetwiseBase(base_policy, scenario, num_fleets, policy_options)
    return resolve_base_policy(base_policy, scenario, policy_options)


def make_core(
    scenario: str | Scenario,
    num_fleets: int,
    base_policy: str | FleetPolicy | None = None,
    residual: ResidualConfig | None = None,
    stagger: bool = True,
    policy_options: dict[str, Any] | None = None,
    **overrides: Any,
) -> EpisodeCore:
    """The episode core of a learning route: always the residual form (see the module)."""
    resolved = make_scenario(scenario, **overrides)
    base = learner_base(base_policy, resolved, num_fleets, policy_options)
    config = ResidualConfig() if residual is None else residual
    return EpisodeCore(resolved, num_fleets, base, config, stagger)
