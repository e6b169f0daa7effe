"""Top-down matplotlib view of one fleet: paths, hulls, trails, virtual targets, links.

Convention: x (m) to the right, y (m) up, heading psi counter-clockwise from
the x axis, as the path module defines psi_d = atan2(y_d', x_d') and as the
paper's figures are drawn. Each frame shows, per vessel (one colour each):

* its desired path eta_d(theta) (thin line), precomputed over the theta range
  the episode covers at the leader's speed and widened when the view reaches past it;
* its hull, a Cybership II outline (1.255 m x 0.29 m) drawn at ``hull_scale``
  times true size (by default enlarged so a hull spans >= 4 % of the initial
  view; the legend then says by how much), with its index beside it; vessels
  that hear the leader (b_i = 1) at this step are ringed in gold;
* a trail of its positions at the last ``trail_length`` rendered frames;
* its virtual target eta_d(theta_i) (an ``x``);
* grey lines between neighbours in the topology active at this step.

The view follows the fleet (all vessels and targets, with a margin). Artists
are created once and only their data change per frame. This module imports
matplotlib; the envs import it only when they render.
"""

from __future__ import annotations

from collections import deque

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon
from numpy.typing import NDArray

from cpf_env.model.paths import encode_paths, evaluate_paths
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

__all__ = ["HULL_BEAM", "HULL_LENGTH", "FleetRenderer"]

HULL_LENGTH = 1.255  # Cybership II length overall (m)
HULL_BEAM = 0.29  # Cybership II beam (m)
RENDER_MODES = ("human", "rgb_array")
# Built-in matplotlib backends that cannot open a window: human mode draws but shows nothing.
_NON_INTERACTIVE = frozenset({"agg", "cairo", "pdf", "pgf", "ps", "svg", "template"})
_MARGIN = 3.0  # view margin around vessels and targets (m)
_MIN_SPAN = 8.0  # smallest view extent (m)
_PATH_MARGIN = 10.0  # theta beyond the covered range for which paths are drawn
_PATH_STEP = 0.1  # theta spacing of the drawn path points (about m)
_LEADER_EDGE = "#e0a000"


def _hull_outline(scale: float) -> NDArray[np.float64]:
    """Body-frame hull polygon (5, 2), bow along +x, centred on the origin (m)."""
    half_length, half_beam = 0.5 * HULL_LENGTH, 0.5 * HULL_BEAM
    return scale * np.array(
        [
            [-half_length, -half_beam],
            [0.45 * half_length, -half_beam],
            [half_length, 0.0],
            [0.45 * half_length, half_beam],
            [-half_length, half_beam],
        ]
    )


