"""Read-only views of a simulator's true state that no vessel observes: for headroom references.

The local observation of vessel i carries its own state and what its links
delivered; it does not carry the plant's true model, the disturbances or
what the neighbours hold right now. The privileged references of
``baselines.privileged`` are told exactly that, to show how much a
controller could gain with perfect knowledge (they are not deployable).
Nothing here writes to the simulator.

* ``lumped_uncertainty``: per vessel the force f (B, n, 3) with
  M nu' = tau - f at the current state, M the vessel's true mass matrix:
  Coriolis and damping of the true model, the paper's unmodeled dynamics
  and disturbance, wave and wind forces and the current's effect
  (``docs/model.md`` sections 1-2), from the plant's own right-hand side.
* ``ideal_link_observations``: the observations as lossless, undelayed
  links would have delivered them: each occupied neighbour slot holds
  theta_j - theta_i now, age 0 and the message j sent at the last step. On
  links without loss and delay these are the observations, bit for bit.
* ``unobserved_state``: a short summary of what the vessel cannot see, as
  dimensionless-ish features for a learner's critic (``UNOBSERVED_SIZE`` = 5
  per vessel): the lumped f over the vessel's force scale, v0 now (m/s) and
  theta_i minus the fleet's mean path variable.

The first two are computed per fleet by compiled functions (``fleet_lumped_uncertainty``,
``fleet_ideal_observations``), which the compiled closed loop of
``baselines.closed_loop`` calls too, so there is one implementation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpf_env.model.vessel import M11, M22, M23, M32, M33
from cpf_env.sim.arrays import FleetArrays, KernelConstants
from cpf_env.sim.kernels import vessel_acceleration
from cpf_env.sim.observation import SLOT_AGE, SLOT_DTHETA, SLOT_MSG, SLOT_WEIGHT, SLOTS

if TYPE_CHECKING:  # a kernel module imports only kernel sources at run time (kernel_cache)
    from cpf_env.sim.fleet import FleetSim

__all__ = [
    "UNOBSERVED_SIZE",
    "fleet_ideal_observations",
    "fleet_lumped_uncertainty",
    "ideal_link_observations",
    "lumped_uncertainty",
    "true_dynamics",
    "unobserved_state",
]

#: Features per vessel of ``unobserved_state``.
UNOBSERVED_SIZE = 5


@numba.njit(cache=True)
def fleet_lumped_uncertainty(
    a: FleetArrays, c: KernelConstants, b: int, lumped: np.ndarray, mass: np.ndarray
) -> None:
    """Fleet b's lumped f (n, 3) into ``lumped`` and true mass matrices (n, 3, 3) into ``mass``.

    f = -M nu'(tau = 0): the plant's acceleration without control force at
    the current state, with the wave, wind and current of the coming control
    period, times the true mass matrix (N, N, N m; M in kg, kg m, kg m^2).
    """
    zero = np.zeros(3)
    for i in range(a.eta.shape[1]):
        p = a.params[b, i]
        mass[i] = 0.0
        mass[i, 0, 0] = p[M11]
        mass[i, 1, 1], mass[i, 1, 2] = p[M22], p[M23]
        mass[i, 2, 1], mass[i, 2, 2] = p[M32], p[M33]
        drift = vessel_acceleration(a, c, b, i, zero)
        for q in range(3):
            total = 0.0
            for j in range(3):
                total = total + mass[i, q, j] * drift[j]
            lumped[i, q] = -total


@numba.njit(cache=True)
def fleet_ideal_observations(a: FleetArrays, c: KernelConstants, b: int, out: np.ndarray) -> None:
    """Fleet b's observations (n, obs_dim) with ideal-link neighbour slots, into ``out``.

    Each value is rounded to float32, as the simulator's observations are,
    whatever the dtype of ``out``.
    """
    n, m = a.eta.shape[1], a.message.shape[2]
    for i in range(n):
        for q in range(out.shape[1]):
            out[i, q] = a.obs[b, i, q]
    for k in range(c.slots.shape[1]):
        base = SLOTS + k * (SLOT_MSG + m)
        for i in range(n):
            occupied = a.obs[b, i, base + SLOT_WEIGHT] != 0.0  # a link in the active graph
            j = max(c.slots[i, k], 0)
            # the float64 difference, rounded once to float32 as the simulator does
            dtheta = np.float32(a.theta[b, j] - a.theta[b, i]) if occupied else np.float32(0.0)
            out[i, base + SLOT_DTHETA] = dtheta
            out[i, base + SLOT_AGE] = 0.0
            for q in range(m):
                message = np.float32(a.message[b, j, q]) if occupied else np.float32(0.0)
                out[i, base + SLOT_MSG + q] = message


@numba.njit(cache=True)
def _lumped_rows(
    a: FleetArrays, c: KernelConstants, fleets: np.ndarray, lumped: np.ndarray, mass: np.ndarray
) -> None:
    for r in range(fleets.shape[0]):
        fleet_lumped_uncertainty(a, c, fleets[r], lumped[r], mass[r])


@numba.njit(cache=True)
def _ideal_rows(a: FleetArrays, c: KernelConstants, fleets: np.ndarray, out: np.ndarray) -> None:
    for r in range(fleets.shape[0]):
        fleet_ideal_observations(a, c, fleets[r], out[r])


def _rows(sim: FleetSim, fleets: ArrayLike | None, what: str) -> NDArray[np.int64]:
    """The fleet indices to read (default all), once the simulator holds an episode."""
    if not sim.started:
        raise RuntimeError(f"call sim.reset() before reading its {what}.")
    if fleets is None:
        return np.arange(sim.num_fleets, dtype=np.int64)
    return np.ascontiguousarray(fleets, dtype=np.int64)


def true_dynamics(
    sim: FleetSim, fleets: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The lumped f (R, n, 3) and the true mass matrices M (R, n, 3, 3) of ``fleets`` (default all).

    f in N, N, N m with M nu' = tau - f at the current state; M in kg, kg m, kg m^2.
    """
    rows = _rows(sim, fleets, "lumped uncertainty")
    lumped = np.empty((rows.shape[0], sim.n, 3))
    mass = np.empty((rows.shape[0], sim.n, 3, 3))
    _lumped_rows(sim.arrays, sim.constants, rows, lumped, mass)
    return lumped, mass


