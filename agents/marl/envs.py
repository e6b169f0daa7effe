"""``make_env``: a ``TorchRLFleetEnv`` with its base policy given by name.

The env layer (``cpf_env.envs.torchrl_env``) takes a base policy object and
imports no policy code; names resolve in ``agents.envs.resolve``, as on every
learning route, with ``FleetVecEnv``'s defaults (no base policy: the learner
commands forces and path rate itself; stagger on).

Example:
    >>> env = make_env("bench_lossy_links", 2, "nn_dsc", seed=0, max_steps=50)
    >>> env.full_action_spec["vessel", "action"].shape  # force residual, k = 3
    torch.Size([2, 5, 3])
"""

from __future__ import annotations

from typing import Any

from agents.envs.resolve import learner_base
from cpf_env.envs.core import DEFAULT_INFO_LEVEL, check_flag
from cpf_env.envs.input_statistics import InputStatistics, estimate_input_statistics
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.torchrl_env import StateFeatures, TorchRLFleetEnv
from cpf_env.evaluation.privileged import UNOBSERVED_SIZE, unobserved_state
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.fleet import observation_layout

__all__ = ["make_env"]


def make_env(
    scenario: str | Scenario = "wang2014",
    num_fleets: int = 64,
    base_policy: str | FleetPolicy | None = None,
    residual: ResidualConfig | None = None,
    stagger: bool = True,
    info_level: str = DEFAULT_INFO_LEVEL,
    policy_options: dict[str, Any] | None = None,
    shared_slot_statistics: bool = False,
    privileged_state: bool = False,
    **options: Any,
) -> TorchRLFleetEnv:
    """A residual ``TorchRLFleetEnv`` over a base policy given by name (``FleetVecEnv``'s).

    Args:
        scenario: A registered name or a ``Scenario``.
        num_fleets: B.
        base_policy: A name of ``baselines.DEPLOYABLE``, a policy object, or None /
            ``"none"``: the learner commands forces and theta_dot itself, as
            fractions of their limits (``cpf_env.envs.residual.learner_config``).
        residual: The residual composition (default: forces, scale 0.2, no extras).
        stagger: Spread the horizons over the fleets (``EpisodeCore``).
        info_level: ``"none"`` (default), ``"minimal"`` or ``"full"``.
        policy_options: Options (gains) of a base policy given by name.
        shared_slot_statistics: With ``normalize=True``, scale every neighbour slot
            with the slots' pooled statistics and leave the links' weights a_ij raw
            (``agents.envs.slot_statistics.shared_slot_statistics``, ``raw_weights=True``):
            the inputs a ``NeighbourSetEncoder`` reads (``agents.marl.models``).
        privileged_state: With ``state=True``, append to the global ``"state"`` what no
            vessel observes (``cpf_env.evaluation.privileged.unobserved_state``: the true
            lumped force over the force scale, v0, theta_i minus the fleet's mean; 5 per
            vessel): [B, 15 n], for an asymmetric actor-critic.
        **options: ``TorchRLFleetEnv``'s own (``device``, ``seed``, ``normalize``,
            ``normalization_steps``, ``state``) and ``Scenario`` field overrides.

    Raises:
        ValueError: An unknown base policy name, ``shared_slot_statistics`` without
            ``normalize=True``, ``privileged_state`` without ``state=True`` (or any
            error of ``TorchRLFleetEnv``).
    """
    env_options = {"device", "seed", "normalize", "normalization_steps", "state"}
    own = {key: value for key, value in options.items() if key in env_options}
    overrides = {key: value for key, value in options.items() if key not in env_options}
    if check_flag(privileged_state, "privileged_state") and own.get("state") is not True:
        raise ValueError(
            "privileged_state=True appends to the global state, which is off: pass state=True "
            "as well, or leave privileged_state off."
        )
    if privileged_state:
        own["extra_state"] = StateFeatures(UNOBSERVED_SIZE, unobserved_state)
    resolved = make_scenario(scenario, **overrides)
    base = learner_base(base_policy, resolved, num_fleets, policy_options)
    residual = ResidualConfig() if residual is None else residual
    if shared_slot_statistics:
        if own.get("normalize") is not True:
            raise ValueError("shared_slot_statistics=True pools the statistics of normalize=True.")
        own["normalize"] = _shared_slot_statistics(
            resolved, base, residual, own.get("normalization_steps", 200)
        )
    return TorchRLFleetEnv(resolved, num_fleets, base, residual, stagger, info_level, **own)


def _shared_slot_statistics(
    scenario: Scenario, base: FleetPolicy | None, residual: ResidualConfig, steps: int
) -> InputStatistics:
    """The env's input statistics (as ``normalize=True`` estimates them), slots pooled."""
    from agents.envs.slot_statistics import shared_slot_statistics

    estimated = estimate_input_statistics(scenario, base, residual, steps=steps)
    layout = residual.learner_layout(observation_layout(scenario))
    mean, var = shared_slot_statistics(
        estimated.mean, estimated.var, layout.n_slots, layout.slot_size, raw_weights=True
    )
    return InputStatistics(mean, var, estimated.epsilon, estimated.clip)
