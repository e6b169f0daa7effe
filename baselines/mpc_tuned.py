"""``mpc_tuned``: ``mpc`` with its v0 estimator tuned on the suite's training seeds.

Most of the room ``mpc`` leaves to the ``oracle`` was the start-up transient
of its distributed v0 estimator (studies/headroom/README.md, "What a local
controller can reach"): every vessel starts its estimate at 0 and takes it
up at gains k5 = k6 = 1 /s. ``mpc_tuned`` is ``mpc`` with two settings of
that estimator changed (``baselines.mpc.RecedingHorizonGains``) and nothing
else:

* gains ``k5 = k6 = 5`` /s (``K5``, ``K6``), so the estimate reaches what
  the leader-linked vessels hear within about a second;
* the estimate moves at most ``speed_rate`` (``baselines.mpc.SPEED_RATE``, 0.25) times the
  surge acceleration the vessel's own force limit gives its nominal model
  at rest, ``tau_max_u / (m - X_udot)`` (m/s^2). A speed the vessel cannot
  yet reach is not asked for: with the fast gains alone, a fleet with tight
  force limits (``bench_saturation``) chases a speed it cannot reach and
  costs more than ``mpc``.

At 5 /s the estimator's step would overshoot on a vessel of weighted degree
4 or more; ``mpc``'s estimator divides such a step so that the new estimate
stays a convex combination of the old one, the messages and v0 (at 1 /s
that never happens below a degree of 19). Everything used is on board (its
neighbours' messages and link weights, what it hears of v0, its own force
limits and nominal model): deployable (``baselines.POLICIES``). The values
were chosen on the suite's training seeds (0-4), never on the evaluation
seeds: ``studies/headroom/mpc_tuning.py`` prints the sweep (studies/headroom/README.md has it).
"""

from __future__ import annotations

from typing import Any, ClassVar

from baselines.mpc import SPEED_RATE, MPCPolicy

__all__ = ["K5", "K6", "MPCTuned"]

#: Speed-estimator gain on neighbours' estimates (1/s).
K5 = 5.0
#: Speed-estimator gain on the heard v0 (1/s).
K6 = 5.0


class MPCTuned(MPCPolicy):
    """``mpc`` with a fast, rate-limited v0 estimator (module docstring).

    Args:
        env: Anything ``baselines.policy.resolve_scenario`` accepts.
        **options: Fields of ``baselines.mpc.RecedingHorizonGains``; ``k5``, ``k6`` and
            ``speed_rate`` default to ``K5``, ``K6`` and ``baselines.mpc.SPEED_RATE``.
    """

    name = "mpc_tuned"
    DEFAULTS: ClassVar[dict[str, Any]] = {"k5": K5, "k6": K6, "speed_rate": SPEED_RATE}
