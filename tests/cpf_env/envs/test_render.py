"""Renderer: frames in rgb_array mode, human mode headless, closing, lazy import."""

from __future__ import annotations

import subprocess
import sys
import warnings

import matplotlib

matplotlib.use("Agg")  # headless; must precede any pyplot import

import numpy as np
import pytest
from conftest import ROOT

import cpf_env
from cpf_env.envs.gym_envs import CentralizedFleetEnv, CentralizedFleetVectorEnv
from cpf_env.envs.render import FleetRenderer
from cpf_env.sim.fleet import FleetSim


def forward(env: CentralizedFleetEnv, steps: int) -> None:
    """Push every vessel forward and turn it a little, advancing theta at v0."""
    action = np.zeros((env.scenario.n, env.sim.act_dim), dtype=np.float32)
    action[:, 0], action[:, 2], action[:, 3] = 5.0, 0.3, 0.1
    for _ in range(steps):
        env.step(action.reshape(-1))


def test_rgb_array_frame_is_a_nonblank_image_that_changes() -> None:
    env = CentralizedFleetEnv(render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert isinstance(first, np.ndarray)
    assert first.dtype == np.uint8 and first.shape == (480, 640, 3)
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 20  # paths, hulls, text: not blank
    forward(env, 40)
    later = env.render()
    assert later is not None and later.shape == first.shape
    assert np.mean(np.any(later != first, axis=-1)) > 0.001
    env.close()


def test_new_episode_clears_trails() -> None:
    env = CentralizedFleetEnv(render_mode="rgb_array")
    env.reset(seed=0)
    fresh = env.render()
    forward(env, 30)
    env.render()
    env.reset(seed=0)
    assert np.array_equal(env.render(), fresh)
    env.close()


@pytest.mark.parametrize("name", cpf_env.scenarios.list_scenarios())
def test_every_scenario_renders(name: str) -> None:
    sim = FleetSim(cpf_env.scenarios.get(name))
    sim.reset(seeds=[0])
    renderer = FleetRenderer(sim.scenario, "rgb_array", size=(320, 240))
    frame = renderer.draw(sim)
    assert frame is not None and frame.shape == (240, 320, 3)
    assert renderer.hull_scale >= 1.0
    renderer.close()


def test_human_mode_under_agg_is_silent_and_returns_none() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = CentralizedFleetEnv(render_mode="human")
        env.reset(seed=0)  # renders
        forward(env, 2)  # renders
        assert env.render() is None
        parallel = cpf_env.parallel_env(render_mode="human")
        parallel.reset(seed=0)
        parallel.close()
    env.close()


def test_close_is_idempotent_and_draw_after_close_raises() -> None:
    env = CentralizedFleetEnv(render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    env.close()
    env.close()
    assert env.render() is not None  # a new renderer
    env.close()
    renderer = FleetRenderer(env.scenario, "human")
    renderer.close()
    renderer.close()
    with pytest.raises(RuntimeError, match="closed"):
        renderer.draw(env.sim)
    with pytest.raises(ValueError, match="mode"):
        FleetRenderer(env.scenario, "ansi")


def test_parallel_and_vector_envs_render() -> None:
    parallel = cpf_env.parallel_env("switching_topology", render_mode="rgb_array")
    parallel.reset(seed=0)
    frame = parallel.render()
    assert isinstance(frame, np.ndarray) and frame.shape == (480, 640, 3)
    parallel.close()
    envs = CentralizedFleetVectorEnv(num_envs=2, render_mode="rgb_array")
    envs.reset(seed=0)
    frames = envs.render()
    assert frames is not None and len(frames) == 2 and frames[0].shape == (480, 640, 3)
    envs.close()


def test_importing_cpf_env_does_not_import_matplotlib() -> None:
    code = "import sys, cpf_env; assert 'matplotlib' not in sys.modules, 'matplotlib imported'"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_human_mode_on_an_interactive_backend_pauses_for_dt(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from matplotlib import pyplot as plt

    pauses: list[float] = []
    monkeypatch.setattr(plt, "get_backend", lambda: "TkAgg")
    monkeypatch.setattr(plt, "pause", pauses.append)
    env = CentralizedFleetEnv(render_mode="human")
    env.reset(seed=0)
    forward(env, 1)
    assert pauses == [env.scenario.dt, env.scenario.dt]
    env.close()
