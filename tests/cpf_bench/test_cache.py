"""The content-keyed cache of the receding-horizon cells, and the headroom table."""

from __future__ import annotations

import numpy as np
import pytest

from cpf_bench import cache, evaluate
from cpf_bench.headroom import headroom_rows, headroom_table, oracle_not_lowest
from cpf_bench.report import CellResult
from cpf_env import scenarios


def test_keys_change_with_the_scenario_the_horizon_and_the_policy():
    mild = scenarios.get("bench_mild")
    key = cache.cell_key("oracle", mild, 20)
    assert key == cache.cell_key("oracle", mild, 20)
    assert key != cache.cell_key("oracle", mild, 21)
    assert key != cache.cell_key("mpc", mild, 20)
    assert key != cache.cell_key("oracle", mild.replace(max_path_error=9.0), 20)
    with pytest.raises(
        ValueError,
        match="only oracle, mpc, mpc_tuned, mpc_tuned_ekf, mpc_tuned_mmae, mpc_tuned_safe, "
        "mpc_tuned_ekf_safe are cached, not 'nn_dsc'",
    ):
        cache.cell_key("nn_dsc", mild, 20)


def test_cells_round_trip_per_seed_and_partial_hits_miss(tmp_path):
    mild = scenarios.get("bench_mild")
    metrics = {"cost": np.array([1.5, 2.25]), "steps": np.array([20.0, 20.0])}
    assert cache.load_cell("mpc", mild, [1, 2], 20, tmp_path) is None
    cache.store_cell("mpc", mild, [1, 2], 20, metrics, tmp_path)
    loaded = cache.load_cell("mpc", mild, [2, 1], 20, tmp_path)
    np.testing.assert_array_equal(loaded["cost"], [2.25, 1.5])
    assert cache.load_cell("mpc", mild, [1, 2, 3], 20, tmp_path) is None
    assert cache.load_cell("mpc", mild, [1], 21, tmp_path) is None
    cache.store_cell("mpc", mild, [3], 20, {k: v[:1] for k, v in metrics.items()}, tmp_path)
    assert cache.load_cell("mpc", mild, [1, 2, 3], 20, tmp_path)["cost"].tolist() == [
        1.5,
        2.25,
        1.5,
    ]


def test_the_bench_reuses_a_matching_cell_and_recomputes_otherwise(tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "CACHE_DIRECTORY", tmp_path / "cache")
    task = scenarios.get("bench_mild").replace(max_steps=10)
    first = evaluate(["mpc", "nn_dsc"], [task], num_seeds=2).cells
    assert len(list((tmp_path / "cache").glob("mpc-bench_mild-*.json"))) == 1
    planted = cache.load_cell("mpc", task, (10000, 10001), None)
    planted["cost"] = np.array([-1.0, -2.0])  # a cached cell is read, not run again
    cache.store_cell("mpc", task, (10000, 10001), None, planted)
    again = evaluate(["mpc", "nn_dsc"], [task], num_seeds=2).cells
    assert again[0].metrics["cost"].tolist() == [-1.0, -2.0]
    assert again[1].metrics["cost"].tolist() == first[1].metrics["cost"].tolist()
    other = evaluate(["mpc"], [task.replace(max_steps=11)], num_seeds=2).cells  # another key
    assert other[0].metrics["cost"].min() > 0
    evaluate(["mpc"], [task], num_seeds=3, max_steps=5)  # a quick look is not kept
    assert cache.load_cell("mpc", task, (10000, 10001, 10002), 5) is None


def _cells(costs):
    return [
        CellResult(p, s, (0, 1), False, {"cost": np.array(j), "cost_window": np.array(j) / 10})
        for (p, s), j in costs.items()
    ]


def test_headroom_is_measured_against_the_best_deployable_analytic_design():
    cells = _cells(
        {
            ("nn_dsc", "a"): [10.0, 10.0],
            ("mpc", "a"): [8.0, 8.0],
            ("nn_dsc_privileged", "a"): [1.0, 1.0],  # privileged: never the deployable best
            ("oracle", "a"): [6.0, 6.0],
            ("nn_dsc", "b"): [4.0, 4.0],
            ("oracle", "b"): [5.0, 5.0],
        }
    )
    rows = {row["scenario"]: row for row in headroom_rows(cells)}
    assert rows["a"]["best"] == "mpc" and rows["a"]["headroom"] == 0.25
    assert rows["b"]["headroom"] == 1.0 - 5.0 / 4.0  # negative: the bound is not below
    assert oracle_not_lowest(cells) == [
        ("a", "nn_dsc_privileged", 1.0, 6.0),
        ("b", "nn_dsc", 4.0, 5.0),
    ]
    assert rows["a"]["interval"] == (0.25, 0.25)  # no spread over the seeds
    text = "\n".join(headroom_table(cells))
    assert "| a | 10 | mpc | 8 | 6 | 25.0% (25.0% to 25.0%) |" in text
    assert "Lower mean cost than oracle: nn_dsc_privileged on a" in text


def test_a_score_above_one_is_flagged_in_the_summary():
    from cpf_bench.episodes import METRICS
    from cpf_bench.report import summarize
    from cpf_commands.bench.views import gap_table

    def cell(policy, costs):
        metrics = {name: np.array([1.0, 1.1, 0.9]) for name in METRICS}
        metrics["cost"] = metrics["cost_window"] = np.array(costs)
        return CellResult(policy, "a", (0, 1, 2), False, metrics)

    cells = [
        cell("nn_dsc", [10.0, 10.5, 9.5]),
        cell("oracle", [6.0, 6.5, 5.5]),
        cell("mpc", [8.0, 8.5, 7.5]),
        cell("agent", [5.0, 5.4, 4.8]),
    ]
    lines = "\n".join(gap_table(summarize(cells), cells, "cost", "nn_dsc"))
    assert "| mpc | 0.50 [0.50, 0.50] |" in lines  # (10 - 8) / (10 - 6), not flagged
    assert "| agent | 1.23 [1.18, 1.27] (above 1: beats the bound) |" in lines


def test_the_headroom_interval_pairs_the_seeds_both_ran():
    cells = [
        CellResult("mpc", "a", (0, 1, 2, 3), False,
                   {"cost": np.array([10.0, 20.0, 30.0, 40.0]), "cost_window": np.ones(4)}),
        CellResult("oracle", "a", (3, 2, 1, 0), False,
                   {"cost": np.array([20.0, 15.0, 10.0, 5.0]), "cost_window": np.ones(4)}),
    ]  # fmt: skip
    (row,) = headroom_rows(cells)
    low, high = row["interval"]
    # paired by seed the bound is half of the best on every seed: no spread
    assert row["headroom"] == pytest.approx(0.5) and low == pytest.approx(0.5) == high
