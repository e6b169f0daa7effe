"""Tests for cpf_env.model.graph: Laplacian facts, constructors, validation, switching, slots."""

from __future__ import annotations

import numpy as np
import pytest

from cpf_env.model.graph import (
    Graph,
    SwitchingTopology,
    as_switching,
    leader_schedule,
    neighbour_slots,
    slot_weights,
    switch_table,
)
from cpf_env.model.links import LinkImpairments

PAPER_L = np.array(
    [
        [1, -1, 0, 0, 0],
        [-1, 2, -1, 0, 0],
        [0, -1, 2, -1, 0],
        [0, 0, -1, 2, -1],
        [0, 0, 0, -1, 1],
    ],
    dtype=float,
)

CONNECTED = [
    Graph.path(5, leaders=(0, 3)),
    Graph.path(4, weight=2.5),
    Graph.ring(6, leaders=(2,)),
    Graph.complete(4),
    Graph.star(5, center=2),
    Graph.from_edges(4, [(0, 1, 0.5), (1, 2), (1, 3, 3.0)], leaders=(3,)),
    Graph.path(1),
]
DISCONNECTED = [
    Graph.from_edges(5, [(0, 1), (3, 4)]),
    Graph.from_edges(3, []),
    Graph(np.zeros((2, 2)), np.ones(2)),
]


