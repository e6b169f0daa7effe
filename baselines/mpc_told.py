"""``mpc`` told one thing it lacks: the pieces of the headroom bound's information, apart.

``mpc_privileged`` (``baselines.mpc``) tells ``mpc`` everything a vessel
lacks at once; each member here tells it exactly one of those things and
leaves the rest as ``mpc`` has it (local observation as received, the
disturbance observer on the nominal model, the distributed v0 estimator).
Their costs split the gap between ``mpc`` and ``oracle`` into what each
piece of information closes (studies/headroom/README.md, "What a local controller
can reach"). Privileged, not deployable (``baselines.PRIVILEGED``): they read
the simulator they act in, as ``mpc_privileged`` does (build them with a
``FleetSim`` or an env, or call ``bind_simulator``).

=====================  ==========================================================
``mpc_told_dynamics``  the vessel's own true model (parameters) and its true
                       lumped residual force now (the plant's force beyond that
                       model's Coriolis and damping: unmodeled dynamics,
                       disturbance, waves, wind, current), in place of the
                       nominal model and the observer's estimate: what a
                       perfect estimator on the vessel's own history would give
``mpc_told_links``     ideal links: every neighbour's path variable and message
                       as they are now (no loss, no delay, age 0), in place of
                       the last packet received
``mpc_told_v0``        the true reference speed v0 now, in place of the
                       distributed estimate (and sends it on as its message)
=====================  ==========================================================

None of them is told the future disturbances nor plans centrally: those, and
what the told pieces do together, are the rest of the gap to ``oracle``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from baselines import mpc_kernels as kernels
from baselines.mpc import MPCPolicy, _ReadsSimulator
from cpf_env.evaluation.privileged import ideal_link_observations, true_dynamics
from cpf_env.sim.observation import NU

__all__ = ["MPCToldDynamics", "MPCToldLinks", "MPCToldV0"]

Array = NDArray[np.float64]


class MPCToldDynamics(_ReadsSimulator, MPCPolicy):
    """``mpc`` told its own true model and true lumped residual force (per vessel, now).

    Plans with each vessel's true parameters and the residual force
    ``f - C(nu) nu - D(nu) nu`` of that model (N, N, N m), f the true lumped
    uncertainty (``cpf_env.evaluation.privileged.true_dynamics``): what the
    disturbance observer estimates, exactly. Neighbours as received and the
    v0 estimate are ``mpc``'s.
    """

    name = "mpc_told_dynamics"
    privileged = True

    def _update_knowledge(self, obs: Array) -> None:
        super()._update_knowledge(obs)  # the v0 estimator; the observer's residual is replaced
        sim = self._bound()
        lumped, _ = true_dynamics(sim, self._fleets)
        self._params = np.ascontiguousarray(sim.arrays.params[self._fleets])
        hydro = np.empty_like(lumped)
        kernels.hydrodynamics(self._params, np.ascontiguousarray(obs[..., NU : NU + 3]), hydro)
        self._residual[:] = lumped - hydro


class MPCToldLinks(_ReadsSimulator, MPCPolicy):
    """``mpc`` on ideal links: neighbours' path variables and messages as they are now.

    Its observations are ``ideal_link_observations`` of the simulator (the
    neighbour slots replaced; the vessel's own state and what it hears of v0
    unchanged). Model, observer and v0 estimator are ``mpc``'s, the estimator
    fed the neighbours' current messages.
    """

    name = "mpc_told_links"
    privileged = True

    def _local(self, obs: Array) -> Array:
        return ideal_link_observations(self._bound(), self._fleets).astype(np.float64)


class MPCToldV0(_ReadsSimulator, MPCPolicy):
    """``mpc`` told the true reference speed v0 now (m/s) in place of its distributed estimate.

    Every vessel plans with, and sends as its message, v0 of the scenario's
    schedule at its fleet's current time. Neighbours as received, nominal model and
    observer are ``mpc``'s.
    """

    name = "mpc_told_v0"
    privileged = True

    def _update_knowledge(self, obs: Array) -> None:
        super()._update_knowledge(obs)  # the observer; the estimator's speed is replaced
        sim, dt = self._bound(), self.scenario.dt
        steps = sim.arrays.step[self._fleets]
        self._speed[:] = np.array([sim.v0_at(float(step) * dt) for step in steps])[:, None]
