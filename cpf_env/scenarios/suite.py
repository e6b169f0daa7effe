"""The benchmark suite: named evaluation scenarios in which the seed matters.

The named scenarios of ``cpf_env.scenarios`` reproduce fixed situations
(``wang2014`` and ``saturation_heavy`` start every episode from the same
poses with deterministic disturbances, so every seed gives the same
episode). The suite's scenarios cover the same ground but draw initial
positions, headings and path variables at every reset, and, where it fits,
model spread, disturbance noise and packet loss, so that N seeds are N
samples:

=======================  ============================================================
name                     what it stresses
=======================  ============================================================
``bench_mild``           the paper's task from random starts (the easy case)
``bench_saturation``     v0 = 0.5 m/s, halved force limits, large random offsets
``bench_current_waves``  varying current, Gauss-Markov waves and wind, model spread 10 %
``bench_lossy_links``    30 % packet loss, 5-step delay, large path-variable spread
``bench_switching``      chain, ring, star, leaderless ring (10 s each); v0 steps unheard
``bench_heterogeneous``  true models drawn +-30 % around Cybership II
``bench_large_fleet``    n = 10 on a ring graph
=======================  ============================================================

Importing ``cpf_env.scenarios`` registers them:

    >>> from cpf_env import scenarios
    >>> from cpf_env.scenarios import suite
    >>> suite.list_suite()[0]
    'bench_mild'
    >>> suite.is_deterministic(scenarios.get("wang2014"))
    True
    >>> suite.is_deterministic(scenarios.get("bench_mild"))
    False
"""

from __future__ import annotations

import dataclasses

from cpf_env.model.graph import Graph, SwitchingTopology
from cpf_env.model.links import LinkImpairments
from cpf_env.scenarios import paper
from cpf_env.scenarios.registry import register
from cpf_env.scenarios.scenario import Scenario, SpeedSchedule

__all__ = [
    "HARD_VERSION",
    "SUITE",
    "SUITE_VERSION",
    "TRACKS",
    "TRACK_VERSIONS",
    "is_deterministic",
    "list_suite",
    "track_of",
]

#: Version of the suite's definitions; results of different versions do not compare.
#: 1: the first suite. 2: ``bench_switching`` cuts the fleet off the leader for
#: 10 s of every 40 and steps v0 meanwhile, inside the scored window too (in
#: version 1 it cycled chain, ring and star with leader links throughout at a
#: constant v0, and its final-window costs equalled ``bench_mild``'s).
SUITE_VERSION = 2
#: Version of the hard track's definitions (``cpf_env.scenarios.hard``). 1: sensing and
#: thruster dynamics on the core suite's seven tasks. 2: crossing paths with a separation
#: constraint (``hard_crossing`` in place of ``hard_lossy_sensing``; ``hard_large_fleet``
#: five crossing pairs with every mechanism), and the planners' thruster-aware feedback.
#: 3: hulls without a sway actuator (``hard_underactuated`` and ``hard_underactuated_sensing``
#: in place of ``hard_thrusters`` and ``hard_switching_thrusters``). 4: crossing pairs 0.57 m
#: apart in formation (``hard.CROSSING_OFFSET`` 0.8 m, was 0.3 m), ``hard_large_fleet`` with
#: every mechanism (hulls without sway, at 0.5 m/s), and an ``oracle`` that sees the whole
#: episode where vessels cross.
HARD_VERSION = 4

#: Spread of the random starts (m, rad, path-variable units), common to the suite.
POSITION_STD, HEADING_STD, THETA_STD = 1.0, 0.3, 0.5
#: Episode length of the suite's scenarios (control steps; 100 s at dt = 0.05 s).
BENCH_STEPS = 2000


def _randomized(base: Scenario, name: str, description: str, **changes: object) -> Scenario:
    """``base`` with random starts (unless ``changes`` gives ``initial``) and the suite's length."""
    initial = dataclasses.replace(
        base.initial, position_std=POSITION_STD, heading_std=HEADING_STD, theta_std=THETA_STD
    )
    fields: dict[str, object] = {"initial": initial, "max_steps": BENCH_STEPS}
    fields.update(changes)
    return base.replace(name=name, description=description, **fields)


def bench_mild() -> Scenario:
    """The paper's task from random starts."""
    return _randomized(
        paper.wang2014(), "bench_mild", "wang2014 from random poses, headings and theta."
    )


def bench_saturation() -> Scenario:
    """``saturation_heavy`` (v0 = 0.5 m/s, halved limits) from random large offsets."""
    base = paper.saturation_heavy()
    return _randomized(
        base,
        "bench_saturation",
        "saturation_heavy from random 3 m offsets: sustained saturation.",
        max_steps=base.max_steps,
    )


