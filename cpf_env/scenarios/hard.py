"""The hard track: the suite's tasks under the sensing, actuation and traffic of real vessels.

The core suite (``cpf_env.scenarios.suite``) observes the true state at every
step, applies every force at once and keeps the vessels 4 m apart; there,
the best deployable analytic design comes within a few per cent of the
``oracle``. The hard track puts the tasks on the conditions a real surface
vessel meets:

* **sensing** (``STANDALONE_FIX``, ``cpf_env.model.sensors``): a satellite fix
  and compass at model scale, 2 cm and 1 degree, every 4 steps (5 Hz), 5 % of
  fixes lost, no velocity sensor (docs/model.md, "Sensors");
* **thruster dynamics** (``LAGGED_THRUSTERS``, ``cpf_env.model.actuators``): a
  0.5 s lag and slew limits that take about a second from zero to full force
  (a few seconds at full scale, divided by Froude's 8.4);
* **hulls without a sway actuator** (``without_sway``): a propeller and a
  rudder, the common case at sea; at the steerage speed of ``bench_saturation``
  (0.5 m/s), where a rudder turns a hull (at the core suite's 0.1 m/s,
  Cybership II's weak low-speed sway damping lets every turn set the hull
  sliding for tens of seconds, and no design holds the path);
* **crossing paths with a separation constraint** (``crossing``,
  ``cpf_env.scenarios.crossing``, ``CROSSING_SEPARATION``): pairs of vessels
  whose synchronized formation brings them 0.57 m apart, deep inside a 1.5 m
  keep-out and 7 cm outside a 0.5 m collision, so that a packet lost at the
  wrong moment or a few centimetres of position error make a collision;
  room in the messages for a safety filter's broadcast (``baselines.safety``).

==============================  ===========================================================
name                            the task, and what the track adds
==============================  ===========================================================
``hard_sensing``                ``bench_mild``: sensing
``hard_sensing_waves``          ``bench_current_waves``: sensing
``hard_underactuated``          ``bench_saturation``: no sway actuator, thruster dynamics
``hard_crossing``               two crossing pairs over links that lose 30 % of packets,
                                5-step delay: separation
``hard_underactuated_sensing``  ``bench_saturation``: no sway actuator, sensing
``hard_heterogeneous``          ``bench_heterogeneous``: sensing and thruster dynamics
``hard_large_fleet``            five crossing pairs (n = 10, ring graph, 10 % packet loss)
                                at 0.5 m/s: separation, no sway actuator, sensing and
                                thruster dynamics
==============================  ===========================================================

Each has a ``test`` and a ``shift`` split like the core suite's
(``cpf_env.scenarios.splits``). A scenario built on a core task shifts as its
core scenario does; the crossing scenarios start from a wider spread
(``SHIFTED_CROSSING_SPREAD``), lose twice the packets' delay and 20 % more
packets. Both take ``SHIFTED_FIX`` (3 cm, 1.5 degrees, every 6 steps, 10 %
lost) and ``SHIFTED_THRUSTERS`` (a 0.8 s lag, slew limits x 0.7) where they
have the mechanism; a hull without sway keeps none in its shift. The cost is
the core suite's on the true state, plus the separation term where vessels
cross; its tolerances (1 cm of path error, 0.05 rad of heading) sit at what
a filter makes of these sensors (about 1 cm and 0.01 rad), so the sensors do
not make the cost unreachable. The large fleet has every mechanism.

    >>> from cpf_env.scenarios.suite import list_suite
    >>> list_suite("hard")[0]
    'hard_sensing'
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from cpf_env.model.actuators import Thrusters
from cpf_env.model.links import LinkImpairments
from cpf_env.model.sensors import Sensors
from cpf_env.model.separation import Separation
from cpf_env.scenarios import suite
from cpf_env.scenarios.crossing import crossing_fleet
from cpf_env.scenarios.registry import register
from cpf_env.scenarios.scenario import Scenario

__all__ = [
    "BASES",
    "CROSSING_MESSAGE",
    "CROSSING_MESSAGE_MAX",
    "CROSSING_OFFSET",
    "CROSSING_SEPARATION",
    "CROSSING_SPREAD",
    "HARD_FACTORIES",
    "LAGGED_THRUSTERS",
    "LARGE_FLEET_SPEED",
    "SHIFTED_CROSSING_SPREAD",
    "SHIFTED_FIX",
    "SHIFTED_THRUSTERS",
    "STANDALONE_FIX",
    "crossing",
    "crossing_shift",
    "without_sway",
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
#: The crossing scenarios' separation: keep 1.5 m apart (a hull length and a beam), never 0.5 m.
CROSSING_SEPARATION = Separation(safe_distance=1.5, hard_distance=0.5, weight=10.0)
#: Message entries of the crossing scenarios: the designs' own, then a flag, position and
#: velocity for a safety filter (``baselines.safety``), within +- 100 m.
CROSSING_MESSAGE, CROSSING_MESSAGE_MAX = 6, 100.0
#: Random starts of the crossing scenarios (m, rad, path-variable units): tighter than the
#: core suite's 1 m, so that no fleet starts inside its collision distance.
CROSSING_SPREAD = (0.3, 0.1, 0.3)
#: How far a crossing pair's second vessel is behind the first in formation (m): the
#: synchronized pair passes 0.57 m apart (offset / sqrt(2)), 7 cm outside the collision
#: distance. Versions 2 and 3 had 0.3 m (0.21 m apart): a pass then took metres of
#: desynchronization, which the sync term charges more than stopping, and the bound stopped
#: the fleet short of the crossings (docs/findings).
CROSSING_OFFSET = 0.8
#: The large fleet's speed (m/s): its hulls have no sway actuator, and at the crossing
#: scenarios' 0.1 m/s such a hull does not hold even a straight path (docs/findings); 0.5
#: m/s is ``bench_saturation``'s, where a rudder steers. Its pairs meet after 40 s, as at
#: 0.1 m/s.
LARGE_FLEET_SPEED = 0.5
#: The crossing scenarios' ``shift`` spread of the starts (m, rad, path-variable units).
SHIFTED_CROSSING_SPREAD = (0.5, 0.17, 0.5)


def without_sway(task: Scenario) -> Scenario:
    """``task`` on hulls without a sway actuator: every vessel's sway force limits set to 0 N.

    Example:
        >>> from cpf_env.scenarios import suite
        >>> without_sway(suite.bench_saturation()).actuated[0].tolist()
        [True, False, True]
    """
    tau_min, tau_max = task.tau_limits
    tau_min[:, 1], tau_max[:, 1] = 0.0, 0.0
    rows = lambda a: tuple(tuple(float(x) for x in row) for row in a)  # noqa: E731
    return task.replace(tau_max=rows(tau_max), tau_min=rows(tau_min))


def crossing(
    name: str,
    pairs: int,
    description: str,
    v0: float = 0.1,
    lead: float = 4.0,
    **changes: object,
) -> Scenario:
    """``pairs`` crossing pairs (``cpf_env.scenarios.crossing``) under ``CROSSING_SEPARATION``.

    At ``v0`` (m/s) for the core suite's 100 s, the eastbound vessels ``lead`` metres
    before their crossings (the pairs meet after lead / v0 seconds, 40 s by default), with
    random starts of ``CROSSING_SPREAD``; ``changes`` adds the mechanisms.
    """
    paths, initial, topology = crossing_fleet(
        pairs, lead=lead, offset=CROSSING_OFFSET, leaders=(0,) if pairs < 3 else (0, pairs)
    )
    position, heading, theta = CROSSING_SPREAD
    return Scenario(
        name=name,
        paths=paths,
        topology=topology,
        initial=dataclasses.replace(
            initial, position_std=position, heading_std=heading, theta_std=theta
        ),
        v0=v0,
        max_steps=suite.BENCH_STEPS,
        separation=CROSSING_SEPARATION,
        message_size=CROSSING_MESSAGE,
        message_max=CROSSING_MESSAGE_MAX,
        description=description,
        **changes,  # type: ignore[arg-type]
    )


def crossing_shift(task: Scenario) -> Scenario:
    """A crossing scenario's task outside its training ranges: wider starts, worse links.

    The starts spread by ``SHIFTED_CROSSING_SPREAD``; links lose 20 % more packets and
    twice the delay. The ``shift`` split (``cpf_env.scenarios.splits``) then shifts the
    mechanisms, as for every hard scenario.
    """
    position, heading, theta = SHIFTED_CROSSING_SPREAD
    links = task.links
    changes: dict[str, object] = {
        "initial": dataclasses.replace(
            task.initial, position_std=position, heading_std=heading, theta_std=theta
        ),
        "links": dataclasses.replace(
            links,
            loss_probability=round(min(links.loss_probability + 0.2, 0.9), 9),
            delay_steps=2 * links.delay_steps,
        ),
    }
    return task.replace(**changes)


def hard_crossing() -> Scenario:
    """Two crossing pairs over links that lose 30 % of packets and delay them 0.25 s."""
    return crossing(
        "hard_crossing",
        2,
        "Two crossing pairs, 1.5 m keep-out, 30 % packet loss, 5-step delay. Hard track: "
        "separation.",
        links=LinkImpairments(loss_probability=0.3, delay_steps=5),
    )


#: The hard scenarios built on a core task, and that task (their ``shift`` builds on its).
BASES = {
    "hard_sensing": "bench_mild",
    "hard_sensing_waves": "bench_current_waves",
    "hard_underactuated": "bench_saturation",
    "hard_underactuated_sensing": "bench_saturation",
    "hard_heterogeneous": "bench_heterogeneous",
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


def hard_underactuated() -> Scenario:
    """``bench_saturation`` on hulls without sway (``without_sway``) with ``LAGGED_THRUSTERS``."""
    return _hard(
        without_sway(suite.bench_saturation()),
        "hard_underactuated",
        "no sway actuator, thruster dynamics",
        thrusters=LAGGED_THRUSTERS,
    )


def hard_underactuated_sensing() -> Scenario:
    """``bench_saturation`` on hulls without sway (``without_sway``) through ``STANDALONE_FIX``."""
    return _hard(
        without_sway(suite.bench_saturation()),
        "hard_underactuated_sensing",
        "no sway actuator, sensing",
        sensors=STANDALONE_FIX,
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
    """Every mechanism: five crossing pairs (n = 10) on hulls without sway, 0.5 m/s.

    ``without_sway`` hulls at ``LARGE_FLEET_SPEED``, with ``STANDALONE_FIX`` and
    ``LAGGED_THRUSTERS``.
    """
    return without_sway(
        crossing(
            "hard_large_fleet",
            5,
            "Five crossing pairs (n = 10, ring graph, leaders 0 and 5) at 0.5 m/s, 1.5 m "
            "keep-out, 10 % packet loss. Hard track: separation, no sway actuator, sensing "
            "and thruster dynamics.",
            v0=LARGE_FLEET_SPEED,
            lead=LARGE_FLEET_SPEED * 40.0,
            links=LinkImpairments(loss_probability=0.1),
            sensors=STANDALONE_FIX,
            thrusters=LAGGED_THRUSTERS,
        )
    )


#: The hard track's factories, in the order the bench reports them (``suite.TRACKS["hard"]``).
HARD_FACTORIES: tuple[Callable[[], Scenario], ...] = (
    hard_sensing,
    hard_sensing_waves,
    hard_underactuated,
    hard_crossing,
    hard_underactuated_sensing,
    hard_heterogeneous,
    hard_large_fleet,
)

for _factory in HARD_FACTORIES:
    register(_factory.__name__, _factory)
