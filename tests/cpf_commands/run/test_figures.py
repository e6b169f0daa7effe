"""Figures 3-7 (cpf_commands.run.figures): what is drawn matches what the legends and notes say."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgba

from cpf_commands.run import figures
from cpf_commands.run.experiment import run_episode


@pytest.fixture(scope="module")
def run():
    return run_episode("wang2014", "nn_dsc", seed=0, max_steps=400)


def test_fig3_desired_paths_are_drawn_as_the_legend_shows(run):
    ax = figures.paths_figure(run).axes[0]
    handles, labels = ax.get_legend_handles_labels()
    legend = dict(zip(labels, handles, strict=True))
    key = legend["desired path"]
    desired = [
        line for line in ax.lines if line.get_label().startswith("_") and len(line.get_xdata()) > 1
    ]
    assert len(desired) == run.eta.shape[1]
    trajectories = [line for line in ax.lines if line.get_label().startswith("vessel")]
    for line, trajectory in zip(desired, trajectories, strict=True):
        assert line.get_linestyle() == key.get_linestyle() == "--"
        assert to_rgba(line.get_color()) == to_rgba(key.get_color()) == to_rgba("k")
        assert ax.lines.index(line) > ax.lines.index(trajectory)  # on top, not hidden


def test_fig4_annotates_error_and_gain_per_axis(run):
    fig = figures.nn_figure(run, vessel=1)
    titles = [ax.get_title(loc="left") for ax in fig.axes[1::2]]
    assert len(titles) == 3
    for title in titles:
        assert "relative RMS error" in title and "fitted NN = " in title


def test_fig4_fit_is_least_squares():
    f = np.array([1.0, 2.0, -1.0])
    error, gain = figures._fit(0.5 * f, f)
    assert gain == pytest.approx(0.5) and error == pytest.approx(0.5)


def test_fig6_has_a_zoom_of_the_saturated_seconds(run):
    fig = figures.forces_figure(run, vessel=2)
    assert len(fig.axes) == 6
    whole, zoom = fig.axes[0].get_xlim(), fig.axes[1].get_xlim()
    saturated = np.any(run.tau_command[:, 2] != run.tau_applied[:, 2], axis=-1)
    last = run.time[np.flatnonzero(saturated)[-1]]
    assert zoom[1] - zoom[0] < 0.5 * (whole[1] - whole[0])
    assert zoom[1] > last  # the zoom shows every saturated sample


@pytest.mark.parametrize("draw", [figures.coordination_figure, figures.speed_figure])
def test_float32_floor_is_marked(run, draw):
    floor = float(np.spacing(np.float32(0.1)))
    log_axis = draw(run).axes[1]
    levels = [line.get_ydata()[0] for line in log_axis.lines if "float32" in line.get_label()]
    assert levels == [pytest.approx(floor)]


def test_figures_number_vessels_from_0_like_the_env(run):
    """The env's agents are vessel_0..vessel_4 and so are the figures' (the paper counts from 1)."""
    labels = figures.paths_figure(run).axes[0].get_legend_handles_labels()[1]
    assert [label for label in labels if label.startswith("vessel")] == [
        f"vessel {i}" for i in range(run.eta.shape[1])
    ]
    coordination = figures.coordination_figure(run).axes[0].get_legend_handles_labels()[1]
    assert coordination[0] == r"$\theta_0 - \theta_{1}$"
    speeds = figures.speed_figure(run).axes[0].get_legend_handles_labels()[1]
    assert speeds[0] == r"$\hat v_{0}$"
    title = figures.forces_figure(run, vessel=2)._suptitle.get_text()
    assert title == "Control forces of vessel 2 (the paper's vessel 3)"
    nn = figures.nn_figure(run, vessel=1)
    assert "vessel 1 (the paper's vessel 2)" in nn._suptitle.get_text()
    assert nn.axes[0].get_legend_handles_labels()[1][0] == "true $f_1$"
