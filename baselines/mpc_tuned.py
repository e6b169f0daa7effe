"""``mpc_tuned``: ``mpc`` with its v0 estimator tuned on the suite's training seeds.

Most of the room ``mpc`` leaves to the ``oracle`` is the start-up transient
of its distributed v0 estimator (docs/benchmark.md, "What a local
controller can reach"): every vessel starts its estimate at 0 and takes it
up at gains k5 = k6 = 1 /s. ``mpc_tuned`` changes that estimator and
nothing else (plan, model, observer, neighbours as received are ``mpc``'s):

* gains ``k5 = k6 = 5`` /s (``K5``, ``K6``), so the estimate reaches what
  the leader-linked vessels hear within about a second;
* the step is kept stable on any graph: where dt (k5 d_i + k6 l_i) > 1 (d_i
  the vessel's weighted degree as received, l_i its leader link), the step
  is divided by that number, so the new estimate is a convex combination of
  the old one, the neighbours' messages and v0 (at 5 /s and dt = 0.05 s,
  from a weighted degree of 4 with a leader link; the 7-vessel star of
  ``bench_large_fleet_shift`` has a hub of degree 6);
* the estimate's rate of change is limited to ``speed_rate`` (``SPEED_RATE``,
  0.25) times the surge acceleration the vessel's own force limit gives its
  nominal model at rest, ``tau_max_u / (m - X_udot)`` (m/s^2). A speed the
  vessel cannot yet reach is not asked for: with the fast gains alone, a
  fleet with tight force limits (``bench_saturation``) chases a speed it
  cannot reach and costs more than ``mpc``.

All use only what a vessel has on board (its neighbours' messages and link
weights, what it hears of v0, its own force limits and nominal model):
deployable (``baselines.POLICIES``). The values were chosen on the suite's
training seeds (0-4), never on the evaluation seeds: ``examples/mpc_tuning.py``
prints the sweep (docs/benchmark.md has it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from baselines.mpc import MPCPolicy
from cpf_env.sim.observation import LEADER, SLOT_WEIGHT, SLOTS

__all__ = ["K5", "K6", "SPEED_RATE", "MPCTuned"]

#: Speed-estimator gain on neighbours' estimates (1/s).
K5 = 5.0
#: Speed-estimator gain on the heard v0 (1/s).
K6 = 5.0
#: Rate limit of the speed estimate, as a fraction of the nominal surge acceleration
#: at the force limit.
SPEED_RATE = 0.25


class MPCTuned(MPCPolicy):
    """``mpc`` with a fast, rate-limited v0 estimator (module docstring).

    Args:
        env: Anything ``baselines.policy.resolve_scenario`` accepts.
        speed_rate: Rate limit of the speed estimate, a fraction > 0 of each
            vessel's nominal surge acceleration at its force limit (``inf``: no
            limit, ``mpc``'s estimator at the given gains).
        **options: Fields of ``RecedingHorizonGains``; ``k5`` and ``k6`` default to
            ``K5`` and ``K6``.

    Attributes:
        speed_step: (n,) the most the speed estimate moves in one control step (m/s).
    """

    name = "mpc_tuned"

    def __init__(self, env: object, speed_rate: float = SPEED_RATE, **options: Any) -> None:
        if not speed_rate > 0:
            raise ValueError(
                f"speed_rate must be > 0 (a fraction of the nominal surge acceleration; inf "
                f"for no limit), got {speed_rate!r}."
            )
        super().__init__(env, **{"k5": K5, "k6": K6, **options})
        s = self.scenario
        _, tau_max = s.tau_limits
        surge_mass = np.array([vessel.mass - vessel.X_udot for vessel in s.vessel_models])
        self.speed_step: NDArray[np.float64] = speed_rate * s.dt * tau_max[:, 0] / surge_mass

    def _update_knowledge(self, obs: NDArray[np.float64]) -> None:
        before = self._speed.copy()
        super()._update_knowledge(obs)  # the observer, and mpc's estimator step at the gains
        g = self.gains
        slots = SLOTS + self._slot_width * np.arange(self._slots)
        degree = obs[..., slots + SLOT_WEIGHT].sum(axis=-1)
        weight = self.scenario.dt * (g.k5 * degree + g.k6 * obs[..., LEADER])  # the old one's
        change = (self._speed - before) / np.maximum(weight, 1.0)
        self._speed = before + np.clip(change, -self.speed_step, self.speed_step)
