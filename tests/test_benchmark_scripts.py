"""The benchmark scripts: numpy_plant_baseline.py's RK4 integrates the simulator's own plant;
gpu_check.py says when there is no GPU and reports the vessel-steps it trained."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from cpf_env import scenarios
from cpf_env.model.disturbances import D_SCALE
from cpf_env.sim.fleet import FleetSim

ROOT = Path(__file__).resolve().parents[1]


def _load_example(name: str = "numpy_plant_baseline"):
    path = ROOT / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", ["bench_current_waves", "bench_heterogeneous"])
def test_numpy_rk4_integrates_the_simulators_plant(name):
    """20 control periods of 4 fleets: the numpy RK4 lands where ``FleetSim.step`` does.

    bench_current_waves has a current, waves, wind and the paper's unmodeled
    terms; bench_heterogeneous perturbed models (every vessel its own
    parameters). Both sides do the same floating-point operations in the same
    order (on the development machine they agree bit for bit); they may differ
    only where a numpy build implements sin and cos differently from libm (a
    few ulp), which 1e-12 of each quantity's magnitude covers many times over,
    while a modelling difference (a coefficient off by 0.2 %, the current's
    rotation, a term of M^-1 left out) fails it.
    """
    example = _load_example()
    sim = FleetSim(scenarios.get(name), num_fleets=4)
    sim.reset(seeds=[0, 1, 2, 3])
    c = sim.constants
    rng = np.random.default_rng(0)
    scale = float(c.disturbances[D_SCALE])
    for _ in range(20):
        actions = np.zeros((4, sim.n, sim.act_dim))
        actions[..., :3] = rng.uniform(-1.2, 1.2, (4, sim.n, 3)) * c.tau_scale  # some saturate
        actions[..., 3] = 0.3
        params, state, load = example.plant_inputs(sim)
        applied = np.clip(actions[..., :3], c.tau_min, c.tau_max).reshape(-1, 3)
        load = load._replace(tau_u=applied[:, 0], tau_v=applied[:, 1], tau_r=applied[:, 2])
        t0 = float(sim.arrays.step[0]) * c.dt
        expected = example.numpy_rk4_period(params, scale, t0, c.dt, c.substeps, state, load)
        sim.step(actions)
        got = np.concatenate([sim.arrays.eta, sim.arrays.nu], axis=2).reshape(-1, 6)
        for column, values in enumerate(expected):
            magnitude = np.abs(values).max()
            np.testing.assert_allclose(got[:, column], values, rtol=1e-12, atol=1e-12 * magnitude)


def test_numpy_baseline_prints_both_rates_and_their_ratio(capsys):
    example = _load_example()
    (row,) = example.main(["--fleets", "2", "--seconds", "0.05"])
    assert row["B"] == 2 and row["n"] == 5
    assert row["simulator"] > 0 and row["numpy"] > 0
    assert row["ratio"] == pytest.approx(row["simulator"] / row["numpy"])
    out = capsys.readouterr().out
    assert "FleetSim.step" in out and "numpy RK4" in out and f"{row['ratio']:.2f}x" in out


def test_without_a_cuda_device_the_gpu_check_says_so_and_trains_nothing(monkeypatch, capsys):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert _load_example("gpu_check").main(["--device", "cuda"]) == {}
    assert "no CUDA device" in capsys.readouterr().out


def test_the_gpu_check_reports_the_vessel_steps_it_trained(capsys):
    rates = _load_example("gpu_check").main(
        ["--device", "cpu", "--timesteps", "1000", "--fleets", "4"]
    )
    assert set(rates) == {"cpu"} and rates["cpu"] > 0.0
    out = capsys.readouterr().out
    trained = re.search(r"for ([\d,]+) vessel-steps \(-n 1,000 rounded up", out)  # cpf-train's
    assert trained is not None and f"cpu: {trained.group(1)} vessel-steps in" in out
    assert trained.group(1) != "1,000"  # whole rollouts: the count is read, not the budget
