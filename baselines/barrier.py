"""The separation barrier: the force closest to a command that keeps a vessel clear of others.

For vessel i at earth-frame position p_i, velocity v_i, heading psi and body
velocity nu, and another vessel j at p_j moving at v_j, the barrier

    h = ||p_i - p_j||^2 - d_b^2

has relative degree two in i's force tau. The exponential second-order
condition (Nguyen & Sreenath 2016)

    h'' + (k1 + k2) h' + k1 k2 h >= 0,    h' = 2 p.v,  h'' = 2 |v|^2 + 2 p.(a_i - a_j)

(p = p_i - p_j, v = v_i - v_j) keeps h >= 0 once it holds. With a_j = 0 (j's
acceleration unknown) and a_i from i's model,

    a_i = R(psi) M^-1 (tau - C(nu) nu - D(nu) nu) + r R(psi) S nu      (rows x, y)

it is a half-plane g . tau >= beta in the force. ``barrier_filter`` projects
the command onto each violated half-plane in turn, in the metric of the
force limits squared (an axis without an actuator, limits 0, is never
used), for ``PASSES`` passes over the others, and clips to the limits: under
saturation the condition can fail, and then the force is what the limits
allow. Used by the deployable safety filter (``baselines.safety``, from
neighbours' messages) and by the ``oracle``'s feedback (``baselines.mpc``,
from the true state of every vessel).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cpf_env.model.vessel import hydrodynamic_forces, solve_mass

__all__ = ["BARRIER_GAINS", "BARRIER_MARGIN", "PASSES", "barrier_filter"]

#: Passes of the cyclic projection over the other vessels.
PASSES = 3
#: k1, k2 of the second-order barrier condition (1/s).
BARRIER_GAINS = (1.0, 1.0)
#: How far outside the collision distance the barrier keeps a vessel by default (m).
BARRIER_MARGIN = 0.2


@numba.njit(cache=True)
def barrier_filter(
    tau: np.ndarray,
    x: float,
    y: float,
    psi: float,
    nu: np.ndarray,
    params: np.ndarray,
    others: np.ndarray,
    count: int,
    distance: float,
    k1: float,
    k2: float,
    tau_min: np.ndarray,
    tau_max: np.ndarray,
) -> None:
    """Project ``tau`` (3,) in place onto the barrier conditions (module docstring).

    Args:
        tau: (3,) the command (N, N, N m), filtered and clipped in place.
        x: Earth-frame position of the vessel, x (m).
        y: Earth-frame position of the vessel, y (m).
        psi: Heading (rad).
        nu: (3,) body velocity u, v (m/s), r (rad/s).
        params: The vessel's model parameters (``VesselModel.to_params``).
        others: (K, 4) the other vessels' x, y (m) and earth-frame velocity (m/s).
        count: How many rows of ``others`` are filled.
        distance: d_b (m), the distance the barrier keeps.
        k1: First gain of the condition (1/s).
        k2: Second gain of the condition (1/s).
        tau_min: (3,) lower force limits (N, N, N m).
        tau_max: (3,) upper force limits (N, N, N m).
    """
    c, s = math.cos(psi), math.sin(psi)
    u, v, r = nu[0], nu[1], nu[2]
    vx, vy = c * u - s * v, s * u + c * v
    columns = np.empty((3, 2))
    for q in range(3):
        acc = solve_mass(params, 1.0 if q == 0 else 0.0, 1.0 if q == 1 else 0.0,
                         1.0 if q == 2 else 0.0)  # fmt: skip
        columns[q, 0] = c * acc[0] - s * acc[1]
        columns[q, 1] = s * acc[0] + c * acc[1]
    h = hydrodynamic_forces(params, u, v, r)
    drift = solve_mass(params, -h[0], -h[1], -h[2])
    a0x = c * drift[0] - s * drift[1] - r * vy
    a0y = s * drift[0] + c * drift[1] + r * vx
    weight = np.empty(3)
    for q in range(3):
        scale = max(abs(tau_min[q]), abs(tau_max[q]))
        weight[q] = scale * scale
    g = np.empty(3)
    for _ in range(PASSES):
        for k in range(count):
            px, py = x - others[k, 0], y - others[k, 1]
            rvx, rvy = vx - others[k, 2], vy - others[k, 3]
            barrier = px * px + py * py - distance * distance
            rate = 2.0 * (px * rvx + py * rvy)
            beta = (-2.0 * (rvx * rvx + rvy * rvy) - (k1 + k2) * rate - k1 * k2 * barrier
                    - 2.0 * (px * a0x + py * a0y))  # fmt: skip
            slack, norm = -beta, 0.0
            for q in range(3):
                g[q] = 2.0 * (px * columns[q, 0] + py * columns[q, 1])
                slack += g[q] * tau[q]
                norm += weight[q] * g[q] * g[q]
            if slack < 0.0 and norm > 0.0:
                for q in range(3):
                    tau[q] -= slack / norm * weight[q] * g[q]
    for q in range(3):
        tau[q] = min(max(tau[q], tau_min[q]), tau_max[q])
