"""Per-step reward of a vessel and the weights that shape it.

Reward of vessel i for one control step (docs/environment.md, "Reward"):

    r_i = -dt * ( w_pos ||z1_xy||^2 + w_head z1_psi^2 + w_sync s_i^2
                  + w_speed (theta_dot_i - v0)^2 + w_tau ||tau_i / tau_max||^2 )

with s_i = sum_j a_ij (theta_i - theta_j) on true path variables, z1 the
body-frame path error after the step, tau_i the applied (saturated) force and
tau_max the per-axis magnitude limit max(|tau_min|, |tau_max|). With a team
reward every vessel receives the fleet mean.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["RewardWeights"]


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms (defaults: path following first, effort barely).

    Attributes:
        position: On ||z1_xy||^2 (1/m^2).
        heading: On the wrapped heading error squared (1/rad^2).
        sync: On the synchronization error s_i^2.
        speed: On (theta_dot_i - v0)^2 (s^2/m^2).
        effort: On the normalized applied force ||tau / tau_max||^2.
        team: If True, every vessel gets the fleet-mean reward.
    """

    position: float = 1.0
    heading: float = 0.1
    sync: float = 1.0
    speed: float = 1.0
    effort: float = 0.01
    team: bool = False

    def __post_init__(self) -> None:
        for field in fields(self)[:5]:
            value = getattr(self, field.name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(
                    f"RewardWeights.{field.name} must be a finite number >= 0, got {value}."
                )

    def encode(self) -> NDArray[np.float64]:
        """Weights as a (5,) array in the order position, heading, sync, speed, effort."""
        return np.array([self.position, self.heading, self.sync, self.speed, self.effort])


@numba.njit(cache=True, inline="always")
def step_reward(
    weights: NDArray,
    dt: float,
    z1: NDArray,
    sync_error: float,
    speed_error: float,
    tau: NDArray,
    tau_scale: NDArray,
) -> float:
    """Reward of one vessel for one control step (see module docstring).

    Args:
        weights: ``RewardWeights.encode()``, shape (5,).
        dt: Control period (s).
        z1: Body-frame path error after the step, shape (3,).
        sync_error: s_i on true path variables.
        speed_error: theta_dot_i - v0 (m/s).
        tau: Applied force, shape (3,).
        tau_scale: Per-axis normalization max(|tau_min|, |tau_max|), shape (3,).
    """
    effort = 0.0
    for k in range(3):
        effort += (tau[k] / tau_scale[k]) ** 2
    cost = (
        weights[0] * (z1[0] * z1[0] + z1[1] * z1[1])
        + weights[1] * z1[2] * z1[2]
        + weights[2] * sync_error * sync_error
        + weights[3] * speed_error * speed_error
        + weights[4] * effort
    )
    return -dt * cost
