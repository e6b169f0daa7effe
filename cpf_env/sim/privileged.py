"""Read-only views of a simulator's true state that no vessel observes: for headroom references.

The local observation of vessel i carries its own state and what its links
delivered; it does not carry the plant's true model, the disturbances or
what the neighbours hold right now. The privileged references of
``baselines.privileged`` are told exactly that, to show how much a
controller could gain with perfect knowledge (they are not deployable).
Both functions read ``FleetSim.arrays`` and write nothing to the simulator.

* ``lumped_uncertainty``: per vessel the force f (B, n, 3) with
  M nu' = tau - f at the current state, M the vessel's true mass matrix:
  Coriolis and damping of the true model, the paper's unmodeled dynamics
  and disturbance, wave and wind forces and the current's effect
  (``docs/model.md`` sections 1-2), from the plant's own right-hand side.
* ``ideal_link_observations``: the observations as lossless, undelayed
  links would have delivered them: each occupied neighbour slot holds
  theta_j - theta_i now, age 0 and the message j sent at the last step. On
  links without loss and delay these are the observations, bit for bit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import SLOT_AGE, SLOT_DTHETA, SLOT_MSG, SLOT_WEIGHT, SLOTS

__all__ = ["ideal_link_observations", "lumped_uncertainty"]


def lumped_uncertainty(sim: FleetSim) -> NDArray[np.float64]:
    """The lumped f (B, n, 3) in N, N, N m: M nu' = tau - f at the current state, true model.

    f = -M nu'(tau = 0): the plant's acceleration without control force,
    times the true mass matrix, with the wave, wind and current of the
    coming control period.
    """
    if not sim.started:
        raise RuntimeError("call sim.reset() before reading its lumped uncertainty.")
    drift = sim.accelerations(np.zeros_like(sim.arrays.tau_applied))
    return -np.einsum("bnij,bnj->bni", sim.mass_matrices(), drift)


def ideal_link_observations(sim: FleetSim) -> NDArray[np.float32]:
    """The current observations (B, n, obs_dim) float32 with ideal-link neighbour slots (a copy)."""
    if not sim.started:
        raise RuntimeError("call sim.reset() before reading its observations.")
    a = sim.arrays
    obs = a.obs.copy()
    slots = sim.constants.slots  # (n, K) neighbour index, -1 unused
    m = a.message.shape[2]
    for k in range(slots.shape[1]):
        base = SLOTS + k * (SLOT_MSG + m)
        occupied = obs[..., base + SLOT_WEIGHT] != 0.0  # (B, n): a link in the active graph
        j = np.maximum(slots[:, k], 0)
        dtheta = a.theta[:, j] - a.theta  # float64 difference, rounded once as the kernel does
        obs[..., base + SLOT_DTHETA] = np.where(occupied, dtheta, 0.0)
        obs[..., base + SLOT_AGE] = 0.0
        for q in range(m):
            obs[..., base + SLOT_MSG + q] = np.where(occupied, a.message[:, j, q], 0.0)
    return obs
