"""cpf-export: the ONNX graph acts as the torch policy; cpf-bench runs it through onnxruntime."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

pytest.importorskip("onnx")
onnxruntime = pytest.importorskip("onnxruntime")

from agents import load_policy  # noqa: E402
from agents.onnx_policy import OnnxActor, load_onnx_policy  # noqa: E402
from cpf_commands.bench.run import run_bench  # noqa: E402
from cpf_commands.export import export_main  # noqa: E402
from cpf_env import FleetSim  # noqa: E402

AGENT = ROOT / "results/residual_rl/agents/residual_ppo_bench_lossy_links_5m_s0"


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("onnx") / "agent.onnx"
    assert export_main([str(AGENT), str(out)]) == 0
    return out


def test_export_reports_the_difference_from_torch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert export_main([str(AGENT), str(tmp_path / "a.onnx"), "--checks", "1000"]) == 0
    printed = capsys.readouterr().out
    difference = float(printed.rsplit(":", 1)[1])
    assert 0.0 <= difference < 1e-5


def test_onnx_actions_and_residuals_match_torch_on_1000_observations(exported: Path) -> None:
    """200 fleets x 5 vessels of real inputs, along 20 steps of the torch policy."""
    torch_policy = load_policy(AGENT)
    torch_actor = torch_policy.actor
    seen: list[np.ndarray] = []

    def recording(rows: np.ndarray) -> np.ndarray:
        seen.append(rows)
        return torch_actor(rows)

    torch_policy.actor = recording  # type: ignore[assignment]
    onnx_actor = OnnxActor(exported)
    sim = FleetSim(torch_policy.scenario, num_fleets=200)
    obs = sim.reset(seeds=list(range(200)))
    worst = 0.0
    for _ in range(20):
        command = torch_policy.act_batch(obs)
        rows = seen[-1]
        assert rows.shape == (1000, onnx_actor.input_size)
        (action, residual) = onnx_actor.session.run(None, {"inputs": rows.reshape(200, 5, -1)})
        expected = torch_actor(rows).reshape(200, 5, -1)
        worst = max(worst, float(np.max(np.abs(action - expected))))
        # the residual output in newtons: what the torch policy added to the base's force
        np.testing.assert_allclose(residual, torch_policy.diagnostics["residual"], atol=1e-5)
        obs = sim.step(command)
    assert worst < 1e-5


def test_bench_runs_the_onnx_policy_within_the_torch_policys_interval(exported: Path) -> None:
    cells = run_bench(
        {"torch": AGENT, "onnx": exported, "nn_dsc": "nn_dsc"},
        ["bench_lossy_links"],
        seeds=4,
        steps=200,
    )
    torch_cost = cells[0].metrics["cost"]
    onnx_cost = cells[1].metrics["cost"]
    np.testing.assert_allclose(onnx_cost, torch_cost, rtol=1e-6)
    assert not np.array_equal(cells[2].metrics["cost"], torch_cost)  # the correction acts


def test_an_onnx_file_for_another_fleet_size_is_refused(exported: Path) -> None:
    with pytest.raises(ValueError, match="exported for fleets of 5"):
        load_onnx_policy(exported, "bench_large_fleet")
