"""Local observation of one vessel: layout and the compiled builder.

Vessel i observes only what is on board or arrives over its links
(``docs/environment.md``, "Observation"):

======  ===========  ===========================================================
index   name         meaning (units)
======  ===========  ===========================================================
0-2     nu           body velocity u, v, r (m/s, m/s, rad/s)
3-5     z1           J(psi)^T (eta - eta_d(theta)), heading part wrapped (m, m, rad)
6-8     t1           J(psi)^T d eta_d / d theta (m, m, rad per unit theta)
9-11    t2           J(psi)^T d2 eta_d / d theta2
12      theta        own path variable
13-15   tau          last applied (saturated) force (N, N, N m)
16      b            1 if the vessel hears the virtual leader, else 0
17      v0           leader speed as heard (m/s; 0 when b = 0)
18..    K slots      each [a_ij, theta_j - theta_i, age (steps), msg_j (m floats)]
======  ===========  ===========================================================

The slot of neighbour j holds the last packet received from j; ``a_ij = 0``
marks an empty slot (no link in the active topology, or a vessel with fewer
than K neighbours), and then the whole slot is zero. At reset every vessel
holds its neighbours' initial theta and a zero message, with age 0 (a
hand-shake before the start, even on delayed links); after that only what the
links deliver arrives.

Bounds: the components have no physical bounds the env could promise (theta
grows with time, velocities depend on the model), so every observation and
state space is ``observation_box``: float32 in [-OBS_BOUND, OBS_BOUND] with
``OBS_BOUND`` half the float32 maximum. The bounds are finite (PettingZoo's
``api_test`` and SuperSuit's ``normalize_obs`` require it) and so is their
width high - low (min-max scaling does not overflow); they are not a scale to
normalize by: use running statistics (SB3 ``VecNormalize``, Gymnasium
``NormalizeObservation``). The simulator raises before a state turns
non-finite, so observations stay inside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numba
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

__all__ = ["OBS_BOUND", "ObsLayout", "observation_box", "wrap_angle", "wrap_angles"]

#: Bound of every observation and state component (half the float32 maximum, see above).
OBS_BOUND = float(np.finfo(np.float32).max) / 2.0


def observation_box(size: int) -> spaces.Box[np.float32]:
    """The observation (or state) space of ``size`` components: the one rule for bounds.

    Args:
        size: Number of components.

    Returns:
        ``Box(-OBS_BOUND, OBS_BOUND, (size,), float32)``.
    """
    box = spaces.Box(-OBS_BOUND, OBS_BOUND, shape=(size,), dtype=np.float32)
    return cast("spaces.Box[np.float32]", box)


# Offsets, shared by ObsLayout and the compiled builder (numba freezes globals).
NU, Z1, T1, T2, THETA, TAU, LEADER, V0, SLOTS = 0, 3, 6, 9, 12, 13, 16, 17, 18
SLOT_WEIGHT, SLOT_DTHETA, SLOT_AGE, SLOT_MSG = 0, 1, 2, 3


@dataclass(frozen=True)
class ObsLayout:
    """Named slices into a vessel's observation vector.

    Attributes:
        n_slots: Number of neighbour slots K (largest degree of the topology).
        msg_size: Message length m.

    Example:
        >>> layout = ObsLayout(n_slots=2, msg_size=1)
        >>> layout.size, layout.z1, layout.slot(1)
        (26, slice(3, 6, None), slice(22, 26, None))
    """

    n_slots: int
    msg_size: int = 1

    nu = slice(NU, NU + 3)
    z1 = slice(Z1, Z1 + 3)
    t1 = slice(T1, T1 + 3)
    t2 = slice(T2, T2 + 3)
    theta = slice(THETA, THETA + 1)
    tau = slice(TAU, TAU + 3)
    leader = slice(LEADER, LEADER + 1)
    v0 = slice(V0, V0 + 1)

    def __post_init__(self) -> None:
        if self.n_slots < 0 or self.msg_size < 0:
            raise ValueError(f"n_slots and msg_size must be >= 0, got {self}.")

    @property
    def slot_size(self) -> int:
        """Floats per neighbour slot: weight, theta difference, age, message."""
        return SLOT_MSG + self.msg_size

    @property
    def neighbours(self) -> slice:
        """All K neighbour slots, flattened."""
        return slice(SLOTS, self.size)

    @property
    def size(self) -> int:
        """Length of the observation vector, 18 + K (3 + m)."""
        return SLOTS + self.n_slots * self.slot_size

    def slot(self, k: int) -> slice:
        """Slice of neighbour slot k (0 <= k < K)."""
        if not 0 <= k < self.n_slots:
            raise IndexError(f"slot {k} out of range for K = {self.n_slots}.")
        start = SLOTS + k * self.slot_size
        return slice(start, start + self.slot_size)

    def slots(self, obs: NDArray) -> NDArray:
        """View the neighbour slots of ``obs`` (..., size) as (..., K, 3 + m)."""
        return obs[..., SLOTS:].reshape((*obs.shape[:-1], self.n_slots, self.slot_size))

    def slot_weights(self, obs: NDArray) -> NDArray:
        """Link weights a_ij of the K slots, shape (..., K); 0 marks an empty slot."""
        return self.slots(obs)[..., SLOT_WEIGHT]

    def slot_theta_differences(self, obs: NDArray) -> NDArray:
        """Received theta_j - theta_i of the K slots, shape (..., K)."""
        return self.slots(obs)[..., SLOT_DTHETA]

    def slot_ages(self, obs: NDArray) -> NDArray:
        """Steps since each slot's value was sent, shape (..., K)."""
        return self.slots(obs)[..., SLOT_AGE]

    def slot_messages(self, obs: NDArray) -> NDArray:
        """Received messages of the K slots, shape (..., K, m)."""
        return self.slots(obs)[..., SLOT_MSG:]

    def names(self) -> list[str]:
        """A name for every index, e.g. ``"z1_x"`` or ``"slot1_age"``."""
        names = ["u", "v", "r"]
        for group in ("z1", "t1", "t2"):
            names += [f"{group}_x", f"{group}_y", f"{group}_psi"]
        names += ["theta", "tau_u", "tau_v", "tau_r", "b", "v0"]
        for k in range(self.n_slots):
            names += [f"slot{k}_a", f"slot{k}_dtheta", f"slot{k}_age"]
            names += [f"slot{k}_msg{q}" for q in range(self.msg_size)]
        return names


