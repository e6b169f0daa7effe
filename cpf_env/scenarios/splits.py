"""Held-out conditions of the benchmark suite: training, ``test`` and ``shift``.

Every suite scenario (``cpf_env.scenarios.suite``) is its own training
distribution: the ranges of its random parameters (initial spread, model
spread, disturbance noise, packet loss) are the ones it declares. Two
evaluation splits are held out from it:

* ``test``: the same scenario, on evaluation seeds (``EVALUATION_SEED`` and
  up), which training never draws;
* ``shift``: ``<name>_shift``, conditions outside the training ranges
  (``SHIFTS`` says which), on the same evaluation seeds.

=========================  ==================================================================
training scenario          its ``shift`` (outside the training ranges)
=========================  ==================================================================
``bench_mild``             sinusoids of amplitude 3 m, wavenumber 0.3 /m (were 2 m, 0.2 /m)
``bench_saturation``       v0 0.6 m/s (was 0.5), force limits x 0.8
``bench_current_waves``    current 0.12 m/s +- 0.02 (was 0.06 +- 0.01), waves and wind std
                           x 2, model spread 20 % (was 10 %)
``bench_lossy_links``      50 % loss (was 30 %), 10-step delay (was 5)
``bench_switching``        the graph switches every 5 s (was 10 s)
``bench_heterogeneous``    models +- 45 % (was +- 30 %)
``bench_large_fleet``      n = 7 on a star graph (was n = 10 on a ring), 20 % loss (was 10 %)
``hard_*``                 its core scenario's shift (the crossing scenarios: starts spread
                           0.5 m (was 0.3 m), 20 % more packets lost, twice the delay), with
                           fixes of 3 cm and 1.5 degrees every 6 steps, 10 % lost (were 2 cm,
                           1 degree, 4 steps, 5 %), and thrusters with a 0.8 s lag and slew
                           limits x 0.7 (were 0.5 s), where it has them
                           (``cpf_env.scenarios.hard``)
=========================  ==================================================================

Between training and the splits sit the validation seeds, ``VALIDATION_SEED``
(9,000) to ``EVALUATION_SEED`` - 1: the training distribution on seeds no
training draws, on which a training run evaluates itself and keeps its best
agent, so that choosing an agent never sees a seed the benchmark reports.
Training code draws only from the training distribution: ``check_training``
refuses a ``_shift`` scenario and any reset seed at or above
``VALIDATION_SEED``.

Example:
    >>> from cpf_env.scenarios import splits
    >>> splits.split_scenario("bench_lossy_links", "shift").links.delay_steps
    10
    >>> splits.check_training("bench_lossy_links", range(0, 256))
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterable

import numpy as np

from cpf_env.model.disturbances import GaussMarkov
from cpf_env.model.graph import Graph, SwitchingTopology
from cpf_env.model.links import LinkImpairments
from cpf_env.model.paths import Sinusoid
from cpf_env.scenarios import hard, suite
from cpf_env.scenarios.registry import get, register
from cpf_env.scenarios.scenario import Scenario

__all__ = [
    "CORE_SHIFTS",
    "EVALUATION_SEED",
    "SHIFTS",
    "SPLITS",
    "VALIDATION_SEED",
    "check_training",
    "split_scenario",
    "suite_version",
]

#: First evaluation seed: the ``test`` and ``shift`` splits reset with seeds from here.
EVALUATION_SEED = 10_000
#: First validation seed: seeds ``VALIDATION_SEED`` .. ``EVALUATION_SEED`` - 1 select among
#: a training run's agents (its evaluations during training and its best agent), so the
#: benchmark's seeds play no part in any choice; training resets use seeds below it.
VALIDATION_SEED = 9_000
#: The evaluation splits.
SPLITS = ("test", "shift")
SHIFT_SUFFIX = "_shift"


def _scaled(noise: GaussMarkov, factor: float) -> GaussMarkov:
    x, y, r = noise.std
    return dataclasses.replace(noise, std=(factor * x, factor * y, factor * r))


def _mild() -> Scenario:
    base = suite.bench_mild()
    paths = tuple(
        Sinusoid(y0=p.y0, amplitude=3.0, wavenumber=0.3)  # type: ignore[attr-defined]
        for p in base.paths
    )
    return base.replace(paths=paths)


def _saturation() -> Scenario:
    base = suite.bench_saturation()
    tau_max = tuple(tuple(0.8 * t for t in row) for row in np.atleast_2d(base.tau_max).tolist())
    return base.replace(v0=0.6, tau_max=tau_max)


def _current_waves() -> Scenario:
    base = suite.bench_current_waves()
    d = base.disturbances
    current = dataclasses.replace(d.current, velocity=(0.1, 0.06), std=0.02)
    disturbances = dataclasses.replace(
        d, current=current, waves=_scaled(d.waves, 2.0), wind=_scaled(d.wind, 2.0)
    )
    return base.replace(disturbances=disturbances, model_spread=0.2)


def _lossy_links() -> Scenario:
    return suite.bench_lossy_links().replace(
        links=LinkImpairments(loss_probability=0.5, delay_steps=10)
    )


def _switching() -> Scenario:
    base = suite.bench_switching()
    topology = base.topology
    assert isinstance(topology, SwitchingTopology)
    return base.replace(
        topology=SwitchingTopology(
            graphs=topology.graphs, switch_steps=(0, 100, 200, 300), period=400
        )
    )


def _heterogeneous() -> Scenario:
    return suite.bench_heterogeneous().replace(model_spread=0.45)


def _large_fleet() -> Scenario:
    base = suite.bench_large_fleet()
    offsets = [4.0 * (k - 3) for k in range(7)]
    initial = dataclasses.replace(
        base.initial, eta=tuple((0.0, y + 1.0, 0.0) for y in offsets), nu=None, theta=None
    )
    return base.replace(
        paths=tuple(Sinusoid(y0=y, amplitude=2.0, wavenumber=0.2) for y in offsets),
        topology=Graph.star(7, center=3, leaders=(3,)),
        initial=initial,
        links=LinkImpairments(loss_probability=0.2),
    )


#: Core suite scenario -> its shifted variant's factory.
CORE_SHIFTS: dict[str, Callable[[], Scenario]] = {
    "bench_mild": _mild,
    "bench_saturation": _saturation,
    "bench_current_waves": _current_waves,
    "bench_lossy_links": _lossy_links,
    "bench_switching": _switching,
    "bench_heterogeneous": _heterogeneous,
    "bench_large_fleet": _large_fleet,
}


def _hard_shift(name: str) -> Scenario:
    """Hard scenario ``name``'s shift, with the shifted mechanisms it has.

    A scenario on a core task shifts as the core task does, a crossing scenario
    by ``hard.crossing_shift``; then ``SHIFTED_FIX`` and ``SHIFTED_THRUSTERS``
    replace its sensors and thrusters where it has them, and a hull without
    sway stays without.
    """
    task = get(name)
    if name in hard.BASES:
        base = CORE_SHIFTS[hard.BASES[name]]()
    else:
        base = hard.crossing_shift(task)
    changes: dict[str, object] = {}
    if not task.sensors.ideal:
        changes["sensors"] = hard.SHIFTED_FIX
    if not task.thrusters.instant:
        changes["thrusters"] = hard.SHIFTED_THRUSTERS
    if not task.actuated[:, 1].any():
        base = hard.without_sway(base)
    return base.replace(**changes)


#: Every track's scenario -> its shifted variant's factory.
SHIFTS: dict[str, Callable[[], Scenario]] = {
    **CORE_SHIFTS,
    **{
        factory.__name__: functools.partial(_hard_shift, factory.__name__)
        for factory in hard.HARD_FACTORIES
    },
}


def _named(name: str) -> Scenario:
    scenario = SHIFTS[name]()
    return scenario.replace(
        name=name + SHIFT_SUFFIX,
        description=f"{name} outside its training ranges (cpf_env.scenarios.splits).",
    )


def split_scenario(name: str, split: str) -> Scenario:
    """The scenario an evaluation split runs for the suite scenario ``name``.

    Args:
        name: A suite scenario (``suite.SUITE``).
        split: ``test`` (the scenario itself) or ``shift`` (``<name>_shift``).

    Raises:
        ValueError: An unknown split, or a scenario without a shift variant.
    """
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose one of {list(SPLITS)}.")
    if name not in SHIFTS:
        raise ValueError(
            f"{name!r} has no held-out splits; only the tracks' scenarios do: {sorted(SHIFTS)}."
        )
    return get(name) if split == "test" else _named(name)


def suite_version(name: str) -> int | None:
    """The version of the track of a scenario or its shift variant, else None.

    Example:
        >>> suite_version("bench_mild_shift") == suite.SUITE_VERSION, suite_version("wang2014")
        (True, None)
        >>> suite_version("hard_sensing") == suite.HARD_VERSION
        True
    """
    track = suite.track_of(name)
    return None if track is None else suite.TRACK_VERSIONS[track]


def check_training(scenario: str | Scenario, seeds: Iterable[int]) -> None:
    """Refuse to train on an evaluation split or on held-out seeds.

    Args:
        scenario: The training scenario (name or object).
        seeds: Every reset seed training will use.

    Raises:
        ValueError: A ``_shift`` scenario, or a seed >= ``VALIDATION_SEED`` (the
            validation seeds, then the evaluation seeds).
    """
    name = scenario if isinstance(scenario, str) else scenario.name
    if name.endswith(SHIFT_SUFFIX) and name[: -len(SHIFT_SUFFIX)] in SHIFTS:
        raise ValueError(
            f"{name} is the held-out shift split of {name[: -len(SHIFT_SUFFIX)]}; train on "
            f"{name[: -len(SHIFT_SUFFIX)]} and evaluate on {name}."
        )
    used = [int(seed) for seed in seeds if int(seed) >= VALIDATION_SEED]
    if used:
        raise ValueError(
            f"training would reset fleets with held-out seeds (from {used[0]}; seeds "
            f"{VALIDATION_SEED}-{EVALUATION_SEED - 1} select a run's best agent, seeds >= "
            f"{EVALUATION_SEED} are cpf-bench's evaluation seeds); choose a seed below "
            f"{VALIDATION_SEED} minus the number of fleets."
        )


for _name in SHIFTS:
    register(_name + SHIFT_SUFFIX, functools.partial(_named, _name))
