"""Crossing paths: pairs of vessels whose straight paths cross, timed to meet unless they give way.

The paper's fleets sail parallel paths 4 m apart and never come near each
other. Here the fleet is ``pairs`` pairs laid out on a diagonal staircase,
pair k (vessels 2k and 2k + 1) at the crossing point c_k = (s k, s k),
``s`` = ``spacing``:

* vessel 2k sails east along y = s k, from x = s k - ``lead`` (theta = 0);
* vessel 2k + 1 sails north along x = s k, from y = s k - ``lead`` - ``offset``.

Both are parameterized by arc length and the fleet synchronizes its path
variables, so when vessel 2k reaches c_k (theta = ``lead``) its partner is
``offset`` metres short of it, and the synchronized pair passes at its
closest d = ``offset`` / sqrt(2). With the default offset of 1.2 m that is
0.85 m: inside a keep-out distance of 1.5 m, outside a collision distance
of 0.5 m (``cpf_env.model.separation``). A fleet that holds its formation
exactly pays the separation cost; one that lets a path error of a few
decimetres grow, collides. Giving way costs path error or synchronization:
the trade-off a controller has to make. Any two vessels of different pairs
stay further apart (4.8 m at the least with the defaults, over the first
20 m of path).

The graph is a ring in vessel order with the leader links given, so the
partners of every crossing are neighbours and can hear each other's
messages (over whatever links the scenario has); vessels of different pairs
meet only through the ring.

    >>> paths, initial, topology = crossing_fleet(2)
    >>> [round(p.heading, 3) for p in paths], topology.n
    ([0.0, 1.571, 0.0, 1.571], 4)
"""

from __future__ import annotations

import math

from cpf_env.model.graph import Graph
from cpf_env.model.paths import Path, StraightLine
from cpf_env.scenarios.scenario import InitialState

__all__ = ["crossing_fleet"]


def crossing_fleet(
    pairs: int,
    spacing: float = 4.0,
    lead: float = 4.0,
    offset: float = 1.2,
    leaders: tuple[int, ...] = (0,),
) -> tuple[tuple[Path, ...], InitialState, Graph]:
    """Paths, nominal start (at theta = 0, heading along the path) and ring graph of the layout.

    Args:
        pairs: Number of crossing pairs (2 ``pairs`` vessels), >= 1.
        spacing: s, the distance between consecutive crossing points along each axis (m),
            > ``offset``.
        lead: How far the eastbound vessel of a pair starts before its crossing (m), > 0.
        offset: How far its northbound partner is behind it in the synchronized formation
            (m), > 0; the pair's closest approach is offset / sqrt(2).
        leaders: The vessels that hear v0.

    Raises:
        ValueError: A layout whose vessels would pass closer than their partners do, or
            a non-positive distance.
    """
    if pairs < 1 or not (lead > 0.0 and 0.0 < offset < spacing):
        raise ValueError(
            f"crossing_fleet needs pairs >= 1, lead > 0 and 0 < offset < spacing (m), got "
            f"pairs={pairs}, lead={lead}, offset={offset}, spacing={spacing}: with offset >= "
            "spacing the vessels of neighbouring pairs would cross closer than partners."
        )
    paths: list[Path] = []
    eta: list[tuple[float, float, float]] = []
    for k in range(pairs):
        corner = spacing * k
        east = StraightLine(x0=corner - lead, y0=corner, heading=0.0)
        north = StraightLine(x0=corner, y0=corner - lead - offset, heading=math.pi / 2.0)
        paths += [east, north]
        eta += [(east.x0, east.y0, 0.0), (north.x0, north.y0, math.pi / 2.0)]
    topology = Graph.ring(2 * pairs, leaders=leaders) if pairs > 1 else Graph.path(2, leaders)
    return tuple(paths), InitialState(eta=tuple(eta)), topology
