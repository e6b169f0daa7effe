"""Privileged references: the analytic controllers told what no vessel observes (headroom).

Not deployable: they show how much better a controller of the same
structure could do with perfect information, so that "how much of the gap
did a policy close" has a top. Each is its deployable parent with two
pieces of knowledge from the simulator (``cpf_env.evaluation.privileged``):

1. **the true lumped uncertainty**: per vessel the force f with
   M nu' = tau - f (true model, the paper's unmodeled dynamics and
   disturbance, waves, wind, current) and the true mass matrix M.
   ``nn_dsc_privileged`` uses f + M nubar' (eq. [26]) in place of the NN's
   estimate What^T sigma(xi) (no weights adapted); ``backstepping_privileged``
   cancels the true M alpha' + f in place of the nominal model's
   M alpha' + C(nu) nu + D(nu) nu;
2. **ideal links**: every neighbour's theta_j and message as they are now
   (no loss, no delay, age 0), in place of the last packet received.

Everything else (gains, cooperative layer, auxiliary system, the one
compiled kernel of ``baselines.kernels``) is the parent's. With no model
error, no disturbance and ideal links ``backstepping_privileged`` acts as
``backstepping`` up to rounding; on ideal links the observations they act
on are the true ones bit for bit.

A privileged policy reads a simulator: build it with a ``FleetSim`` or an
env that has one (``env.sim``), or call ``bind_simulator(sim, fleets)``
before acting (``cpf_bench.rollout`` does, with the fleets the
policy acts for). These names are in ``baselines.PRIVILEGED``, not in
``baselines.POLICIES`` (nor a base for training).

==============================  ===============================================
``nn_dsc_privileged``           ``nn_dsc`` told f + M nubar', ideal links
``backstepping_privileged``     ``backstepping`` told M and f, ideal links
==============================  ===============================================
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baselines.backstepping import BacksteppingPolicy
from baselines.kernel_types import KnownDynamics
from baselines.nn_dsc import NNDSCPolicy
from baselines.policy import AnalyticPolicy
from cpf_env.evaluation.privileged import ideal_link_observations, true_dynamics
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import SLOTS

__all__ = [
    "BacksteppingPrivileged",
    "NNDSCPrivileged",
    "PrivilegedPolicy",
    "fleet_rows",
    "simulator_of",
]


def fleet_rows(sim: FleetSim, fleets: ArrayLike | None) -> NDArray[np.int64]:
    """The fleet indices (F,) of ``sim`` a policy reads, checked: default every fleet.

    Raises:
        ValueError: ``fleets`` is not a 1-D array of indices in [0, ``sim.num_fleets``).
    """
    rows = np.arange(sim.num_fleets) if fleets is None else np.asarray(fleets)
    if (
        rows.ndim != 1
        or not np.issubdtype(rows.dtype, np.integer)
        or np.any((rows < 0) | (rows >= sim.num_fleets))
    ):
        raise ValueError(
            f"fleets must be indices in [0, {sim.num_fleets}) of the simulator, got "
            f"{np.asarray(fleets).tolist()!r}."
        )
    return np.ascontiguousarray(rows, dtype=np.int64)


def simulator_of(env: object) -> FleetSim | None:
    """The FleetSim of ``env`` (itself, ``env.sim`` or ``env.unwrapped.sim``), or None."""
    for candidate in (env, getattr(env, "sim", None), getattr(env, "unwrapped", None)):
        if isinstance(candidate, FleetSim):
            return candidate
        sim = getattr(candidate, "sim", None)
        if isinstance(sim, FleetSim):
            return sim
    return None


class PrivilegedPolicy(AnalyticPolicy):
    """Mixin of the privileged references: observations and knowledge read from a FleetSim.

    Args:
        env: A FleetSim or an env with one (bound at once), or anything
            ``AnalyticPolicy`` accepts (then ``bind_simulator`` before acting).
        **options: The parent's gains.
    """

    privileged = True

    def __init__(self, env: object, **options: Any) -> None:
        super().__init__(env, **options)
        self._sim: FleetSim | None = None
        self._rows = np.zeros(0, dtype=np.int64)
        sim = simulator_of(env)
        if sim is not None:
            self.bind_simulator(sim)

    def bind_simulator(self, sim: FleetSim, fleets: ArrayLike | None = None) -> None:
        """Read the true state of ``sim``'s fleets ``fleets`` (default all) when acting.

        Row k of the observations given to ``act_batch`` must be fleet
        ``fleets[k]`` of ``sim``.

        Raises:
            ValueError: ``sim`` runs another scenario, or bad fleet indices.
        """
        if sim.scenario.name != self.scenario.name or sim.n != self.n:
            raise ValueError(
                f"policy {self.name!r} was built for scenario {self.scenario.name!r} but the "
                f"simulator runs {sim.scenario.name!r}; build it for that scenario."
            )
        self._sim, self._rows = sim, fleet_rows(sim, fleets)

    def _bound(self) -> FleetSim:
        if self._sim is None:
            raise RuntimeError(
                f"policy {self.name!r} is a privileged reference and reads the simulator it "
                "acts in: build it with the FleetSim (or env) or call bind_simulator(sim) first."
            )
        return self._sim

    def _observations(self, obs: ArrayLike) -> ArrayLike:
        """The bound fleets' observations with ideal-link neighbour slots.

        Raises:
            ValueError: ``obs`` are not the bound fleets' current observations.
        """
        ideal = ideal_link_observations(self._bound(), self._rows)
        given = np.asarray(obs)
        if given.shape != ideal.shape or not np.array_equal(
            given[..., :SLOTS], ideal[..., :SLOTS].astype(given.dtype)
        ):
            raise ValueError(
                f"policy {self.name!r} got observations that are not those of the fleets it is "
                "bound to; bind it to the simulator and fleets that produced them "
                "(bind_simulator(sim, fleets))."
            )
        return ideal

    def _knowledge(self, fleets: NDArray[np.int64]) -> KnownDynamics:
        """The true lumped uncertainty and mass matrices of the acting fleets."""
        return KnownDynamics(*true_dynamics(self._bound(), self._rows[fleets]))

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> NDArray[np.float64]:
        """As the parent's, for all bound fleets at once (``fleets`` is not supported)."""
        if fleets is not None:
            raise ValueError(
                f"policy {self.name!r} acts for all the fleets it is bound to; bind it to "
                "the fleets you want (bind_simulator(sim, fleets)) instead of passing fleets."
            )
        return super().act_batch(obs)


class NNDSCPrivileged(PrivilegedPolicy, NNDSCPolicy):
    """``nn_dsc`` told the true f + M nubar' instead of learning it, on ideal links."""

    name = "nn_dsc_privileged"
    use_nn = False  # the NN's estimate is replaced, its weights are not adapted


class BacksteppingPrivileged(PrivilegedPolicy, BacksteppingPolicy):
    """``backstepping`` cancelling the true model and disturbances, on ideal links."""

    name = "backstepping_privileged"