def lumped_uncertainty(sim: FleetSim, fleets: ArrayLike | None = None) -> NDArray[np.float64]:
    """The lumped f (R, n, 3) of ``fleets`` (default all B) in N, N, N m (``true_dynamics``)."""
    return true_dynamics(sim, fleets)[0]


def ideal_link_observations(sim: FleetSim, fleets: ArrayLike | None = None) -> NDArray[np.float32]:
    """Observations (R, n, obs_dim) float32 of ``fleets`` (default all) with ideal-link slots."""
    rows = _rows(sim, fleets, "observations")
    obs = np.empty((rows.shape[0], *sim.arrays.obs.shape[1:]), dtype=np.float32)
    _ideal_rows(sim.arrays, sim.constants, rows, obs)
    return obs


def unobserved_state(sim: FleetSim, fleets: ArrayLike | None = None) -> NDArray[np.float32]:
    """What no vessel observes, (R, n, ``UNOBSERVED_SIZE``) float32, of ``fleets`` (default all).

    Per vessel: the lumped f (``lumped_uncertainty``) over the vessel's force
    scale ``max(|tau_min|, |tau_max|)`` (3, dimensionless), the leader speed v0
    at the fleet's time (m/s; most vessels only estimate it), and theta_i minus
    the mean path variable of the fleet (how far the vessel is from the
    fleet's synchronization, which its delayed, lossy links show only in
    part). Each is of order one on the suite, so a learner may use them unscaled.
    """
    rows = _rows(sim, fleets, "state")
    lumped = true_dynamics(sim, rows)[0] / sim.constants.tau_scale
    v0 = np.array([sim.v0_at(float(t)) for t in sim.time[rows]])
    theta = sim.arrays.theta[rows]
    out = np.empty((rows.shape[0], sim.n, UNOBSERVED_SIZE), dtype=np.float32)
    out[..., :3] = lumped
    out[..., 3] = v0[:, None]
    out[..., 4] = theta - theta.mean(axis=1, keepdims=True)
    return out
