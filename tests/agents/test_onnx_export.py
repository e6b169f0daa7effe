"""cpf-export: the ONNX graph acts as the torch policy; cpf-bench runs it through onnxruntime."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

pytest.importorskip("onnx")
onnxruntime = pytest.importorskip("onnxruntime")

from agents import load_policy  # noqa: E402
from agents.folder.loading import TrainedPolicy  # noqa: E402
from agents.folder.onnx_policy import OnnxActor, load_onnx_policy  # noqa: E402
from cpf_commands.bench.run import run_bench  # noqa: E402
from cpf_commands.export import export_main  # noqa: E402
from cpf_env import FleetSim  # noqa: E402
from cpf_env.scenarios import make_scenario  # noqa: E402

AGENT = ROOT / "tests/fixtures/agents/residual_ppo_lossy_links"


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
        num_seeds=4,
        max_steps=200,
    )
    torch_cost = cells[0].metrics["cost"]
    onnx_cost = cells[1].metrics["cost"]
    np.testing.assert_allclose(onnx_cost, torch_cost, rtol=1e-6)
    assert not np.array_equal(cells[2].metrics["cost"], torch_cost)  # the correction acts


def test_an_onnx_file_for_another_fleet_size_is_refused(exported: Path) -> None:
    with pytest.raises(ValueError, match="exported for fleets of 5"):
        load_onnx_policy(exported, "bench_large_fleet")


# ---- an agent with a neighbour encoder and a history: static K', the history in the input -------


@pytest.fixture(scope="module")
def encoder_agent(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import torch
    from test_loading import CONFIG

    from agents import train

    torch.manual_seed(0)
    return train(CONFIG, tmp_path_factory.mktemp("encoder") / "agent", progress=False)


def _actions_recorded(policy: TrainedPolicy) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Record the inputs (R, k) and actions (R, a) of the policy's actor at each ``act_batch``."""
    inputs: list[np.ndarray] = []
    actions: list[np.ndarray] = []
    actor = policy.actor

    class Recorder:
        input_size, action_size = actor.input_size, actor.action_size

        def __call__(self, rows: np.ndarray) -> np.ndarray:
            inputs.append(rows.copy())
            actions.append(actor(rows))
            return actions[-1]

    policy.actor = Recorder()
    return inputs, actions


