"""The leaderboard generator: its tables from constructed cells, its agents, its refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ROOT

from cpf_bench.report import CellResult
from cpf_commands.bench import leaderboard
from cpf_env.evaluation.fleet_metrics import METRICS

SEEDS = tuple(range(4))


def _cell(policy, scenario, cost):
    metrics = {name: np.full(4, 0.01) for name in METRICS}
    metrics["progress_window"] = np.full(4, 0.9)
    metrics["terminated"] = np.zeros(4)
    metrics["cost"] = np.asarray(cost, dtype=float)
    return CellResult(policy, scenario, SEEDS, False, metrics)


def test_power_table_uses_the_spread_of_paired_differences():
    base = [100.0, 110.0, 120.0, 130.0]
    other = [101.0, 109.0, 122.0, 128.0]  # differences 1, -1, 2, -2
    cells = [_cell("nn_dsc", "s", base), _cell("backstepping", "s", other)]
    (row,) = leaderboard._power_table(cells)[2:]
    sd = np.std([1.0, -1.0, 2.0, -2.0], ddof=1)
    z = 1.959963984540054 + 0.8416212335729143
    expected = [max(2, math.ceil((z * sd / (f * 115.0)) ** 2)) for f in (0.01, 0.02, 0.05)]
    assert row.split(" | ")[1:] == [
        f"{sd:.3g}",
        *(str(k) for k in expected[:-1]),
        f"{expected[-1]} |",
    ]


def test_suite_table_labels_a_cell_that_did_not_run():
    cells = [_cell("nn_dsc", "a", [1.0] * 4), _cell("nn_dsc", "b", [1.0] * 4)]
    cells.append(_cell(next(iter(leaderboard.AGENTS)), "a", [0.5] * 4))
    lines = leaderboard._suite_table(cells)
    assert "not run" in lines[-1] and "beats" in lines[-1]


def test_agents_are_judged_against_each_scenarios_best_deployable_design():
    """Scenario a: mpc is the best deployable design; b: nn_dsc (mpc did not run)."""
    agent = next(iter(leaderboard.HARD_AGENTS))
    cells = [
        _cell("nn_dsc", "a", [10.0, 11.0, 12.0, 13.0]),
        _cell("mpc", "a", [8.0, 9.0, 10.0, 11.0]),
        _cell("oracle", "a", [4.0] * 4),
        _cell(agent, "a", [6.0, 7.0, 8.0, 9.0]),
        _cell("nn_dsc", "b", [10.0, 11.0, 12.0, 13.0]),
        _cell("oracle", "b", [4.0] * 4),
        _cell(agent, "b", [11.0, 12.0, 13.0, 14.0]),
    ]
    header, _, row = leaderboard._against_best(cells, [agent])
    assert "a (vs mpc)" in header and "b (vs nn_dsc)" in header
    assert row.split(" | ")[1:] == ["7.5 beats", "12.5 loses |"]


def test_page_without_markers_is_refused_before_running(tmp_path, capsys):
    page = tmp_path / "results.md"
    page.write_text("# no markers\n")
    with pytest.raises(SystemExit):
        leaderboard.main(["--page", str(page), "--results", str(tmp_path)])
    assert "marker" in capsys.readouterr().err
    assert page.read_text() == "# no markers\n"


def test_the_default_page_has_the_markers_of_every_track():
    text = (ROOT / leaderboard.PAGE).read_text()
    for track in leaderboard.TRACKS.values():
        assert all(text.count(marker) == 1 for marker in track.markers)


def test_every_reference_agent_is_committed_loads_acts_and_is_listed() -> None:
    """Each leaderboard agent loads with today's code, acts, and results/README.md names it."""
    pytest.importorskip("torch")
    from agents import load_policy
    from cpf_env.sim.fleet import FleetSim

    index = (ROOT / "results" / "README.md").read_text()
    agents = [*leaderboard.AGENTS, *leaderboard.HARD_AGENTS]
    assert sorted(agents) == sorted(
        f"results/agents/{p.name}" for p in (ROOT / "results" / "agents").iterdir()
    )
    for folder in agents:
        assert f"`{folder.removeprefix('results/')}/`" in index, folder
        policy = load_policy(ROOT / folder)
        sim = FleetSim(policy.scenario, num_fleets=2)
        obs = sim.reset(seeds=[0, 1])
        policy.reset()
        for _ in range(3):
            action = policy.act_batch(obs)
            assert np.all(np.isfinite(action))
            obs = sim.step(action)


def test_a_method_is_scored_with_each_agent_where_it_trained() -> None:
    """The learned filter's hard_sensing agent counts on hard_sensing, not on scenario b."""
    agents = leaderboard.HARD_METHODS["learned filter"]
    sensing = next(f for f, s in agents.items() if s == "hard_sensing")
    cells = [
        _cell("mpc", "hard_sensing", [10.0] * 4),
        _cell("oracle", "hard_sensing", [2.0] * 4),
        _cell(sensing, "hard_sensing", [6.0] * 4),
        _cell("mpc", "b", [10.0] * 4),
        _cell("oracle", "b", [2.0] * 4),
        _cell(sensing, "b", [20.0] * 4),
    ]
    header, _, *rows = leaderboard.room_table(leaderboard._by_method(cells))
    assert rows == ["| learned filter | 0.50 (0.50 to 0.50) | 0.50 |"]
    assert header.endswith("| hard_sensing |")
    for method, trained in leaderboard.HARD_METHODS.items():
        assert set(trained) <= set(leaderboard.HARD_AGENTS), method
    listed = {folder for trained in leaderboard.HARD_METHODS.values() for folder in trained}
    assert listed == set(leaderboard.HARD_AGENTS)
