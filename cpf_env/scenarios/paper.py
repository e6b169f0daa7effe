"""The named scenarios: the paper's simulation and its harder variants.

``wang2014`` is the paper's section 4; the others keep its fleet and paths and
change one thing each (saturation, current and waves, lossy links, switching
topology, model spread), plus a ten-vessel fleet. They start from fixed poses
(only ``heterogeneous`` and ``large_fleet`` draw noisy starts); the benchmark
suite (``cpf_env.scenarios.suite``) randomizes them.

    >>> from cpf_env import scenarios
    >>> scenarios.get("lossy_links").links.delay_steps
    5
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from cpf_env.model.disturbances import Disturbances, GaussMarkov, OceanCurrent
from cpf_env.model.graph import Graph, SwitchingTopology
from cpf_env.model.links import LinkImpairments
from cpf_env.model.paths import Path, Sinusoid
from cpf_env.scenarios.registry import register
from cpf_env.scenarios.scenario import InitialState, Scenario

__all__ = [
    "current_and_waves",
    "heterogeneous",
    "large_fleet",
    "lossy_links",
    "saturation_heavy",
    "switching_topology",
    "wang2014",
]

#: Lateral offsets y_i (m) of the paper's five sinusoids (docs/model.md, section 10).
_WANG2014_OFFSETS = (-8.0, -4.0, 0.0, 4.0, 8.0)


def _parallel_sinusoids(offsets: Sequence[float]) -> tuple[Path, ...]:
    """The paper's paths: x_d = theta, y_d = y_i + 2 sin(0.2 theta)."""
    return tuple(Sinusoid(y0=y, amplitude=2.0, wavenumber=0.2) for y in offsets)


def wang2014() -> Scenario:
    """The paper's section 4 (docs/model.md, s. 10): five Cybership II, chain graph, v0 = 0.1."""
    offsets = _WANG2014_OFFSETS
    x0 = [-1.0, 1.0, -0.5, 0.5, 0.0]
    dy = [1.0, -1.0, 0.5, -0.5, 1.0]
    return Scenario(
        name="wang2014",
        paths=_parallel_sinusoids(offsets),
        topology=Graph.path(5, leaders=(0, 3)),
        initial=InitialState(
            eta=tuple((x, y + d, 0.0) for x, y, d in zip(x0, offsets, dy, strict=True))
        ),
        description="The paper's simulation: 5 vessels, sinusoids, chain graph, b = [1,0,0,1,0].",
    )


def saturation_heavy() -> Scenario:
    """Fast run with large initial errors and halved force limits: sustained saturation."""
    offsets = _WANG2014_OFFSETS
    return wang2014().replace(
        name="saturation_heavy",
        v0=0.5,
        tau_max=(4.6, 2.25, 1.5),
        initial=InitialState(
            eta=tuple((-2.0, y + 3.0 * (-1) ** k, 0.6) for k, y in enumerate(offsets))
        ),
        max_steps=1200,
        description="v0 = 0.5 m/s, 3 m initial offsets, force limits halved.",
    )


def current_and_waves() -> Scenario:
    """The paper's task in a slowly varying current with wave and wind forces."""
    return wang2014().replace(
        name="current_and_waves",
        disturbances=Disturbances(
            current=OceanCurrent(velocity=(0.05, 0.03), std=0.01, time_constant=60.0),
            waves=GaussMarkov(std=(0.5, 0.5, 0.1), time_constant=2.0),
            wind=GaussMarkov(mean=(0.3, 0.2, 0.0), std=(0.2, 0.2, 0.05), time_constant=30.0),
        ),
        description="Current 0.06 m/s (varying), Gauss-Markov waves and wind.",
    )


def lossy_links() -> Scenario:
    """The paper's task over links that lose 30 % of packets and delay them 0.25 s."""
    return wang2014().replace(
        name="lossy_links",
        links=LinkImpairments(loss_probability=0.3, delay_steps=5),
        description="30 % packet loss and 5-step delay on every link.",
    )


def switching_topology() -> Scenario:
    """The paper's task over a topology that cycles chain -> ring -> star every 10 s."""
    graphs = (
        Graph.path(5, leaders=(0, 3)),
        Graph.ring(5, leaders=(2,)),
        Graph.star(5, center=2, leaders=(4,)),
    )
    return wang2014().replace(
        name="switching_topology",
        topology=SwitchingTopology(graphs=graphs, switch_steps=(0, 200, 400), period=600),
        description="Chain, ring, star in turn, 10 s each; leader links change too.",
    )


def heterogeneous() -> Scenario:
    """Every vessel's true model drawn +-30 % around Cybership II, random initial poses."""
    base = wang2014()
    return base.replace(
        name="heterogeneous",
        model_spread=0.3,
        initial=dataclasses.replace(base.initial, position_std=0.5, heading_std=0.2),
        description="True models +-30 % around Cybership II per reset, noisy initial poses.",
    )


def large_fleet() -> Scenario:
    """Ten vessels on parallel sinusoids, ring graph, two leader links, noisy start."""
    offsets = [4.0 * (k - 4.5) for k in range(10)]
    return Scenario(
        name="large_fleet",
        paths=_parallel_sinusoids(offsets),
        topology=Graph.ring(10, leaders=(0, 5)),
        initial=InitialState(
            eta=tuple((0.0, y + 1.0, 0.0) for y in offsets), position_std=0.5, heading_std=0.1
        ),
        description="n = 10, ring graph, leaders 0 and 5.",
    )


for _factory in (
    wang2014,
    saturation_heavy,
    current_and_waves,
    lossy_links,
    switching_topology,
    heterogeneous,
    large_fleet,
):
    register(_factory.__name__, _factory)
