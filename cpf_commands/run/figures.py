"""Figures equivalent to Figs. 3-7 of Wang, Wang & Peng (2014), from a ``Trajectory``.

Each function draws one figure on a fresh matplotlib ``Figure`` (Agg, no
window) and returns it; ``write_figures`` saves all five as PNG. Vessels are
numbered 0..n-1, as the environments' agents (``vessel_0`` ...) and the videos
are; the paper's vessel k is vessel k - 1 here (figures of one vessel say so).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from cpf_env.evaluation.metrics import Trajectory, final_window

__all__ = [
    "coordination_figure",
    "forces_figure",
    "nn_figure",
    "paths_figure",
    "speed_figure",
    "write_figures",
]

_AXES = ("surge (N)", "sway (N)", "yaw (N m)")


def paths_figure(trajectory: Trajectory) -> Figure:
    """Fig. 3: the vessels' trajectories (coloured) and desired paths (black dashes on top)."""
    fig = Figure(figsize=(8, 6), layout="constrained")
    ax = fig.add_subplot()
    for i in range(trajectory.eta.shape[1]):
        (line,) = ax.plot(
            trajectory.eta[:, i, 0], trajectory.eta[:, i, 1], lw=2.2, label=f"vessel {i}"
        )
        ax.plot(*trajectory.eta[0, i, :2], "o", color=line.get_color(), ms=5)
        ax.plot(trajectory.eta_desired[:, i, 0], trajectory.eta_desired[:, i, 1], "k--", lw=0.8)
    ax.plot([], [], "k--", lw=0.8, label="desired path")
    ax.plot([], [], "o", color="0.4", ms=5, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", title="Paths and trajectories")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    return fig


def _paper(vessel: int) -> str:
    """The paper's number of a vessel (it counts from 1)."""
    return f"the paper's vessel {vessel + 1}"


def _fit(nn: NDArray[np.float64], true: NDArray[np.float64]) -> tuple[float, float]:
    """Relative RMS error RMS(nn - f) / RMS(f) and least-squares gain k of nn = k f, one axis."""
    energy = max(float(true @ true), 1e-300)
    error = float(np.sqrt(((nn - true) ** 2).sum() / energy))
    return error, float(nn @ true) / energy


def nn_figure(trajectory: Trajectory, vessel: int = 1, zoom_from: float = 0.1) -> Figure:
    """Fig. 4: NN output What^T sigma(xi) vs the true lumped uncertainty f_i of one vessel.

    Left column: the whole run. Right column: from ``zoom_from`` of the run on,
    with its own scale, where the transient no longer hides what the NN does;
    the shaded last quarter is where each axis's relative RMS error and the
    least-squares gain k of NN = k f (k = 1 is perfect tracking) are measured.
    """
    fig = Figure(figsize=(11, 7), layout="constrained")
    axes = fig.subplots(3, 2, sharex="col")
    nn = trajectory.extras.get("nn_output")
    true = trajectory.extras.get("lumped_true")
    start = int(zoom_from * len(trajectory.time))
    last = final_window(trajectory)
    for column, window in enumerate((slice(None), slice(start, None))):
        time = trajectory.time[window]
        for k, ax in enumerate(axes[:, column]):
            if true is not None:
                ax.plot(time, true[window, vessel, k], lw=1.4, label=f"true $f_{vessel}$")
            if nn is not None:
                ax.plot(
                    time,
                    nn[window, vessel, k],
                    "--",
                    lw=1.2,
                    label=r"NN output $\hat W^T \sigma(\xi)$",
                )
            ax.grid(alpha=0.3)
        axes[-1, column].set_xlabel("time (s)")
    for k in range(3):
        axes[k, 0].set_ylabel(_AXES[k])
        if nn is None or true is None:
            continue
        error, gain = _fit(nn[last, vessel, k], true[last, vessel, k])
        axes[k, 1].axvspan(trajectory.time[last][0], trajectory.time[-1], color="0.9", zorder=0)
        axes[k, 1].set_title(
            f"shaded last quarter: relative RMS error {error:.3f}, fitted NN = {gain:.3f} f",
            fontsize=8,
            loc="left",
        )
    axes[0, 0].legend(fontsize=8)
    axes[0, 0].set_title("whole run")
    fig.suptitle(
        f"Lumped uncertainty of vessel {vessel} ({_paper(vessel)}) and its NN approximation: "
        "whole run (left), "
        f"from t = {trajectory.time[start]:.0f} s on its own scale (right)"
    )
    return fig


def _float32_floor(ax: Axes, v0: NDArray[np.float64], what: str) -> None:
    """Mark one float32 ulp of v0 (the resolution of observations and messages)."""
    floor = float(np.spacing(np.float32(np.abs(v0).max())))
    ax.axhline(
        floor, color="k", ls=":", lw=1.0, label=f"float32 floor: 1 ulp of $v_0$ = {floor:.2g}"
    )
    ax.legend(fontsize=8, loc="upper right", title=what, title_fontsize=8)


def coordination_figure(trajectory: Trajectory) -> Figure:
    """Fig. 5: path-variable coordination errors theta_0 - theta_j, linear and log scale."""
    fig = Figure(figsize=(8, 6), layout="constrained")
    linear, log = fig.subplots(2, 1, sharex=True)
    theta = trajectory.theta
    for j in range(1, theta.shape[1]):
        difference = theta[:, 0] - theta[:, j]
        (line,) = linear.plot(
            trajectory.time, difference, lw=1.2, label=rf"$\theta_0 - \theta_{{{j}}}$"
        )
        log.semilogy(trajectory.time, np.abs(difference) + 1e-16, lw=1.0, color=line.get_color())
    linear.set(ylabel="coordination error", title="Path-variable coordination errors")
    log.set(xlabel="time (s)", ylabel="|coordination error|", ylim=(1e-12, None))
    _float32_floor(log, trajectory.v0, "messages are float32")
    for ax in (linear, log):
        ax.grid(alpha=0.3)
    linear.legend(fontsize=8, ncol=2)
    return fig


def _zoom_end(trajectory: Trajectory, vessel: int) -> float:
    """End (s) of Fig. 6's zoom: 1.5 x the last saturated time + 1 s, within [2 s, the run]."""
    saturated = np.any(trajectory.tau_command[:, vessel] != trajectory.tau_applied[:, vessel], -1)
    time = trajectory.time
    last = float(time[np.flatnonzero(saturated)[-1]]) if saturated.any() else 0.0
    return float(np.clip(1.5 * last + 1.0, min(2.0, time[-1]), time[-1]))


def forces_figure(trajectory: Trajectory, vessel: int = 2) -> Figure:
    """Fig. 6: applied (saturated) forces of one vessel, its commands, and the limits.

    Left column: the whole run. Right column: a zoom of the first seconds,
    where the saturation happens (``_zoom_end``).
    """
    fig = Figure(figsize=(11, 7), layout="constrained")
    axes = fig.subplots(3, 2, sharex="col", gridspec_kw={"width_ratios": (3, 2)})
    end = _zoom_end(trajectory, vessel)
    zoom = slice(0, int(np.searchsorted(trajectory.time, end, side="right")))
    for column, window in enumerate((slice(None), zoom)):
        time = trajectory.time[window]
        for k, ax in enumerate(axes[:, column]):
            ax.plot(
                time,
                trajectory.tau_command[window, vessel, k],
                color="0.6",
                lw=0.8,
                label="command $\\tau_0$",
            )
            ax.plot(
                time, trajectory.tau_applied[window, vessel, k], lw=1.4, label="applied $\\tau$"
            )
            low, high = trajectory.tau_min[vessel, k], trajectory.tau_max[vessel, k]
            for limit in (low, high):
                ax.axhline(limit, color="r", ls="--", lw=1.0)
            ax.set_ylim(1.3 * low, 1.3 * high)
            ax.grid(alpha=0.3)
        axes[-1, column].set_xlabel("time (s)")
    for k in range(3):
        axes[k, 0].set_ylabel(_AXES[k])
    axes[0, 0].plot([], [], "r--", lw=1.0, label="limits")
    axes[0, 0].legend(fontsize=8, ncol=3)
    axes[0, 0].set_title("whole run (commands clipped to view)")
    axes[0, 1].set_title(f"first {end:.1f} s: where the saturation happens")
    fig.suptitle(f"Control forces of vessel {vessel} ({_paper(vessel)})")
    return fig


def speed_figure(trajectory: Trajectory) -> Figure:
    """Fig. 7: distributed speed estimates vhat_i vs v0, and their errors on a log scale."""
    fig = Figure(figsize=(8, 6), layout="constrained")
    value, error = fig.subplots(2, 1, sharex=True)
    estimate = trajectory.extras.get("speed_estimate")
    if estimate is not None:
        for i in range(estimate.shape[1]):
            (line,) = value.plot(
                trajectory.time, estimate[:, i], lw=1.2, label=rf"$\hat v_{{{i}}}$"
            )
            error.semilogy(
                trajectory.time,
                np.abs(estimate[:, i] - trajectory.v0) + 1e-18,
                lw=1.0,
                color=line.get_color(),
            )
    value.plot(trajectory.time, trajectory.v0, "k--", lw=1.0, label="$v_0$")
    value.set(ylabel="speed (m/s)", title="Distributed estimates of the leader speed")
    error.set(xlabel="time (s)", ylabel=r"$|\hat v_i - v_0|$ (m/s)", ylim=(1e-12, None))
    _float32_floor(error, trajectory.v0, "observations are float32")
    for ax in (value, error):
        ax.grid(alpha=0.3)
    value.legend(fontsize=8, ncol=3)
    return fig


def write_figures(trajectory: Trajectory, directory: str | Path) -> list[Path]:
    """Save Figs. 3-7 as PNG files in ``directory`` and return their paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    n = trajectory.eta.shape[1]
    figures = {
        "fig3_paths.png": paths_figure(trajectory),
        "fig4_nn_vs_f.png": nn_figure(trajectory, vessel=min(1, n - 1)),
        "fig5_coordination.png": coordination_figure(trajectory),
        "fig6_forces.png": forces_figure(trajectory, vessel=min(2, n - 1)),
        "fig7_speed_estimates.png": speed_figure(trajectory),
    }
    written = []
    for name, figure in figures.items():
        path = directory / name
        figure.savefig(path, dpi=120)
        written.append(path)
    return written
