"""The hard track: the core suite's tasks under the sensing and actuation of real vessels.

The core suite (``cpf_env.scenarios.suite``) observes the true state at every
step and applies every force at once; there, the best deployable analytic
design comes within a few per cent of the ``oracle``. The hard track puts the
same tasks on the conditions a real surface vessel meets:

* **sensing** (``STANDALONE_FIX``, ``cpf_env.model.sensors``): a satellite fix
  and compass at model scale, 2 cm and 1 degree, every 4 steps (5 Hz), 5 % of
  fixes lost, no velocity sensor (docs/model.md, "Sensors");
* **thruster dynamics** (``LAGGED_THRUSTERS``, ``cpf_env.model.actuators``): a
  0.5 s lag and slew limits that take about a second from zero to full force
  (a few seconds at full scale, divided by Froude's 8.4).

============================  ===============================================================
name                          the core scenario it builds on, and what it adds
============================  ===============================================================
``hard_sensing``              ``bench_mild``: sensing
``hard_sensing_waves``        ``bench_current_waves``: sensing
``hard_thrusters``            ``bench_saturation``: thruster dynamics
``hard_lossy_sensing``        ``bench_lossy_links``: sensing
``hard_switching_thrusters``  ``bench_switching``: thruster dynamics
``hard_heterogeneous``        ``bench_heterogeneous``: sensing and thruster dynamics
``hard_large_fleet``          ``bench_large_fleet``: sensing and thruster dynamics
============================  ===============================================================

Each has a ``test`` and a ``shift`` split like the core suite's
(``cpf_env.scenarios.splits``): the shift is its core scenario's shift with
``SHIFTED_FIX`` (3 cm, 1.5 degrees, every 6 steps, 10 % lost) and
``SHIFTED_THRUSTERS`` (a 0.8 s lag, slew limits x 0.7) where it has them.
The cost is the core suite's, on the true state; its tolerances (1 cm of
path error, 0.05 rad of heading) sit at what a filter makes of these sensors
(about 1 cm and 0.01 rad), so the sensors do not make the cost unreachable.
Not yet on the track: hulls without a sway actuator (``baselines.ilos``
exists, the bound's feedback does not yet work without sway) and crossing
paths with a separation constraint.

    >>> from cpf_env.scenarios.suite import list_suite
    >>> list_suite("hard")[0]
    'hard_sensing'
"""

from __future__ import annotations

from collections.abc import Callable

from cpf_env.model.actuators import Thrusters
from cpf_env.model.sensors import Sensors
from cpf_env.scenarios import suite
from cpf_env.scenarios.registry import register
from cpf_env.scenarios.scenario import Scenario

__all__ = [
    "BASES",
    "HARD_FACTORIES",
    "LAGGED_THRUSTERS",
    "SHIFTED_FIX",
    "SHIFTED_THRUSTERS",
    "STANDALONE_FIX",
]

#: A standalone satellite fix and compass at Cybership II's scale (docs/model.md, "Sensors").
STANDALONE_FIX = Sensors(
    position_std=0.02, heading_std=0.0175, period=4, dropout=0.05, velocity=False
)
#: Thrusters with a 0.5 s lag and about 1 s from zero to the core suite's full force.
LAGGED_THRUSTERS = Thrusters(time_constant=0.5, rate_limit=(10.0, 5.0, 3.0))
#: The ``shift`` split's sensing: 3 cm, 1.5 degrees, every 6 steps, 10 % lost.
SHIFTED_FIX = Sensors(position_std=0.03, heading_std=0.026, period=6, dropout=0.1, velocity=False)
#: The ``shift`` split's thrusters: a 0.8 s lag, slew limits x 0.7.
SHIFTED_THRUSTERS = Thrusters(time_constant=0.8, rate_limit=(7.0, 3.5, 2.1))
#: Each hard scenario's core scenario (its ``shift`` builds on the core one's).
BASES = {
    "hard_sensing": "bench_mild",
    "hard_sensing_waves": "bench_current_waves",
    "hard_thrusters": "bench_saturation",
    "hard_lossy_sensing": "bench_lossy_links",
    "hard_switching_thrusters": "bench_switching",
    "hard_heterogeneous": "bench_heterogeneous",
    "hard_large_fleet": "bench_large_fleet",
}


def _hard(base: Scenario, name: str, what: str, **changes: object) -> Scenario:
    """``base`` named ``name``, its description saying what the track adds."""
    return base.replace(name=name, description=f"{base.description} Hard track: {what}.", **changes)


def hard_sensing() -> Scenario:
    """``bench_mild`` seen through ``STANDALONE_FIX``."""
    return _hard(suite.bench_mild(), "hard_sensing", "sensing", sensors=STANDALONE_FIX)


def hard_sensing_waves() -> Scenario:
    """``bench_current_waves`` seen through ``STANDALONE_FIX``."""
    return _hard(
        suite.bench_current_waves(), "hard_sensing_waves", "sensing", sensors=STANDALONE_FIX
    )


def hard_thrusters() -> Scenario:
    """``bench_saturation`` with ``LAGGED_THRUSTERS``."""
    return _hard(
        suite.bench_saturation(), "hard_thrusters", "thruster dynamics", thrusters=LAGGED_THRUSTERS
    )


def hard_lossy_sensing() -> Scenario:
    """``bench_lossy_links`` seen through ``STANDALONE_FIX``."""
    return _hard(suite.bench_lossy_links(), "hard_lossy_sensing", "sensing", sensors=STANDALONE_FIX)


def hard_switching_thrusters() -> Scenario:
    """``bench_switching`` with ``LAGGED_THRUSTERS``."""
    return _hard(
        suite.bench_switching(),
        "hard_switching_thrusters",
        "thruster dynamics",
        thrusters=LAGGED_THRUSTERS,
    )


def hard_heterogeneous() -> Scenario:
    """``bench_heterogeneous`` with ``STANDALONE_FIX`` and ``LAGGED_THRUSTERS``."""
    return _hard(
        suite.bench_heterogeneous(),
        "hard_heterogeneous",
        "sensing and thruster dynamics",
        sensors=STANDALONE_FIX,
        thrusters=LAGGED_THRUSTERS,
    )


def hard_large_fleet() -> Scenario:
    """``bench_large_fleet`` with ``STANDALONE_FIX`` and ``LAGGED_THRUSTERS``."""
    return _hard(
        suite.bench_large_fleet(),
        "hard_large_fleet",
        "sensing and thruster dynamics",
        sensors=STANDALONE_FIX,
        thrusters=LAGGED_THRUSTERS,
    )


#: The hard track's factories, in the order the bench reports them (``suite.TRACKS["hard"]``).
HARD_FACTORIES: tuple[Callable[[], Scenario], ...] = (
    hard_sensing,
    hard_sensing_waves,
    hard_thrusters,
    hard_lossy_sensing,
    hard_switching_thrusters,
    hard_heterogeneous,
    hard_large_fleet,
)

for _factory in HARD_FACTORIES:
    register(_factory.__name__, _factory)
