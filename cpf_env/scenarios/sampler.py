"""A procedural distribution over fleets: sizes, graphs, paths, disturbances, links, models.

Training a learner on the suite's seven fleets teaches it those fleets, not
the task. ``ScenarioDistribution`` is a frozen, seeded distribution over
fleets that training draws from instead:

* fleet size n in ``sizes`` (inclusive range);
* graph family: ``chain``, ``ring``, ``star`` (a random centre) or ``random``
  (a random spanning tree plus extra edges, always connected), with 1 to
  ``max(1, n // 3)`` random leader links, optionally capped at a largest degree;
* path family: ``line``, ``sinusoid``, ``circle`` (concentric, 4 m apart),
  ``lemniscate`` or ``mixed`` (each vessel draws one of the four shapes),
  all laid out along a common random heading with 4 m lateral spacing;
* a current of random direction and speed, Gauss-Markov waves and wind of
  random strength;
* packet loss and delay; model spread; leader speed;
* actuator limits: the nominal force limits times a drawn ``force_scale``
  (1 by default, so the default draws keep the nominal limits).

Every draw passes ``Scenario``'s checks and ``Graph.validate_for_consensus``.
``sample(seed)`` is deterministic: the same seed gives an equal scenario.

Held-out sets. The suite's ``test`` and ``shift`` splits are evaluation sets
(``cpf_env.scenarios.splits``); a draw equal to one of them (up to its name)
is refused, and so is a draw named like one. Draw seeds follow the suite's
rule: seeds below ``splits.EVALUATION_SEED`` are training fleets, seeds at or
above it are held-out fleets that only evaluation draws
(``sample(seed, evaluation=True)``).

Example:
    >>> from cpf_env.scenarios.sampler import ScenarioDistribution
    >>> fleets = ScenarioDistribution(sizes=(3, 6))
    >>> a, b = fleets.sample(7), fleets.sample(7)
    >>> a == b, 3 <= a.n <= 6, a.name
    (True, True, 'procedural_7')
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import cast

import numpy as np

from cpf_env.model.disturbances import Disturbances, GaussMarkov, OceanCurrent
from cpf_env.model.graph import Graph
from cpf_env.model.links import LinkImpairments
from cpf_env.model.paths import Circle, Lemniscate, Path, Sinusoid, StraightLine
from cpf_env.scenarios import splits
from cpf_env.scenarios.scenario import InitialState, Scenario
from cpf_env.scenarios.suite import BENCH_STEPS, HEADING_STD, POSITION_STD, THETA_STD

__all__ = [
    "GRAPH_FAMILIES",
    "NOMINAL_TAU_MAX",
    "PATH_FAMILIES",
    "ScenarioDistribution",
    "check_not_held_out",
]

#: Graph families the distribution draws from.
GRAPH_FAMILIES = ("chain", "ring", "star", "random")
#: Path families; ``mixed`` draws a shape per vessel from the other four.
PATH_FAMILIES = ("line", "sinusoid", "circle", "lemniscate", "mixed")
#: Lateral spacing between neighbouring paths (m).
SPACING = 4.0

Range = tuple[float, float]

#: The nominal force limits (N, N, N m) that ``force_scale`` multiplies: ``Scenario``'s default.
NOMINAL_TAU_MAX = cast(
    tuple[float, float, float],
    next(f.default for f in dataclasses.fields(Scenario) if f.name == "tau_max"),
)


def _check_range(name: str, value: Range, low: float, high: float) -> None:
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise ValueError(
            f"ScenarioDistribution.{name} = {value!r} must be a range (lo, hi) of two numbers."
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and low <= lo <= hi <= high):
        raise ValueError(
            f"ScenarioDistribution.{name} = {value} must be a range (lo, hi) with "
            f"{low} <= lo <= hi <= {high}."
        )


@functools.cache
def _held_out() -> tuple[Scenario, ...]:
    """Every scenario of the suite's evaluation splits (``test`` and ``shift``)."""
    return tuple(
        splits.split_scenario(name, split) for name in splits.SHIFTS for split in splits.SPLITS
    )


