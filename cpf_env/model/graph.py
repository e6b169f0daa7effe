"""Communication graphs: fixed and switching topologies, neighbour slots.

Vessels are numbered ``0 .. n-1`` (the paper numbers them from 1). A :class:`Graph` is
undirected and weighted: ``adjacency[i, j] = a_ij >= 0`` is symmetric with a zero
diagonal, and ``leader_links[i] = b_i`` is 1 when vessel i hears the virtual leader's
speed v0. The consensus part of the controller uses the Laplacian ``L = D - A`` (D the
weighted degree matrix) and ``B = diag(b)``; ``L + B`` is positive definite exactly when
the graph is connected and some vessel hears the leader (:meth:`Graph.validate_for_consensus`).

The :class:`Graph` constructor checks structure only (shape, finiteness, signs,
symmetry, diagonal): a member of a :class:`SwitchingTopology` may be disconnected on its
own, as long as the union of all members is connected and has a leader (joint
connectivity). Graphs are immutable: arrays are copied and made read-only, and
``__eq__``/``__hash__`` compare values, so a Graph can sit inside a frozen, hashable
scenario dataclass.

The simulator kernel gives every vessel K fixed neighbour slots, K being the largest
degree of the union graph. :func:`neighbour_slots` assigns the union neighbours of each
vessel to slots (sorted by index, -1 for unused slots), :func:`slot_weights` and
:func:`leader_schedule` tabulate a_ij and b_i per member graph, and :func:`switch_table`
gives the schedule as plain arrays, so the compiled kernel never touches these classes.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Edge",
    "Graph",
    "SwitchingTopology",
    "as_switching",
    "leader_schedule",
    "neighbour_slots",
    "slot_weights",
    "switch_table",
]

_SYMMETRY_TOL = 1e-12
Edge = tuple[int, int] | tuple[int, int, float]  # (i, j) or (i, j, a_ij)


def _leader_vector(n: int, leaders: Iterable[int]) -> NDArray[np.float64]:
    """Return b (n,) with ones at ``leaders``, after checking n and the indices."""
    if n < 1:
        raise ValueError(f"A graph needs n >= 1 vessels, got n={n}; pass a positive n.")
    b = np.zeros(n)
    for i in leaders:
        if not 0 <= i < n:
            raise ValueError(f"Leader index {i} is out of range; use indices in 0..{n - 1}.")
        b[i] = 1.0
    return b


@dataclass(frozen=True, eq=False)
class Graph:
    """Undirected weighted communication graph with links to the virtual leader.

    Attributes:
        adjacency: (n, n) weights a_ij >= 0 (dimensionless), symmetric, zero diagonal;
            a_ij > 0 means vessels i and j exchange packets. Read-only copy.
        leader_links: (n,) b_i in {0, 1}; 1 if vessel i hears the leader. Read-only copy.

    Example:
        >>> g = Graph.path(5, leaders=(0, 3))  # the paper's chain 1-2-3-4-5
        >>> g.neighbours(1), g.leaders, g.is_connected()
        ((0, 2), (0, 3), True)
    """

    adjacency: NDArray[np.float64]
    leader_links: NDArray[np.float64]

    def __post_init__(self) -> None:
        a = np.array(self.adjacency, dtype=np.float64)
        if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] < 1:
            raise ValueError(f"adjacency must be a non-empty square (n, n) matrix, got {a.shape}.")
        if not np.all(np.isfinite(a)):
            raise ValueError("adjacency contains NaN or inf; all weights must be finite.")
        if np.any(a < 0):
            bad = np.argwhere(a < 0)[:5].tolist()
            raise ValueError(f"adjacency has negative weights at {bad}; use a_ij >= 0.")
        if np.any(np.diag(a) != 0):
            bad = np.flatnonzero(np.diag(a)).tolist()
            raise ValueError(f"adjacency has self-loops at rows {bad}; set a_ii = 0.")
        asym = np.argwhere(np.abs(a - a.T) > _SYMMETRY_TOL)
        if asym.size:
            pairs = ", ".join(
                f"a[{i},{j}]={a[i, j]:g} vs a[{j},{i}]={a[j, i]:g}"
                for i, j in asym[asym[:, 0] < asym[:, 1]][:5]
            )
            raise ValueError(f"adjacency is not symmetric ({pairs}); give a_ij = a_ji.")
        b = np.array(self.leader_links, dtype=np.float64)
        if b.shape != a.shape[:1]:
            raise ValueError(
                f"leader_links must have shape {a.shape[:1]} (one b_i per vessel), got {b.shape}."
            )
        if not np.all((b == 0) | (b == 1)):
            raise ValueError(f"leader_links must contain only 0 or 1, got {b.tolist()}.")
        # Exact symmetry; "+ 0.0" turns -0.0 into 0.0 so equal graphs hash equally.
        a = 0.5 * (a + a.T) + 0.0
        b = b + 0.0
        a.setflags(write=False)
        b.setflags(write=False)
        object.__setattr__(self, "adjacency", a)
        object.__setattr__(self, "leader_links", b)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Graph):
            return NotImplemented
        return np.array_equal(self.adjacency, other.adjacency) and np.array_equal(
            self.leader_links, other.leader_links
        )

    def __hash__(self) -> int:
        return hash((self.n, self.adjacency.tobytes(), self.leader_links.tobytes()))

    @classmethod
    def from_edges(cls, n: int, edges: Iterable[Edge], leaders: Iterable[int] = (0,)) -> Graph:
        """Build a graph from an undirected edge list.

        Args:
            n: Number of vessels (>= 1).
            edges: Pairs ``(i, j)`` (weight 1) or triples ``(i, j, a_ij)`` with a_ij > 0;
                each unordered pair at most once, i != j, indices in ``0..n-1``.
            leaders: Indices of the vessels that hear the virtual leader.

        Raises:
            ValueError: On a bad index, self-loop, repeated pair or non-positive weight.
        """
        b = _leader_vector(n, leaders)
        a = np.zeros((n, n))
        for edge in edges:
            if len(edge) not in (2, 3):
                raise ValueError(f"Edge {edge} must be (i, j) or (i, j, weight).")
            i, j = int(edge[0]), int(edge[1])
            w = float(edge[2]) if len(edge) == 3 else 1.0
            if not (0 <= i < n and 0 <= j < n):
                raise ValueError(f"Edge {edge} has an index outside 0..{n - 1}.")
            if i == j:
                raise ValueError(f"Edge {edge} is a self-loop; connect two distinct vessels.")
            if not (np.isfinite(w) and w > 0):
                raise ValueError(f"Edge {edge} has weight {w}; weights must be finite and > 0.")
            if a[i, j]:
                raise ValueError(f"Edge ({i}, {j}) is listed twice; give each pair once.")
            a[i, j] = a[j, i] = w
        return cls(a, b)

    @classmethod
    def path(cls, n: int, leaders: Iterable[int] = (0,), weight: float = 1.0) -> Graph:
        """Chain 0-1-...-(n-1) with equal weights ``weight``."""
        return cls.from_edges(n, [(i, i + 1, weight) for i in range(n - 1)], leaders)

    @classmethod
    def ring(cls, n: int, leaders: Iterable[int] = (0,), weight: float = 1.0) -> Graph:
        """Cycle 0-1-...-(n-1)-0 with equal weights; needs n >= 3."""
        if n < 3:
            raise ValueError(f"A ring needs n >= 3 vessels, got n={n}; use Graph.path instead.")
        return cls.from_edges(n, [(i, (i + 1) % n, weight) for i in range(n)], leaders)

    @classmethod
    def complete(cls, n: int, leaders: Iterable[int] = (0,), weight: float = 1.0) -> Graph:
        """All-to-all graph with equal weights."""
        edges = [(i, j, weight) for i in range(n) for j in range(i + 1, n)]
        return cls.from_edges(n, edges, leaders)

    @classmethod
    def star(
        cls, n: int, center: int = 0, leaders: Iterable[int] = (0,), weight: float = 1.0
    ) -> Graph:
        """Star: vessel ``center`` linked to every other vessel, equal weights."""
        if n >= 1 and not 0 <= center < n:
            raise ValueError(f"Star center {center} is out of range; use 0..{n - 1}.")
        return cls.from_edges(n, [(center, j, weight) for j in range(n) if j != center], leaders)

    @property
    def n(self) -> int:
        """Number of vessels."""
        return int(self.adjacency.shape[0])

    @property
    def laplacian(self) -> NDArray[np.float64]:
        """(n, n) weighted Laplacian ``L = D - A``, D = diag(row sums of A)."""
        return np.diag(self.adjacency.sum(axis=1)) - self.adjacency

    @property
    def degree(self) -> NDArray[np.int64]:
        """(n,) number of neighbours of each vessel (nonzero a_ij), int64."""
        return np.count_nonzero(self.adjacency, axis=1).astype(np.int64)

    @property
    def leaders(self) -> tuple[int, ...]:
        """Indices of the vessels with b_i = 1, ascending."""
        return tuple(int(i) for i in np.flatnonzero(self.leader_links))

    def neighbours(self, i: int) -> tuple[int, ...]:
        """Indices j with a_ij > 0, ascending."""
        if not 0 <= i < self.n:
            raise ValueError(f"Vessel index {i} is out of range; use 0..{self.n - 1}.")
        return tuple(int(j) for j in np.flatnonzero(self.adjacency[i]))

    def components(self) -> list[tuple[int, ...]]:
        """Connected components, each ascending, ordered by smallest member."""
        # Reachability by repeated squaring of (I + A > 0): after k squarings it covers
        # walks of length 2^k, and 2^k >= n - 1 suffices.
        reach = (self.adjacency > 0) | np.eye(self.n, dtype=bool)
        for _ in range(max(self.n - 1, 1).bit_length()):
            reach = (reach.astype(np.int64) @ reach.astype(np.int64)) > 0
        return sorted({tuple(int(j) for j in np.flatnonzero(row)) for row in reach})

    def is_connected(self) -> bool:
        """True if every vessel can reach every other over links with a_ij > 0."""
        return len(self.components()) == 1

    def validate_for_consensus(self) -> None:
        """Check that ``L + B`` is positive definite (connected, at least one leader link).

        Raises:
            ValueError: If the graph is disconnected (components are listed) or no
                vessel hears the virtual leader.
        """
        comps = self.components()
        if len(comps) > 1:
            raise ValueError(
                f"The communication graph is disconnected, components (vessel indices) "
                f"{comps}; add links between them so the path variables can reach consensus."
            )
        if not self.leaders:
            raise ValueError(
                "No vessel hears the virtual leader (all b_i = 0); set leader_links[i] = 1 "
                "for at least one vessel, e.g. leaders=(0,)."
            )


@dataclass(frozen=True)
class SwitchingTopology:
    """Piecewise-constant schedule of communication graphs.

    Graph ``graphs[t]`` is active from control step ``switch_steps[t]`` until the next
    switch step; with ``period`` set, the schedule repeats every ``period`` steps. The
    union graph (elementwise max of a_ij and b_i over members) must be connected and
    have a leader; members may be disconnected on their own.

    Attributes:
        graphs: The T member graphs, all with the same n.
        switch_steps: (T,) control steps at which each member becomes active; starts at 0,
            strictly increasing.
        period: Repeat length in control steps (> last switch step), or None for a
            one-shot schedule whose last member stays active forever.
    """

    graphs: tuple[Graph, ...]
    switch_steps: tuple[int, ...]
    period: int | None = None

    def __post_init__(self) -> None:
        graphs, steps = tuple(self.graphs), tuple(int(s) for s in self.switch_steps)
        object.__setattr__(self, "graphs", graphs)
        object.__setattr__(self, "switch_steps", steps)
        if not graphs or len(graphs) != len(steps):
            raise ValueError(
                f"Got {len(graphs)} graphs and {len(steps)} switch steps; give one switch "
                "step per graph (at least one)."
            )
        sizes = [g.n for g in graphs]
        if len(set(sizes)) != 1:
            raise ValueError(f"All graphs must have the same number of vessels, got n={sizes}.")
        if steps[0] != 0:
            raise ValueError(f"switch_steps must start at 0, got {steps[0]}; prepend step 0.")
        if np.any(np.diff(steps) <= 0):
            raise ValueError(f"switch_steps must be strictly increasing, got {list(steps)}.")
        if self.period is not None:
            object.__setattr__(self, "period", int(self.period))
        if self.period is not None and self.period <= steps[-1]:
            raise ValueError(
                f"period={self.period} must exceed the last switch step {steps[-1]} "
                "(otherwise the last graph is never active); increase it or pass None."
            )
        try:
            self.union.validate_for_consensus()
        except ValueError as err:
            raise ValueError(
                f"The union of the switching graphs must be jointly connected with a leader: {err}"
            ) from None

    @property
    def n(self) -> int:
        """Number of vessels."""
        return self.graphs[0].n

    @property
    def union(self) -> Graph:
        """Graph with a_ij and b_i the elementwise max over all members."""
        return Graph(
            np.max([g.adjacency for g in self.graphs], axis=0),
            np.max([g.leader_links for g in self.graphs], axis=0),
        )

    def index_at(self, step: int) -> int:
        """Index t of the member active at control step ``step`` >= 0 (see switch_table)."""
        if step < 0:
            raise ValueError(f"Control step must be >= 0, got {step}.")
        local = step % self.period if self.period else step
        return bisect.bisect_right(self.switch_steps, local) - 1

    def graph_at(self, step: int) -> Graph:
        """Graph active at control step ``step`` (>= 0)."""
        return self.graphs[self.index_at(step)]


def as_switching(topology: Graph | SwitchingTopology) -> SwitchingTopology:
    """Wrap a fixed graph as a one-member schedule; pass a schedule through unchanged.

    Raises:
        ValueError: If a fixed graph fails :meth:`Graph.validate_for_consensus`.
    """
    if isinstance(topology, SwitchingTopology):
        return topology
    topology.validate_for_consensus()
    return SwitchingTopology((topology,), (0,))


def neighbour_slots(topology: SwitchingTopology) -> NDArray[np.int64]:
    """Assign each vessel's union-graph neighbours to K fixed slots.

    Args:
        topology: The schedule; K is the largest degree of ``topology.union``.

    Returns:
        (n, K) int64: ``slots[i, k]`` is the k-th neighbour j of vessel i in ascending
        order, or -1 when vessel i has fewer than K neighbours.
    """
    union = topology.union
    k_max = int(union.degree.max())
    slots = np.full((union.n, k_max), -1, dtype=np.int64)
    for i in range(union.n):
        nbrs = union.neighbours(i)
        slots[i, : len(nbrs)] = nbrs
    return slots


def slot_weights(topology: SwitchingTopology, slots: NDArray[np.int64]) -> NDArray[np.float64]:
    """Tabulate the link weight of every slot in every member graph.

    Args:
        topology: The schedule with T members.
        slots: (n, K) slot table from :func:`neighbour_slots`.

    Returns:
        (T, n, K) float64: ``a_ij`` of member t for the neighbour j in slot k of vessel i;
        0 where member t lacks that link or the slot is unused.
    """
    slots = np.asarray(slots, dtype=np.int64)
    n = topology.n
    if slots.ndim != 2 or slots.shape[0] != n or np.any((slots < -1) | (slots >= n)):
        raise ValueError(
            f"slots must be an (n={n}, K) table of indices in -1..{n - 1}; build it with "
            "neighbour_slots(topology)."
        )
    adjacency = np.stack([g.adjacency for g in topology.graphs])  # (T, n, n)
    rows = np.arange(n)[:, None]
    weights = adjacency[:, rows, np.maximum(slots, 0)]
    weights[:, slots < 0] = 0.0
    return weights


def leader_schedule(topology: SwitchingTopology) -> NDArray[np.float64]:
    """(T, n) float64 leader links b_i of each member graph."""
    return np.stack([g.leader_links for g in topology.graphs])


def switch_table(topology: SwitchingTopology) -> tuple[NDArray[np.int64], int]:
    """Schedule as plain data for the compiled kernel.

    The active member at control step ``step`` is the last t with
    ``switch_steps[t] <= local``, where ``local = step % period`` if ``period > 0`` else
    ``step``; this is exactly :meth:`SwitchingTopology.index_at`.

    Returns:
        ``(switch_steps, period)``: (T,) int64 switch steps and the period in control
        steps, 0 for a non-repeating schedule.
    """
    return np.asarray(topology.switch_steps, dtype=np.int64), int(topology.period or 0)