@numba.njit(cache=True, inline="always")
def wrap_angle(angle: float) -> float:
    """Map an angle (rad) to (-pi, pi]."""
    return angle - 2.0 * math.pi * math.ceil((angle - math.pi) / (2.0 * math.pi))


def wrap_angles(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """Map angles (rad, any shape) to [-pi, pi), elementwise: ``wrap_angle`` for arrays."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@numba.njit(cache=True, inline="always")
def path_frame(x: float, y: float, psi: float, point: tuple) -> tuple:
    """Express the path error and the path derivatives in the body frame.

    Args:
        x: Earth-frame position x (m).
        y: Earth-frame position y (m).
        psi: Heading (rad).
        point: ``paths.path_values`` output: eta_d, eta_d', eta_d'', each (x, y, psi).

    Returns:
        (z1, t1, t2), each (x, y, psi) in the body frame; z1's heading part wrapped.
    """
    c, s = math.cos(psi), math.sin(psi)
    target, first, second = point
    dx, dy = x - target[0], y - target[1]
    return (
        (c * dx + s * dy, -s * dx + c * dy, wrap_angle(psi - target[2])),
        (c * first[0] + s * first[1], -s * first[0] + c * first[1], first[2]),
        (c * second[0] + s * second[1], -s * second[0] + c * second[1], second[2]),
    )


@numba.njit(cache=True, inline="always")
def frame_pose(target: tuple, z1x: float, z1y: float, z1psi: float) -> tuple:
    """The pose a body-frame path error puts a vessel at: ``path_frame``'s inverse for z1.

    Args:
        target: eta_d, the path point (x (m), y (m), psi (rad)).
        z1x: Body-frame path error, x (m).
        z1y: Body-frame path error, y (m).
        z1psi: Heading error psi - psi_d (rad).

    Returns:
        (x, y, psi): the earth-frame position (m) and heading psi_d + z1psi (rad).
    """
    psi = target[2] + z1psi
    c, s = math.cos(psi), math.sin(psi)
    return target[0] + c * z1x - s * z1y, target[1] + s * z1x + c * z1y, psi