def bench_current_waves() -> Scenario:
    """``current_and_waves`` with 10 % model spread, from random starts."""
    return _randomized(
        paper.current_and_waves(),
        "bench_current_waves",
        "Current, waves and wind, 10 % model spread, random starts.",
        model_spread=0.1,
    )


def bench_lossy_links() -> Scenario:
    """30 % packet loss and 5-step delay, random starts with twice the theta spread."""
    base = _randomized(
        paper.lossy_links(), "bench_lossy_links", "30 % loss, 5-step delay, random starts."
    )
    return base.replace(initial=dataclasses.replace(base.initial, theta_std=2 * THETA_STD))


def bench_switching() -> Scenario:
    """Chain, ring, star and a leaderless ring in turn; v0 steps while no vessel hears it.

    The graph cycles every 10 s through a chain, a ring and a star (leader
    links change with them) and a ring on which no vessel hears the leader
    (10 s without leader links, from 30 s and from 70 s). The leader's speed
    steps up to 0.15 m/s at 35 s and back to 0.1 m/s at 78 s, each time
    while the fleet is cut off from it, so the new v0 reaches the fleet only
    through the switching graph, inside the benchmark's scored final window
    (the last 25 s) too.
    """
    graphs = (
        Graph.path(5, leaders=(0, 3)),
        Graph.ring(5, leaders=(2,)),
        Graph.star(5, center=2, leaders=(4,)),
        Graph.ring(5, leaders=()),
    )
    return _randomized(
        paper.wang2014(),
        "bench_switching",
        "Chain, ring, star, leaderless ring in turn (10 s each); v0 steps at 35 s and 78 s "
        "while no vessel hears the leader; random starts.",
        topology=SwitchingTopology(graphs=graphs, switch_steps=(0, 200, 400, 600), period=800),
        v0=SpeedSchedule(times=(0.0, 35.0, 78.0), values=(0.1, 0.15, 0.1)),
    )


def bench_heterogeneous() -> Scenario:
    """``heterogeneous`` (models +-30 %) from the suite's random starts."""
    return _randomized(
        paper.heterogeneous(),
        "bench_heterogeneous",
        "True models +-30 % around Cybership II, random starts.",
    )


def bench_large_fleet() -> Scenario:
    """``large_fleet`` (n = 10, ring) from random starts, 10 % packet loss."""
    return _randomized(
        paper.large_fleet(),
        "bench_large_fleet",
        "n = 10, ring graph, random starts, 10 % packet loss.",
        links=LinkImpairments(loss_probability=0.1),
    )


_FACTORIES = (
    bench_mild,
    bench_saturation,
    bench_current_waves,
    bench_lossy_links,
    bench_switching,
    bench_heterogeneous,
    bench_large_fleet,
)

#: Names of the suite's scenarios, in the order the bench reports them.
SUITE: tuple[str, ...] = tuple(factory.__name__ for factory in _FACTORIES)
#: Each track's scenario names: ``core``, this suite; ``hard``, its tasks under
#: sensing, hulls without sway, thruster dynamics and crossing traffic
#: (``cpf_env.scenarios.hard``, which registers them).
TRACKS: dict[str, tuple[str, ...]] = {
    "core": SUITE,
    "hard": (
        "hard_sensing",
        "hard_sensing_waves",
        "hard_underactuated",
        "hard_crossing",
        "hard_underactuated_sensing",
        "hard_heterogeneous",
        "hard_large_fleet",
    ),
}
#: Each track's version; results of different versions of a track do not compare.
TRACK_VERSIONS = {"core": SUITE_VERSION, "hard": HARD_VERSION}


def list_suite(track: str = "core") -> list[str]:
    """Names of a benchmark track's scenarios (default: the core suite).

    Raises:
        ValueError: An unknown track (the message lists them).
    """
    if track not in TRACKS:
        raise ValueError(f"unknown track {track!r}; choose one of {sorted(TRACKS)}.")
    return list(TRACKS[track])


def track_of(name: str) -> str | None:
    """The track of a scenario name (its ``_shift`` variant too), or None."""
    base = name.removesuffix("_shift")
    return next((track for track, names in TRACKS.items() if base in names), None)


def is_deterministic(scenario: Scenario) -> bool:
    """Whether every episode of ``scenario`` is the same, whatever the seed.

    True when nothing is drawn at reset or during the episode: no initial
    spread, no model spread, no noise in current, waves or wind, no packet
    loss. Mean disturbances, delays and the paper's deterministic unmodeled
    dynamics do not make a scenario random.
    """
    initial = scenario.initial
    disturbances = scenario.disturbances
    noise = (
        initial.position_std,
        initial.heading_std,
        initial.theta_std,
        scenario.model_spread,
        disturbances.current.std,
        *disturbances.waves.std,
        *disturbances.wind.std,
        scenario.links.loss_probability,
    )
    return not any(value > 0.0 for value in noise)


for _factory in _FACTORIES:
    register(_factory.__name__, _factory)
