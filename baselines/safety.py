"""A safety filter under any analytic policy: a control barrier function on the separation.

Where paths cross (``cpf_env.scenarios.crossing``, ``Scenario.separation``)
the path-following designs steer every vessel straight at its partner: they
know nothing of other hulls. The classic remedy is a safety filter (Ames et
al. 2019): keep the design's command wherever it is safe, and change it as
little as possible where it is not.

What a vessel knows of a neighbour j is what j broadcasts: the filter makes
every vessel send, in message entries 1-5 (after the design's own entry 0),
a flag 1 (a packet was received), its position p (m) and its velocity over
ground v (m/s), all in the earth frame, from its own observation (the pose
of its path frame; on a navigation filter, ``baselines.estimator``, the
estimate). A receiver advances j's position by the packet's age at j's
velocity. Neighbours never heard from, and vessels that are not neighbours,
are unseen: messages travel only over the graph's links, with their losses
and delays.

Per heard neighbour the filter keeps the barrier distance d_b with the
second-order barrier condition of ``baselines.barrier``, on the vessel's
nominal model: the force closest to the design's that keeps the condition,
within the limits.

The barrier distance d_b is not the keep-out distance d_safe: between the
two the cost charges a pass, but keeping d_safe takes path error that costs
more. With the default gains (``BARRIER_GAINS``) the cost on
``hard_crossing``'s training seeds falls as d_b approaches the collision
distance (``studies/hard_track/safety_tuning.py``); the default keeps
``BARRIER_MARGIN`` (0.2 m) outside it, for the position errors of a
navigation filter and the age of a neighbour's packet. The path-variable
rate and the design's own message pass through unchanged.

``SafetyFiltered`` wraps a design (``nn_dsc_safe``, ``mpc_tuned_safe``);
``mpc_tuned_ekf_safe`` runs the navigation filter (``baselines.estimator``)
under both. The scenario must carry at least
``SAFETY_MESSAGE`` message entries (``Scenario.message_size``) and a bound
``message_max`` above the positions it sails through.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numba
import numpy as np
from numpy.typing import ArrayLike

from baselines.barrier import BARRIER_GAINS, BARRIER_MARGIN, barrier_filter
from baselines.estimator import Filtered
from baselines.mpc_tuned import MPCTuned
from baselines.nn_dsc import NNDSCPolicy
from baselines.policy import resolve_scenario
from cpf_env.envs.policy import Array, FleetPolicy
from cpf_env.model.paths import encode_paths, path_values
from cpf_env.model.separation import Separation
from cpf_env.sim.observation import (
    NU,
    SLOT_AGE,
    SLOT_MSG,
    SLOT_WEIGHT,
    SLOTS,
    THETA,
    Z1,
    frame_pose,
)

__all__ = [
    "SAFETY_MESSAGE",
    "MPCTunedFilteredSafe",
    "MPCTunedSafe",
    "NNDSCSafe",
    "SafetyFiltered",
]

#: Message entries the filter needs: the design's entry 0, then flag, x, y, vx, vy.
SAFETY_MESSAGE = 6


@numba.njit(cache=True)
def filter_forces(
    obs: np.ndarray,
    actions: np.ndarray,
    kinds: np.ndarray,
    paths: np.ndarray,
    nominal: np.ndarray,
    tau_min: np.ndarray,
    tau_max: np.ndarray,
    distance: float,
    gains: np.ndarray,
    dt: float,
) -> None:
    """Write each vessel's broadcast and filter its force in place (module docstring).

    Args:
        obs: (B, n, obs_dim) observations (the slots' messages at ``SLOT_MSG``).
        actions: (B, n, 4 + m) the design's actions; forces and message entries 1-5
            are overwritten.
        kinds: (n,) path kinds.
        paths: (n, PATH_PARAM_SIZE) encoded paths.
        nominal: (n, PARAM_SIZE) nominal vessel parameters.
        tau_min: (n, 3) lower force limits (N, N, N m).
        tau_max: (n, 3) upper force limits (N, N, N m).
        distance: d_b (m), the distance the barrier keeps.
        gains: (2,) k1, k2 (1/s).
        dt: Control period (s).
    """
    B, n = obs.shape[0], obs.shape[1]
    m = actions.shape[2] - 4
    width = SLOT_MSG + m
    slots = (obs.shape[2] - SLOTS) // width
    heard = np.empty((max(slots, 1), 4))
    for b in range(B):
        for i in range(n):
            o = obs[b, i]
            point = path_values(kinds[i], paths[i], o[THETA])[0]
            x, y, psi = frame_pose(point, o[Z1], o[Z1 + 1], o[Z1 + 2])
            c, s = math.cos(psi), math.sin(psi)
            nu = o[NU : NU + 3]
            out = actions[b, i]
            out[5], out[6], out[7] = 1.0, x, y
            out[8], out[9] = c * nu[0] - s * nu[1], s * nu[0] + c * nu[1]
            count = 0
            for k in range(slots):
                base = SLOTS + k * width
                if o[base + SLOT_WEIGHT] == 0.0 or o[base + SLOT_MSG + 1] < 0.5:
                    continue  # not a neighbour now, or never heard from
                age = o[base + SLOT_AGE] * dt
                jvx, jvy = o[base + SLOT_MSG + 4], o[base + SLOT_MSG + 5]
                heard[count, 0] = o[base + SLOT_MSG + 2] + age * jvx
                heard[count, 1] = o[base + SLOT_MSG + 3] + age * jvy
                heard[count, 2], heard[count, 3] = jvx, jvy
                count += 1
            barrier_filter(out[:3], x, y, psi, nu, nominal[i], heard,
                           count, distance, gains[0], gains[1], tau_min[i], tau_max[i])  # fmt: skip


class SafetyFiltered(FleetPolicy):
    """An analytic policy under the separation's safety filter (module docstring).

    Subclasses name the policy (``name``) and the design it filters (``inner``).

    Args:
        env: An env, a simulator or a ``Scenario`` (``resolve_scenario``).
        barrier_distance: d_b (m), the distance the barrier keeps, above the separation's
            hard distance; default hard distance + ``BARRIER_MARGIN``.
        barrier_gains: k1, k2 of the barrier condition (1/s), > 0.
        **options: Passed to the inner policy.

    Raises:
        ValueError: The scenario's messages cannot carry the broadcast, or the barrier
            distance is not above the collision distance.
    """

    name: ClassVar[str]
    inner: ClassVar[type[FleetPolicy]]

    def __init__(
        self,
        env: object,
        barrier_distance: float | None = None,
        barrier_gains: tuple[float, float] = BARRIER_GAINS,
        **options: Any,
    ) -> None:
        scenario = resolve_scenario(env)
        if scenario.message_size < SAFETY_MESSAGE:
            raise ValueError(
                "the safety filter broadcasts a flag, its position and its velocity in "
                f"message entries 1-5, but {scenario.name!r} has message_size = "
                f"{scenario.message_size}; use a scenario with message_size >= "
                f"{SAFETY_MESSAGE} (the crossing scenarios of cpf_env.scenarios.hard have it)."
            )
        self.policy = self.inner(env, **options)  # type: ignore[call-arg]
        self.n = self.policy.n
        self.obs_dim = self.policy.obs_dim
        self.act_dim = self.policy.act_dim
        self.message_entries = SAFETY_MESSAGE
        self.agents = self.policy.agents
        kinds, paths = encode_paths(scenario.paths)
        self._kinds = np.ascontiguousarray(kinds, dtype=np.int64)
        self._paths = np.ascontiguousarray(paths, dtype=np.float64)
        self._nominal = np.stack([model.to_params() for model in scenario.vessel_models])
        tau_min, tau_max = scenario.tau_limits
        self._tau_min = np.ascontiguousarray(tau_min, dtype=np.float64)
        self._tau_max = np.ascontiguousarray(tau_max, dtype=np.float64)
        separation = scenario.separation or Separation()
        if barrier_distance is None:
            barrier_distance = separation.hard_distance + BARRIER_MARGIN
        if not separation.hard_distance < barrier_distance:
            raise ValueError(
                f"barrier_distance = {barrier_distance!r} m must exceed the separation's "
                f"hard_distance of {separation.hard_distance} m (the collision distance)."
            )
        self.barrier_distance = float(barrier_distance)
        self._gains = np.array(barrier_gains, dtype=np.float64)
        if self._gains.shape != (2,) or not np.all(self._gains > 0.0):
            raise ValueError(
                f"barrier_gains must be two gains k1, k2 > 0 (1/s), got {barrier_gains!r}."
            )
        self._dt = float(scenario.dt)
        self.diagnostics: dict[str, Array] = {}

    def reset(self, seed: int | None = None) -> None:
        """Reset the inner design (the filter itself is stateless)."""
        self.policy.reset(seed)

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Reset the inner design's states of the listed fleets."""
        self.policy.reset_fleets(fleets)

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """The inner design's actions, with the broadcast written and the force filtered."""
        batch = np.ascontiguousarray(obs, dtype=np.float64)
        actions = np.array(self.policy.act_batch(obs, fleets), dtype=np.float64)
        filter_forces(batch, actions, self._kinds, self._paths, self._nominal, self._tau_min,
                      self._tau_max, self.barrier_distance, self._gains, self._dt)  # fmt: skip
        self.diagnostics = dict(self.policy.diagnostics)
        return actions


class NNDSCSafe(SafetyFiltered):
    """``nn_dsc`` under the safety filter."""

    name = "nn_dsc_safe"
    inner = NNDSCPolicy


class MPCTunedSafe(SafetyFiltered):
    """``mpc_tuned`` under the safety filter."""

    name = "mpc_tuned_safe"
    inner = MPCTuned


class MPCTunedFilteredSafe(Filtered):
    """``mpc_tuned`` under the safety filter, both on the navigation filter's estimate."""

    name = "mpc_tuned_ekf_safe"
    inner = MPCTunedSafe