class FleetRenderer:
    """Renders one fleet of a ``FleetSim`` as a top-down image or window.

    Args:
        scenario: The scenario of the simulator that will be drawn.
        mode: ``"rgb_array"`` (``draw`` returns an image) or ``"human"`` (a pyplot
            window, updated in real time; draws nothing visible on a
            non-interactive backend such as Agg).
        size: Image width and height (pixels).
        trail_length: Number of rendered frames kept in each trail.
        hull_scale: Hull drawing scale (1 = true size); None picks one (see module).

    Example:
        >>> from cpf_env import scenarios
        >>> sim = FleetSim(scenarios.get("wang2014"))
        >>> _ = sim.reset(seeds=[0])
        >>> renderer = FleetRenderer(sim.scenario, "rgb_array")
        >>> renderer.draw(sim, fleet=0).shape
        (480, 640, 3)
        >>> renderer.close()
    """

    def __init__(
        self,
        scenario: Scenario,
        mode: str = "rgb_array",
        size: tuple[int, int] = (640, 480),
        trail_length: int = 400,
        hull_scale: float | None = None,
    ) -> None:
        if mode not in RENDER_MODES:
            raise ValueError(f"mode must be one of {RENDER_MODES}, got {mode!r}.")
        self.scenario = scenario
        self.mode = mode
        n = scenario.n
        self._kinds, self._params = encode_paths(scenario.paths)
        self._trails: deque[NDArray[np.float64]] = deque(maxlen=int(trail_length))
        self._episode: tuple[int, int] = (-1, -1)  # (RNG key, step) of the last frame
        self._edges = [np.argwhere(np.triu(g.adjacency) > 0) for g in scenario.switching.graphs]
        v0_max = max(abs(v) for v in scenario.v0_schedule.values)
        theta0 = np.array(scenario.initial.theta)
        self._theta_range = (
            float(theta0.min()) - _PATH_MARGIN,
            float(theta0.max()) + v0_max * scenario.max_steps * scenario.dt + _PATH_MARGIN,
        )
        start = self._targets(theta0[None, :])[0]
        positions = np.vstack([np.array(scenario.initial.eta)[:, :2], start[:, :2]])
        extent = float(np.ptp(positions, axis=0).max()) + 2.0 * _MARGIN
        self.hull_scale = (
            max(1.0, 0.04 * extent / HULL_LENGTH) if hull_scale is None else float(hull_scale)
        )
        self._outline = _hull_outline(self.hull_scale)

        dpi = 100
        figsize = (size[0] / dpi, size[1] / dpi)
        fig: Figure
        if mode == "human":
            from matplotlib import pyplot as plt

            fig = plt.figure(figsize=figsize, dpi=dpi)
        else:
            fig = Figure(figsize=figsize, dpi=dpi)
            FigureCanvasAgg(fig)
        self._fig: Figure | None = fig
        fig.subplots_adjust(left=0.12, right=0.97, top=0.88, bottom=0.17)
        self._ax: Axes = fig.add_subplot()
        self._ax.set_xlabel("x (m)")
        self._ax.set_ylabel("y (m)")
        box = self._ax.get_position()
        self._aspect = (box.height * size[1]) / (box.width * size[0])  # axes height / width
        self._ax.grid(True, linewidth=0.4, alpha=0.4)
        self._create_artists(fig, n)
        self._draw_paths()

    def _create_artists(self, fig: Figure, n: int) -> None:
        """Create every artist once; frames only update their data."""
        ax = self._ax
        cmap = matplotlib.colormaps["tab10" if n <= 10 else "viridis"]
        self._colors = [cmap(i if n <= 10 else i / (n - 1)) for i in range(n)]
        self._links = LineCollection([], colors="0.45", linewidths=0.8, zorder=1)
        ax.add_collection(self._links)
        self._paths = [
            ax.plot([], [], color=c, lw=0.9, alpha=0.45, zorder=0)[0] for c in self._colors
        ]
        self._trail_lines = [ax.plot([], [], color=c, lw=1.6, zorder=2)[0] for c in self._colors]
        self._target_marks = [
            ax.plot([], [], "x", color=c, ms=7, mew=2, zorder=4)[0] for c in self._colors
        ]
        self._hulls = [
            Polygon(self._outline, closed=True, fc=c, ec="k", lw=0.8, zorder=3)
            for c in self._colors
        ]
        for hull in self._hulls:
            ax.add_patch(hull)
        self._leader_rings = [
            ax.plot([], [], "o", ms=18, mfc="none", mec=_LEADER_EDGE, mew=1.8, zorder=2)[0]
            for _ in range(n)
        ]
        self._labels = [
            ax.text(0.0, 0.0, str(i), fontsize=7, ha="center", va="center", zorder=5)
            for i in range(n)
        ]
        hull_label = "hull" if self.hull_scale == 1.0 else f"hull (x{self.hull_scale:.1f} size)"
        handles = [
            Line2D([], [], color="0.3", lw=0.9, alpha=0.6, label="path"),
            Line2D([], [], color="0.3", lw=1.6, label="trail"),
            Line2D([], [], color="0.3", ls="", marker="x", mew=2, label="target"),
            Line2D([], [], color="0.45", lw=0.8, label="link"),
            Polygon(self._outline, fc="0.8", ec="k", lw=0.8, label=hull_label),
            Line2D(
                [], [], ls="", marker="o", mfc="none", mec=_LEADER_EDGE, mew=1.8, label="hears v0"
            ),
        ]
        fig.legend(
            handles=handles,
            loc="lower center",
            ncol=6,
            fontsize=8,
            frameon=False,
            bbox_to_anchor=(0.5, 0.0),
        )
        self._title = ax.set_title("", fontsize=9)

    def _targets(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """eta_d(theta) of every vessel, theta shape (T, n) -> (T, n, 3)."""
        count, n = theta.shape
        flat = evaluate_paths(
            np.tile(self._kinds, count),
            np.tile(self._params, (count, 1)),
            np.ascontiguousarray(theta, dtype=np.float64).ravel(),
        )
        return flat[:, 0, :].reshape(count, n, 3)

    def _draw_paths(self) -> None:
        """(Re)compute every path polyline over ``self._theta_range``."""
        lo, hi = self._theta_range
        count = int(np.clip((hi - lo) / _PATH_STEP, 200, 20000))
        grid = np.linspace(lo, hi, count)
        points = self._targets(np.repeat(grid[:, None], self.scenario.n, axis=1))
        for i, line in enumerate(self._paths):
            line.set_data(points[:, i, 0], points[:, i, 1])

    def draw(self, sim: FleetSim, fleet: int = 0) -> NDArray[np.uint8] | None:
        """Draw fleet ``fleet`` of ``sim`` at its current step.

        Returns:
            In ``"rgb_array"`` mode the frame, shape (H, W, 3), uint8; in ``"human"``
            mode None (the window is updated and the call pauses for ``dt``).

        Raises:
            RuntimeError: The renderer was closed.
        """
        fig = self._fig
        if fig is None:
            raise RuntimeError("this FleetRenderer is closed; create a new one.")
        a = sim.arrays
        eta, theta, step = a.eta[fleet], a.theta[fleet], int(a.step[fleet])
        key = int(a.key[fleet])
        if key != self._episode[0] or step < self._episode[1]:
            self._trails.clear()
        if (key, step) != self._episode or not self._trails:
            self._trails.append(eta[:, :2].copy())
        self._episode = (key, step)
        targets = self._targets(theta[None, :])[0]
        self._update_vessels(eta, targets, step)
        reach = self._frame_view(np.vstack([eta[:, :2], targets[:, :2]]))
        lo, hi = self._theta_range
        if theta.min() - reach < lo or theta.max() + reach > hi:  # theta is about arc length
            self._theta_range = (
                min(lo, float(theta.min()) - 2.0 * reach),
                max(hi, float(theta.max()) + 2.0 * reach),
            )
            self._draw_paths()
        time = step * self.scenario.dt
        self._title.set_text(
            f"{self.scenario.name}   t = {time:.1f} s   v0 = {sim.v0_at(time):.2f} m/s\n"
            f"max path error {a.errors[fleet, :, 0].max():.2f} m   "
            f"max |sync error| {np.abs(a.errors[fleet, :, 2]).max():.2f}"
        )
        return self._show(fig)

    def _update_vessels(
        self, eta: NDArray[np.float64], targets: NDArray[np.float64], step: int
    ) -> None:
        trail = np.asarray(self._trails)  # (T, n, 2)
        switching = self.scenario.switching
        member = switching.index_at(step)
        hears = switching.graphs[member].leader_links
        cos, sin = np.cos(eta[:, 2]), np.sin(eta[:, 2])
        for i, hull in enumerate(self._hulls):
            rotation = np.array([[cos[i], -sin[i]], [sin[i], cos[i]]])
            hull.set_xy(self._outline @ rotation.T + eta[i, :2])
            ring = eta[i, :2] if hears[i] else np.empty(0)
            self._leader_rings[i].set_data(ring[:1], ring[1:])
            offset = 0.6 * self.hull_scale * HULL_LENGTH * np.array([-sin[i], cos[i]])
            self._labels[i].set_position((eta[i, 0] + offset[0], eta[i, 1] + offset[1]))
            self._trail_lines[i].set_data(trail[:, i, 0], trail[:, i, 1])
            self._target_marks[i].set_data(targets[i, :1], targets[i, 1:2])
        edges = self._edges[member]
        self._links.set_segments(list(eta[edges][:, :, :2]))

    def _frame_view(self, points: NDArray[np.float64]) -> float:
        """Fit the axes to ``points`` (k, 2) with a margin, widening one axis for equal scales.

        Returns:
            The diagonal of the view (m).
        """
        low, high = points.min(axis=0), points.max(axis=0)
        centre = 0.5 * (low + high)
        half = np.maximum(0.5 * (high - low) + _MARGIN, 0.5 * _MIN_SPAN)
        half = np.maximum(half, [half[1] / self._aspect, half[0] * self._aspect])
        self._ax.set_xlim(centre[0] - half[0], centre[0] + half[0])
        self._ax.set_ylim(centre[1] - half[1], centre[1] + half[1])
        return 2.0 * float(np.hypot(*half))

    def _show(self, fig: Figure) -> NDArray[np.uint8] | None:
        """Rasterize (rgb_array) or refresh the window (human)."""
        if self.mode == "rgb_array":
            canvas = fig.canvas
            assert isinstance(canvas, FigureCanvasAgg)
            canvas.draw()
            return np.asarray(canvas.buffer_rgba())[..., :3].copy()
        from matplotlib import pyplot as plt

        if plt.get_backend().lower() not in _NON_INTERACTIVE:
            plt.figure(fig)
            plt.pause(self.scenario.dt)
        return None

    def close(self) -> None:
        """Close the figure (and its window); safe to call more than once."""
        if self._fig is None:
            return
        if self.mode == "human":
            from matplotlib import pyplot as plt

            plt.close(self._fig)
        self._fig = None