# --------------------------------------------------------------------------- Laplacian
@pytest.mark.parametrize("g", CONNECTED + DISCONNECTED)
def test_laplacian_facts(g: Graph) -> None:
    lap = g.laplacian
    assert lap.shape == (g.n, g.n)
    np.testing.assert_array_equal(lap, lap.T)
    np.testing.assert_allclose(lap.sum(axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(lap @ np.ones(g.n), 0.0, atol=1e-12)
    eig = np.linalg.eigvalsh(lap)
    assert eig.min() > -1e-10
    fiedler = eig[1] if g.n > 1 else 1.0  # a single vessel is trivially connected
    assert (fiedler > 1e-9) == g.is_connected()


@pytest.mark.parametrize("g", CONNECTED)
def test_l_plus_b_positive_definite_when_connected_with_leader(g: Graph) -> None:
    g.validate_for_consensus()
    assert np.linalg.eigvalsh(g.laplacian + np.diag(g.leader_links)).min() > 1e-9


def test_paper_graph() -> None:
    g = Graph.path(5, leaders=(0, 3))
    np.testing.assert_array_equal(g.laplacian, PAPER_L)
    np.testing.assert_array_equal(g.leader_links, [1, 0, 0, 1, 0])
    assert g.leaders == (0, 3)
    assert g.is_connected()


def test_weighted_laplacian() -> None:
    g = Graph.from_edges(3, [(0, 1, 2.0), (1, 2, 0.5)])
    expected = np.array([[2.0, -2.0, 0.0], [-2.0, 2.5, -0.5], [0.0, -0.5, 0.5]])
    np.testing.assert_array_equal(g.laplacian, expected)
    np.testing.assert_array_equal(g.degree, [1, 2, 1])


def test_components() -> None:
    assert DISCONNECTED[0].components() == [(0, 1), (2,), (3, 4)]
    assert Graph.ring(7).components() == [tuple(range(7))]
    assert not DISCONNECTED[0].is_connected()


# ------------------------------------------------------------------------ constructors
def test_path() -> None:
    g = Graph.path(4, weight=2.0)
    np.testing.assert_array_equal(g.degree, [1, 2, 2, 1])
    assert [g.neighbours(i) for i in range(4)] == [(1,), (0, 2), (1, 3), (2,)]
    assert g.adjacency[1, 2] == 2.0
    assert g.leaders == (0,)


def test_ring() -> None:
    g = Graph.ring(5, leaders=(1, 4))
    np.testing.assert_array_equal(g.degree, [2] * 5)
    assert g.neighbours(0) == (1, 4)
    assert g.neighbours(4) == (0, 3)
    assert g.leaders == (1, 4)


def test_complete() -> None:
    g = Graph.complete(4)
    np.testing.assert_array_equal(g.degree, [3] * 4)
    assert g.neighbours(2) == (0, 1, 3)


def test_star() -> None:
    g = Graph.star(5, center=2, leaders=(2,))
    np.testing.assert_array_equal(g.degree, [1, 1, 4, 1, 1])
    assert g.neighbours(2) == (0, 1, 3, 4)
    assert g.neighbours(0) == (2,)


def test_from_edges() -> None:
    g = Graph.from_edges(4, [(0, 1), (3, 1, 0.25)], leaders=(0, 2))
    assert g.adjacency[1, 3] == g.adjacency[3, 1] == 0.25
    assert g.neighbours(1) == (0, 3)
    np.testing.assert_array_equal(g.degree, [1, 2, 0, 1])
    np.testing.assert_array_equal(g.leader_links, [1, 0, 1, 0])
    assert g.degree.dtype == np.int64


def test_near_symmetric_is_symmetrised() -> None:
    a = np.array([[0.0, 1.0], [1.0 + 5e-13, 0.0]])
    g = Graph(a, np.array([1.0, 0.0]))
    np.testing.assert_array_equal(g.adjacency, g.adjacency.T)


# ------------------------------------------------------------------- invalid inputs
@pytest.mark.parametrize(
    ("adjacency", "leader_links", "match"),
    [
        ([[0, 1], [2, 0]], [1, 0], r"not symmetric \(a\[0,1\]=1 vs a\[1,0\]=2\)"),
        ([[0, 1], [1 + 1e-9, 0]], [1, 0], "not symmetric"),
        ([[0, -1], [-1, 0]], [1, 0], r"negative weights at \[\[0, 1\], \[1, 0\]\].*a_ij >= 0"),
        ([[0, 1, 0], [1, 0, 1]], [1, 0], r"square \(n, n\) matrix, got \(2, 3\)"),
        ([1.0, 2.0], [1, 0], "square"),
        (np.zeros((0, 0)), [], "non-empty"),
        ([[1, 1], [1, 0]], [1, 0], r"self-loops at rows \[0\].*a_ii = 0"),
        ([[0, np.nan], [np.nan, 0]], [1, 0], "NaN or inf"),
        ([[0, np.inf], [np.inf, 0]], [1, 0], "NaN or inf"),
        ([[0, 1], [1, 0]], [1, 0, 0], r"leader_links must have shape \(2,\).*got \(3,\)"),
        ([[0, 1], [1, 0]], [[1, 0]], "leader_links must have shape"),
        ([[0, 1], [1, 0]], [0.5, 0], "only 0 or 1"),
        ([[0, 1], [1, 0]], [np.nan, 1], "only 0 or 1"),
    ],
)
def test_graph_rejects(adjacency: object, leader_links: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Graph(np.asarray(adjacency, dtype=float), np.asarray(leader_links, dtype=float))


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: Graph.path(0), "n >= 1"),
        (lambda: Graph.path(3, leaders=(3,)), r"Leader index 3 is out of range.*0\.\.2"),
        (lambda: Graph.ring(2), "ring needs n >= 3.*Graph.path"),
        (lambda: Graph.star(4, center=4), "center 4 is out of range"),
        (lambda: Graph.path(3, weight=0.0), "weights must be finite and > 0"),
        (lambda: Graph.path(3, weight=-1.0), "weights must be finite and > 0"),
        (lambda: Graph.from_edges(3, [(0, 3)]), r"index outside 0\.\.2"),
        (lambda: Graph.from_edges(3, [(1, 1)]), "self-loop"),
        (lambda: Graph.from_edges(3, [(0, 1), (1, 0)]), "listed twice"),
        (lambda: Graph.from_edges(3, [(0,)]), r"\(i, j\) or \(i, j, weight\)"),  # type: ignore[list-item]
    ],
)
def test_constructors_reject(build: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        build()  # type: ignore[operator]


def test_neighbours_rejects_bad_index() -> None:
    with pytest.raises(ValueError, match=r"out of range; use 0\.\.2"):
        Graph.path(3).neighbours(3)


def test_validate_for_consensus_disconnected_names_components() -> None:
    with pytest.raises(
        ValueError, match=r"disconnected.*\[\(0, 1\), \(2,\), \(3, 4\)\].*add links"
    ):
        DISCONNECTED[0].validate_for_consensus()


def test_validate_for_consensus_no_leader() -> None:
    g = Graph(Graph.path(3).adjacency, np.zeros(3))
    with pytest.raises(ValueError, match=r"No vessel hears the virtual leader.*leader_links"):
        g.validate_for_consensus()


# ------------------------------------------------------------- immutability, eq, hash
def test_arrays_read_only_and_copied() -> None:
    a = np.array([[0.0, 1.0], [1.0, 0.0]])
    b = np.array([1.0, 0.0])
    g = Graph(a, b)
    assert a.flags.writeable and b.flags.writeable  # caller's arrays untouched
    a[0, 1] = 5.0
    assert g.adjacency[0, 1] == 1.0
    with pytest.raises(ValueError, match="read-only"):
        g.adjacency[0, 1] = 2.0
    with pytest.raises(ValueError, match="read-only"):
        g.leader_links[1] = 1.0
    with pytest.raises(AttributeError):
        g.adjacency = a  # type: ignore[misc]


def test_equality_and_hash() -> None:
    g1 = Graph.path(5, leaders=(0, 3))
    g2 = Graph.from_edges(5, [(3, 4), (2, 3), (1, 2), (0, 1)], leaders=(3, 0))
    assert g1 == g2
    assert hash(g1) == hash(g2)
    assert len({g1, g2}) == 1
    assert g1 != Graph.path(5, leaders=(0,))
    assert g1 != Graph.path(5, leaders=(0, 3), weight=2.0)
    assert g1 != Graph.path(4)
    assert g1 != "not a graph"
    zero = Graph(np.zeros((2, 2)), np.array([1.0, 0.0]))
    neg_zero = Graph(-np.zeros((2, 2)), np.array([1.0, -0.0]))
    assert zero == neg_zero
    assert hash(zero) == hash(neg_zero)


# --------------------------------------------------------------------- switching
def _schedule(period: int | None = 30) -> SwitchingTopology:
    return SwitchingTopology(
        (Graph.path(5), Graph.ring(5), Graph.star(5, leaders=(2,))), (0, 10, 20), period
    )


def test_index_at_periodic() -> None:
    topo = _schedule(period=30)
    expected = {0: 0, 9: 0, 10: 1, 19: 1, 20: 2, 29: 2, 30: 0, 45: 1, 59: 2, 60: 0, 95: 0}
    for step, idx in expected.items():
        assert topo.index_at(step) == idx
        assert topo.graph_at(step) == topo.graphs[idx]
    steps, period = switch_table(topo)
    assert steps.dtype == np.int64
    assert period == 30
    for step in range(200):  # the documented kernel rule agrees with index_at
        local = step % period if period else step
        assert topo.index_at(step) == int(np.flatnonzero(steps <= local)[-1])


def test_index_at_one_shot() -> None:
    topo = _schedule(period=None)
    assert [topo.index_at(s) for s in (0, 9, 10, 20, 1000)] == [0, 0, 1, 2, 2]
    np.testing.assert_array_equal(switch_table(topo)[0], [0, 10, 20])
    assert switch_table(topo)[1] == 0
    with pytest.raises(ValueError, match=">= 0"):
        topo.index_at(-1)


def test_union() -> None:
    a = Graph.from_edges(4, [(0, 1, 2.0), (2, 3)], leaders=(0,))
    b = Graph.from_edges(4, [(0, 1), (1, 2)], leaders=(3,))
    topo = SwitchingTopology((a, b), (0, 5), period=8)
    assert topo.n == 4
    expected = Graph.from_edges(4, [(0, 1, 2.0), (2, 3), (1, 2)], leaders=(0, 3))
    assert topo.union == expected


def test_switching_members_may_be_disconnected() -> None:
    a = Graph.from_edges(3, [(0, 1)])
    b = Graph.from_edges(3, [(1, 2)], leaders=())
    topo = SwitchingTopology([a, b], [0, 3])  # type: ignore[arg-type]
    assert isinstance(topo.graphs, tuple)
    assert topo.switch_steps == (0, 3)
    assert topo.union.is_connected()
    assert hash(topo) == hash(SwitchingTopology((a, b), (0, 3)))


@pytest.mark.parametrize(
    ("graphs", "steps", "period", "match"),
    [
        ((Graph.path(3),), (1,), None, "must start at 0, got 1"),
        ((Graph.path(3), Graph.ring(3)), (0, 0), None, "strictly increasing"),
        ((Graph.path(3), Graph.ring(3), Graph.path(3)), (0, 5, 3), None, "strictly increasing"),
        ((Graph.path(3), Graph.path(4)), (0, 5), None, r"same number of vessels, got n=\[3, 4\]"),
        ((Graph.path(3), Graph.ring(3)), (0,), None, "one switch step per graph"),
        ((), (), None, "at least one"),
        ((Graph.path(3), Graph.ring(3)), (0, 5), 5, "period=5 must exceed the last switch step 5"),
        ((Graph.path(3), Graph.ring(3)), (0, 5), 0, "period=0 must exceed"),
        (
            (Graph.from_edges(4, [(0, 1)]), Graph.from_edges(4, [(1, 0)])),
            (0, 5),
            None,
            r"union of the switching graphs must be jointly connected.*\(2,\), \(3,\)\]",
        ),
        (
            (Graph.path(3, leaders=()), Graph.ring(3, leaders=())),
            (0, 5),
            None,
            "union of the switching graphs .* No vessel hears the virtual leader",
        ),
    ],
)
def test_switching_rejects(
    graphs: tuple[Graph, ...], steps: tuple[int, ...], period: int | None, match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        SwitchingTopology(graphs, steps, period)


def test_as_switching() -> None:
    g = Graph.path(5, leaders=(0, 3))
    topo = as_switching(g)
    assert topo.graphs == (g,)
    assert topo.switch_steps == (0,)
    assert topo.period is None
    assert all(topo.index_at(s) == 0 for s in (0, 1, 10_000))
    assert as_switching(topo) is topo
    with pytest.raises(ValueError, match="disconnected"):
        as_switching(DISCONNECTED[0])
    with pytest.raises(ValueError, match="No vessel hears"):
        as_switching(Graph.path(3, leaders=()))


# ------------------------------------------------------------------------- slots
def test_slots_and_weights_three_member_schedule() -> None:
    path = Graph.path(5, weight=2.0)  # 0-1-2-3-4
    ring = Graph.ring(5)  # adds 4-0
    star = Graph.star(5, center=0, leaders=(2,), weight=0.5)  # 0 linked to all
    topo = SwitchingTopology((path, ring, star), (0, 10, 20), period=30)
    union = topo.union
    slots = neighbour_slots(topo)
    k = int(union.degree.max())
    assert k == 4
    assert slots.shape == (5, k)
    assert slots.dtype == np.int64
    expected_slots = [
        [1, 2, 3, 4],
        [0, 2, -1, -1],
        [0, 1, 3, -1],
        [0, 2, 4, -1],
        [0, 3, -1, -1],
    ]
    np.testing.assert_array_equal(slots, expected_slots)

    w = slot_weights(topo, slots)
    assert w.shape == (3, 5, k)
    assert w.dtype == np.float64
    for t, g in enumerate(topo.graphs):
        for i in range(5):
            for s in range(k):
                j = slots[i, s]
                assert w[t, i, s] == (g.adjacency[i, j] if j >= 0 else 0.0)
    np.testing.assert_array_equal(w[0, 0], [2.0, 0.0, 0.0, 0.0])  # path lacks 0-2, 0-3, 0-4
    np.testing.assert_array_equal(w[1, 0], [1.0, 0.0, 0.0, 1.0])  # ring lacks 0-2, 0-3
    np.testing.assert_array_equal(w[2, 0], [0.5, 0.5, 0.5, 0.5])
    np.testing.assert_array_equal(w[2, 1], [0.5, 0.0, 0.0, 0.0])  # star lacks 1-2; unused
    assert np.all(w[:, slots < 0] == 0.0)

    np.testing.assert_array_equal(
        leader_schedule(topo), [[1, 0, 0, 0, 0], [1, 0, 0, 0, 0], [0, 0, 1, 0, 0]]
    )


def test_slots_single_vessel_and_complete() -> None:
    assert neighbour_slots(as_switching(Graph.path(1))).shape == (1, 0)
    slots = neighbour_slots(as_switching(Graph.complete(4)))
    np.testing.assert_array_equal(slots, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


def test_slot_weights_rejects_bad_slots() -> None:
    topo = as_switching(Graph.path(3))
    with pytest.raises(ValueError, match="neighbour_slots"):
        slot_weights(topo, np.zeros((4, 2), dtype=np.int64))
    with pytest.raises(ValueError, match=r"-1\.\.2"):
        slot_weights(topo, np.full((3, 2), 3, dtype=np.int64))


# -------------------------------------------------------------------- impairments
def test_link_impairments() -> None:
    assert LinkImpairments().perfect
    assert not LinkImpairments(loss_probability=0.1).perfect
    assert not LinkImpairments(delay_steps=2).perfect
    imp = LinkImpairments(loss_probability=np.float64(0.25), delay_steps=np.int64(3))  # type: ignore[arg-type]
    assert type(imp.loss_probability) is float
    assert type(imp.delay_steps) is int
    assert imp == LinkImpairments(0.25, 3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"loss_probability": 1.0}, r"loss_probability must be in \[0, 1\), got 1.0"),
        ({"loss_probability": -0.1}, r"in \[0, 1\)"),
        ({"loss_probability": float("nan")}, r"in \[0, 1\)"),
        ({"delay_steps": -1}, "delay_steps must be a whole number of control steps >= 0"),
        ({"delay_steps": 1.5}, "whole number"),
    ],
)
def test_link_impairments_reject(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        LinkImpairments(**kwargs)  # type: ignore[arg-type]