def check_not_held_out(scenario: Scenario) -> None:
    """Refuse a scenario that is one of the suite's evaluation splits.

    Args:
        scenario: A candidate training scenario.

    Raises:
        ValueError: It is named like a suite scenario or a shift split, or it
            equals one of them in every field but its name and description.
    """
    for held in _held_out():
        if (
            scenario.name == held.name
            or scenario.replace(name=held.name, description=held.description) == held
        ):
            raise ValueError(
                f"scenario {scenario.name!r} is the evaluation split {held.name!r} "
                "(cpf_env.scenarios.splits); training must draw from the procedural "
                "distribution or the training scenarios, never from the test or shift splits."
            )
    splits.check_training(scenario, ())


def _graph(kind: str, n: int, rng: np.random.Generator, max_degree: int | None) -> Graph:
    """A connected graph of family ``kind`` with random leader links."""
    leaders = tuple(
        int(i)
        for i in np.sort(
            rng.choice(n, size=int(rng.integers(1, max(1, n // 3) + 1)), replace=False)
        )
    )
    if kind == "chain" or n <= 2:
        return Graph.path(n, leaders=leaders)
    if kind == "ring":
        return Graph.ring(n, leaders=leaders)
    if kind == "star":
        return Graph.star(n, center=int(rng.integers(n)), leaders=leaders)
    order = rng.permutation(n)
    degree = np.zeros(n, dtype=np.int64)
    edges: set[tuple[int, int]] = set()
    cap = n - 1 if max_degree is None else max_degree
    for k in range(1, n):  # a random spanning tree, each node joins an earlier one
        earlier = [int(order[j]) for j in range(k) if degree[order[j]] < cap]
        j = earlier[int(rng.integers(len(earlier)))]
        i = int(order[k])
        edges.add((min(i, j), max(i, j)))
        degree[[i, j]] += 1
    for i in range(n):  # extra edges, about one per vessel
        for j in range(i + 1, n):
            if (i, j) not in edges and rng.random() < 1.0 / n and max(degree[i], degree[j]) < cap:
                edges.add((i, j))
                degree[[i, j]] += 1
    return Graph.from_edges(n, [(i, j, 1.0) for i, j in sorted(edges)], leaders=leaders)


def _path(
    shape: str, offset: float, heading: float, radius: float, rng: np.random.Generator
) -> Path:
    """One path of ``shape``, offset laterally by ``offset`` (m) from an axis along ``heading``.

    Circles share one centre, ``radius`` (m) to the left of the axis, so the
    circle of a vessel offset by ``offset`` has radius ``radius - offset``.
    """
    x0, y0 = -offset * math.sin(heading), offset * math.cos(heading)
    if shape == "line":
        return StraightLine(x0=x0, y0=y0, heading=heading)
    if shape == "sinusoid":
        return Sinusoid(
            x0=x0,
            y0=y0,
            heading=heading,
            amplitude=float(rng.uniform(0.5, 3.0)),
            wavenumber=float(rng.uniform(0.1, 0.3)),
        )
    if shape == "circle":  # starts at (x0, y0) travelling along ``heading``, counter-clockwise
        return Circle(
            cx=-radius * math.sin(heading),
            cy=radius * math.cos(heading),
            radius=radius - offset,
            phase=heading - math.pi / 2.0,
        )
    return Lemniscate(cx=x0, cy=y0, half_width=float(rng.uniform(20.0, 40.0)), heading=heading)


@dataclass(frozen=True)
class ScenarioDistribution:
    """A frozen, seeded distribution over fleets (ranges are inclusive).

    Attributes:
        sizes: Fleet size range (vessels), n >= 2.
        graph_families: Families drawn uniformly (``GRAPH_FAMILIES``).
        path_families: Families drawn uniformly (``PATH_FAMILIES``).
        max_degree: Largest neighbour count of any vessel (the learner's
            neighbour slots), or None for no cap. ``star`` is skipped when the
            fleet is too large for it; ``chain`` needs max_degree >= 2.
        v0: Leader speed range (m/s).
        current_speed: Mean current speed range (m/s), random direction.
        wave_std: Range of the wave force std on surge and sway (N); yaw gets a fifth.
        wind_mean: Range of the mean wind force on surge and sway (N).
        loss: Packet-loss probability range.
        delay: Transport delay range (control steps).
        model_spread: Relative model spread range.
        force_scale: Range of the factor on the nominal force limits
            (``NOMINAL_TAU_MAX``), one draw for the whole fleet; drawn last, so
            widening it leaves every other draw of a seed as it was.
        max_steps: Episode length (control steps).
        name: Prefix of the drawn scenarios' names (``<name>_<seed>``).
    """

    sizes: tuple[int, int] = (3, 8)
    graph_families: tuple[str, ...] = GRAPH_FAMILIES
    path_families: tuple[str, ...] = PATH_FAMILIES
    max_degree: int | None = None
    v0: Range = (0.05, 0.3)
    current_speed: Range = (0.0, 0.1)
    wave_std: Range = (0.0, 0.8)
    wind_mean: Range = (0.0, 0.4)
    loss: Range = (0.0, 0.4)
    delay: tuple[int, int] = (0, 6)
    model_spread: Range = (0.0, 0.3)
    force_scale: Range = (1.0, 1.0)
    max_steps: int = BENCH_STEPS
    name: str = "procedural"

    def __post_init__(self) -> None:
        lo, hi = self.sizes
        if not (isinstance(lo, int) and isinstance(hi, int) and 2 <= lo <= hi):
            raise ValueError(
                f"ScenarioDistribution.sizes = {self.sizes} must be ints 2 <= lo <= hi."
            )
        for name, values, known in (
            ("graph_families", self.graph_families, GRAPH_FAMILIES),
            ("path_families", self.path_families, PATH_FAMILIES),
        ):
            unknown = sorted(set(values) - set(known))
            if not values or unknown:
                raise ValueError(
                    f"ScenarioDistribution.{name} = {values} must be a non-empty subset of {known}."
                )
        if self.max_degree is not None and self.max_degree < 2:
            raise ValueError(f"max_degree must be >= 2 or None, got {self.max_degree}.")
        _check_range("v0", self.v0, 0.0, 2.0)
        _check_range("current_speed", self.current_speed, 0.0, 1.0)
        _check_range("wave_std", self.wave_std, 0.0, 10.0)
        _check_range("wind_mean", self.wind_mean, 0.0, 10.0)
        _check_range("loss", self.loss, 0.0, 0.95)
        _check_range("delay", self.delay, 0, self.max_steps - 1)
        _check_range("model_spread", self.model_spread, 0.0, 0.9)
        _check_range("force_scale", self.force_scale, 0.1, 2.0)

    def _graph_kinds(self, n: int) -> list[str]:
        """The families that fit a fleet of n under ``max_degree``."""
        cap = self.max_degree
        fits = {"chain": True, "ring": True, "star": cap is None or n - 1 <= cap, "random": True}
        kinds = [kind for kind in self.graph_families if fits[kind]]
        if not kinds:
            raise ValueError(
                f"no graph family of {self.graph_families} fits n = {n} with max_degree = "
                f"{cap}; add 'chain', 'ring' or 'random', or raise max_degree."
            )
        return kinds

    def sample(self, seed: int, *, evaluation: bool = False) -> Scenario:
        """Draw the fleet of ``seed``.

        Args:
            seed: Draw seed: below ``splits.EVALUATION_SEED`` for training,
                at or above it with ``evaluation=True`` for held-out fleets.
            evaluation: Draw a held-out fleet (seed >= ``EVALUATION_SEED``).

        Returns:
            A valid scenario named ``<name>_<seed>``.

        Raises:
            ValueError: A seed on the wrong side of ``EVALUATION_SEED``, or a
                draw that is one of the suite's evaluation splits.
        """
        seed = int(seed)
        if seed < 0 or (seed >= splits.EVALUATION_SEED) != evaluation:
            side = "at or above" if evaluation else "below"
            raise ValueError(
                f"draw seed {seed}: {'evaluation' if evaluation else 'training'} draws use "
                f"seeds {side} {splits.EVALUATION_SEED} (splits.EVALUATION_SEED), >= 0; "
                "held-out fleets are drawn with sample(seed, evaluation=True)."
            )
        rng = np.random.default_rng([seed, 0x5CE7A210])
        n = int(rng.integers(self.sizes[0], self.sizes[1] + 1))
        kinds = self._graph_kinds(n)
        graph_kind = kinds[int(rng.integers(len(kinds)))]
        graph = _graph(graph_kind, n, rng, self.max_degree)
        graph.validate_for_consensus()
        family = self.path_families[int(rng.integers(len(self.path_families)))]
        shapes = [
            PATH_FAMILIES[int(rng.integers(4))] if family == "mixed" else family for _ in range(n)
        ]
        heading = float(rng.uniform(-math.pi, math.pi))
        offsets = [SPACING * (i - (n - 1) / 2.0) for i in range(n)]
        radius = float(rng.uniform(20.0, 40.0)) + offsets[-1]
        paths = tuple(
            _path(s, o, heading, radius, rng) for s, o in zip(shapes, offsets, strict=True)
        )
        starts = [p.evaluate(0.0)[0] for p in paths]
        initial = InitialState(
            eta=tuple((float(e[0]), float(e[1]), float(e[2])) for e in starts),
            position_std=POSITION_STD,
            heading_std=HEADING_STD,
            theta_std=THETA_STD,
        )
        speed, direction = rng.uniform(*self.current_speed), rng.uniform(-math.pi, math.pi)
        waves, wind = rng.uniform(*self.wave_std), rng.uniform(*self.wind_mean, size=2)
        disturbances = Disturbances(
            current=OceanCurrent(
                velocity=(speed * math.cos(direction), speed * math.sin(direction)),
                std=0.2 * speed,
                time_constant=60.0,
            ),
            waves=GaussMarkov(std=(waves, waves, 0.2 * waves), time_constant=2.0),
            wind=GaussMarkov(
                mean=(float(wind[0]), float(wind[1]), 0.0),
                std=(0.5 * float(wind[0]), 0.5 * float(wind[1]), 0.0),
                time_constant=30.0,
            ),
        )
        links = LinkImpairments(
            loss_probability=float(rng.uniform(*self.loss)),
            delay_steps=int(rng.integers(self.delay[0], self.delay[1] + 1)),
        )
        spread, v0 = float(rng.uniform(*self.model_spread)), float(rng.uniform(*self.v0))
        force_scale = float(rng.uniform(*self.force_scale))
        surge, sway, yaw = NOMINAL_TAU_MAX
        scenario = Scenario(
            name=f"{self.name}_{seed}",
            paths=paths,
            topology=graph,
            initial=initial,
            model_spread=spread,
            v0=v0,
            tau_max=(force_scale * surge, force_scale * sway, force_scale * yaw),
            disturbances=disturbances,
            links=links,
            max_steps=self.max_steps,
            description=(
                f"Procedural draw {seed}: n = {n}, {graph_kind} graph, {family} paths, "
                f"{'evaluation' if evaluation else 'training'} fleet."
            ),
        )
        check_not_held_out(scenario)
        return scenario

    def describe(self, scenario: Scenario) -> dict[str, object]:
        """A summary of a draw for logs: size, degrees, path kinds, links, spread."""
        graph = scenario.switching.graphs[0]
        return {
            "name": scenario.name,
            "n": scenario.n,
            "max_degree": int(graph.degree.max()),
            "leaders": graph.leaders,
            "paths": sorted({type(p).__name__ for p in scenario.paths}),
            "links": dataclasses.asdict(scenario.links),
            "model_spread": scenario.model_spread,
            "v0": scenario.v0_schedule.values[0],
            "tau_max": scenario.tau_limits[1][0].tolist(),
        }