def test_an_encoder_agent_exported_for_four_slots_acts_as_torch_on_a_five_vessel_star(
    encoder_agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Trained on 6 slots, exported with --slots 4, the most a fleet of 5 vessels needs.

    On a star whose centre has 4 neighbours, the graph (4 slots, all filled at the
    centre) acts as the torch policy (6 slots, 2 of them empty) to float rounding,
    the history, which each policy keeps itself, included.
    """
    from test_mixture_env import fleet_of

    from cpf_env.model.graph import Graph

    out = tmp_path / "star.onnx"
    assert export_main([str(encoder_agent), str(out), "--slots", "4"]) == 0
    assert float(capsys.readouterr().out.rsplit(":", 1)[1]) < 1e-5
    star = fleet_of(5, Graph.star(5, center=2, leaders=(2,)))
    torch_policy = load_policy(encoder_agent, scenario=star)
    onnx_policy = load_onnx_policy(out, scenario=star)
    assert onnx_policy.actor.input_size == 18 + 4 * 4 + 3 * 22  # own, 4 slots, 3 entries
    _, torch_actions = _actions_recorded(torch_policy)
    onnx_inputs, onnx_actions = _actions_recorded(onnx_policy)
    sim = FleetSim(star, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(30):
        command = torch_policy.act_batch(obs)
        onnx_policy.act_batch(obs)
        np.testing.assert_allclose(onnx_actions[-1], torch_actions[-1], rtol=1e-4, atol=1e-7)
        obs = sim.step(command)
    centre = onnx_inputs[-1][2]
    assert np.all(centre[18 : 18 + 4 * 4 : 4] != 0.0)  # the centre's 4 slots all filled
    assert centre[-1] == 1.0  # the oldest history entry is filled by now
    assert np.abs(np.concatenate(torch_actions)).max() > 1e-4  # the actions are not all zero


def test_an_encoder_agent_exported_for_a_larger_fleet_acts_as_torch_there(
    encoder_agent: Path, tmp_path: Path
) -> None:
    """Trained on bench_mild's 5 vessels, exported for the 7-vessel star of degree 6."""
    out = tmp_path / "star7.onnx"
    name = "bench_large_fleet_shift"
    assert export_main([str(encoder_agent), str(out), "--slots", "6", "--scenario", name]) == 0
    torch_policy = load_policy(encoder_agent, scenario=name)
    onnx_policy = load_onnx_policy(out, scenario=name)
    assert onnx_policy.actor.n == 7
    sim = FleetSim(make_scenario(name), num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(20):
        command = torch_policy.act_batch(obs)
        np.testing.assert_allclose(onnx_policy.act_batch(obs), command, rtol=1e-4, atol=1e-6)
        obs = sim.step(command)
    with pytest.raises(ValueError, match="exported for fleets of 7 vessels"):
        load_onnx_policy(out)  # the training scenario has 5


def test_an_encoder_agent_with_history_runs_from_onnx_as_from_torch(
    encoder_agent: Path, tmp_path: Path
) -> None:
    """load_onnx_policy keeps the history itself; K' = 3 runs the chain, K' = 1 is refused.

    The chain's vessels have up to 2 neighbours: a graph of 1 slot is refused, saying how
    to export one that fits.
    """
    out = tmp_path / "three.onnx"
    assert export_main([str(encoder_agent), str(out), "--slots", "3"]) == 0
    torch_policy, onnx_policy = load_policy(encoder_agent), load_onnx_policy(out)
    sim = FleetSim(torch_policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(30):
        command = torch_policy.act_batch(obs)
        np.testing.assert_allclose(
            onnx_policy.act_batch(obs) - command, 0.0, atol=1e-4
        )  # forces of up to ~10 N: float32 rounding of 1e-6 relative
        obs = sim.step(command)
    one = tmp_path / "one.onnx"
    assert export_main([str(encoder_agent), str(one), "--slots", "1"]) == 0
    with pytest.raises(ValueError) as caught:
        load_onnx_policy(one)
    message = str(caught.value)
    assert "exported for 1 neighbour slots" in message and "gives a vessel 2" in message
    assert "re-export the agent folder with cpf-export FOLDER OUT.onnx --slots K, K >= 2" in message
    assert "neighbour_slots" not in message


@pytest.mark.parametrize("slots", ["5", "100"])
def test_more_slots_than_a_vessel_can_have_neighbours_are_refused(
    encoder_agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], slots: str
) -> None:
    """bench_mild's fleet of n = 5: at most 4 neighbours, so --slots 5 is refused."""
    out = tmp_path / "many.onnx"
    with pytest.raises(SystemExit) as caught:
        export_main([str(encoder_agent), str(out), "--slots", slots])
    assert caught.value.code == 2
    error = capsys.readouterr().err
    assert "--slots must be in [1, 4]" in error and "n = 5 vessels" in error
    assert "export for it (--scenario NAME)" in error
    assert f"got {slots}" in error and not out.exists()


def test_an_mlp_agent_is_not_exported_for_a_fleet_of_higher_degree(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "a.onnx"
    with pytest.raises(SystemExit):
        export_main([str(AGENT), str(out), "--scenario", "bench_large_fleet_shift"])
    error = capsys.readouterr().err
    assert "train with --set residual.neighbour_slots=K to run on graphs of higher degree" in error
    assert not out.exists()


def test_slots_for_an_mlp_agent_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        export_main([str(AGENT), str(tmp_path / "a.onnx"), "--slots", "9"])
    assert "--slots is for an agent with a neighbour encoder" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        export_main([str(AGENT), str(tmp_path / "a.onnx"), "--slots", "0"])
    assert "--slots must be >= 1" in capsys.readouterr().err


def test_an_agent_with_learned_messages_exports_and_sends_them_from_onnx(tmp_path: Path) -> None:
    """The graph's action holds the messages; its residual output only the correction."""
    from agents import TrainConfig, train

    config = TrainConfig(
        scenario="hard_crossing", base_policy="nn_dsc",
        residual={"mode": "force_and_rate", "messages": 5},  # type: ignore[arg-type]
        timesteps=64, fleets=1, n_steps=16, batch_size=64, n_epochs=1, torch_threads=1,
    )  # fmt: skip
    folder = train(config, tmp_path / "agent", False)
    out = tmp_path / "agent.onnx"
    assert export_main([str(folder), str(out), "--checks", "100"]) == 0
    torch_policy, onnx_policy = load_policy(folder), load_onnx_policy(out)
    sim = FleetSim(torch_policy.scenario)
    obs = sim.reset(seeds=[5])
    for policy in (torch_policy, onnx_policy):
        policy.reset()
    for _ in range(10):
        expected, got = torch_policy.act_batch(obs), onnx_policy.act_batch(obs)
        np.testing.assert_allclose(got, expected, atol=1e-5)
        assert torch_policy.diagnostics["residual"].shape == (1, 4, 4)
        obs = sim.step(expected)
    assert np.any(expected[..., 5:] != 0.0)  # messages sent
