"""``cpf-curves``: IQM over training seeds against a hand calculation, and the files it writes."""

from __future__ import annotations

import csv
import functools
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import STUDENT_TOML

from agents.training.evaluation import ValidationEvaluator
from cpf_commands import distill as distill_command
from cpf_commands.bench.run import run_bench
from cpf_commands.curves import curves_main
from cpf_commands.distill import distill_main
from cpf_env.scenarios.splits import EVALUATION_SEED, VALIDATION_SEED

#: Four runs (training seeds): (vessel_steps, wall_clock_seconds, mean_cost) per evaluation.
RUNS = {
    "s0": [(0, 1.0, 10.0), (100, 2.0, 8.0), (200, 3.0, 5.0)],
    "s1": [(0, 1.5, 10.0), (100, 2.5, 9.0), (200, 3.5, 7.0)],
    "s2": [(0, 1.0, 10.0), (100, 2.0, 12.0), (200, 4.0, 6.0)],
    "s3": [(0, 2.0, 10.0), (100, 3.0, 30.0), (200, 4.0, 1.0)],
}


def _write_runs(root: Path, base: str = "nn_dsc", evaluation: dict | None = None) -> list[str]:
    folders = []
    for name, rows in RUNS.items():
        folder = root / name
        folder.mkdir(parents=True)
        lines = ["vessel_steps,wall_clock_seconds,evaluation_seconds,mean_cost,cost_bench_mild"]
        lines += [f"{s},{t},0.1,{c},{c}" for s, t, c in rows]
        (folder / "evaluations.csv").write_text("\n".join(lines) + "\n")
        record = {"config": {"scenario": "bench_mild", "base": base}, "evaluation": evaluation}
        (folder / "run.json").write_text(json.dumps(record))
        folders.append(str(folder))
    return folders


def _curves(out: Path) -> dict[str, list[dict[str, float]]]:
    rows = list(csv.DictReader((out / "curves.csv").open()))
    by_axis: dict[str, list[dict[str, float]]] = {}
    for row in rows:
        by_axis.setdefault(row.pop("axis"), []).append({k: float(v) for k, v in row.items()})
    return by_axis


def test_iqm_over_seeds_matches_the_hand_calculation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "curves"
    assert curves_main([*_write_runs(tmp_path / "runs"), "--out", str(out)]) == 0
    curves = _curves(out)
    steps = curves["vessel_steps"]
    assert [r["x"] for r in steps] == [0, 100, 200]
    # IQM of 4 values: drop the lowest and the highest, average the middle two.
    assert [r["iqm"] for r in steps] == [10.0, (9 + 12) / 2, (5 + 6) / 2]
    assert all(r["base_cost"] == 10.0 and r["runs"] == 4 for r in steps)  # the 0-step rows
    assert steps[0]["ci_low"] == steps[0]["ci_high"] == 10.0  # no spread, no width
    assert steps[2]["ci_low"] <= 5.5 <= steps[2]["ci_high"] < 10.0
    # Wall clock: from the latest first evaluation (2 s) to the earliest last one (3 s); each
    # run's cost is its latest evaluation by then: t=2: 8,10,12,10; t=2.5: 8,9,12,10;
    # t=3: 5,9,12,30.
    seconds = curves["wall_clock_seconds"]
    assert [r["x"] for r in seconds] == [2.0, 2.5, 3.0]
    assert [r["iqm"] for r in seconds] == [10.0, 9.5, 10.5]
    printed = capsys.readouterr().out
    assert "IQM below base policy from 200 vessel-steps" in printed
    assert "whole 95 % interval below from 200 vessel-steps" in printed
    assert "IQM below base policy from 2.5 s" in printed
    assert (out / "curves.png").read_bytes()[:4] == b"\x89PNG"


def test_the_base_line_of_an_analytic_policy_is_the_benchmark_number(tmp_path: Path) -> None:
    evaluation = {
        "split": "test",
        "scenarios": ["bench_mild"],
        "num_seeds": 2,
        "steps": 20,
    }  # as written before max_steps
    folders = _write_runs(tmp_path / "runs", base="none", evaluation=evaluation)
    with pytest.raises(SystemExit):  # from scratch: no base at 0 steps to compare with
        curves_main([*folders, "--out", str(tmp_path / "c")])
    assert curves_main([*folders, "--out", str(tmp_path / "c"), "--base-policy", "dsc"]) == 0
    cells = run_bench(["dsc"], ["bench_mild"], num_seeds=2, max_steps=20, split="test")
    expected = float(np.mean(cells[0].metrics["cost"]))
    assert _curves(tmp_path / "c")["vessel_steps"][0]["base_cost"] == expected


def test_the_lines_to_beat_run_on_the_seeds_the_runs_were_evaluated_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run evaluated on the validation seeds is compared on them; mixed seeds are refused."""
    evaluation = {"split": "validation", "seed": VALIDATION_SEED, "scenarios": ["bench_mild"],
                  "num_seeds": 2, "max_steps": 20}  # fmt: skip
    folders = _write_runs(tmp_path / "runs", base="none", evaluation=evaluation)
    assert curves_main([*folders, "--out", str(tmp_path / "c"), "--base-policy", "dsc"]) == 0
    validation, test = (
        float(np.mean(run_bench(["dsc"], ["bench_mild"], 2, seed, 20)[0].metrics["cost"]))
        for seed in (VALIDATION_SEED, EVALUATION_SEED)
    )
    assert validation != test
    assert _curves(tmp_path / "c")["vessel_steps"][0]["base_cost"] == validation
    record = json.loads((Path(folders[0]) / "run.json").read_text())
    del record["evaluation"]["seed"]  # a run recorded before the validation seeds
    (Path(folders[0]) / "run.json").write_text(json.dumps(record))
    for lines in ([], ["--base-policy", "dsc"]):  # one IQM over two seed sets: refused
        with pytest.raises(SystemExit):
            curves_main([*folders, "--out", str(tmp_path / "d"), *lines])
        assert "evaluated on different seeds (first seeds [9000, 10000]" in capsys.readouterr().err


def test_several_lines_to_beat_each_have_their_cost_and_time(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    evaluation = {"split": "test", "scenarios": ["bench_mild"], "num_seeds": 2, "max_steps": 20}
    folders = _write_runs(tmp_path / "runs", base="none", evaluation=evaluation)
    argv = [*folders, "--out", str(tmp_path / "c"), "--base-policy", "dsc", "nn_dsc"]
    assert curves_main(argv) == 0
    cells = run_bench(["dsc", "nn_dsc"], ["bench_mild"], num_seeds=2, max_steps=20, split="test")
    dsc, nn_dsc = (float(np.mean(cell.metrics["cost"])) for cell in cells)
    row = _curves(tmp_path / "c")["vessel_steps"][0]
    assert (row["base_cost"], row["nn_dsc_cost"]) == (dsc, nn_dsc)
    printed = capsys.readouterr().out
    assert f"cost of dsc {dsc:.6g}, nn_dsc {nn_dsc:.6g}" in printed
    assert "IQM below dsc" in printed and "IQM below nn_dsc" in printed


def test_a_run_without_evaluations_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit):
        curves_main([str(tmp_path / "empty"), "--out", str(tmp_path / "c")])
    assert "--eval-every" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


def test_one_run_prints_its_cost_without_an_interval(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (folder, *_) = _write_runs(tmp_path / "runs")
    assert curves_main([folder, "--out", str(tmp_path / "c")]) == 0
    printed = capsys.readouterr().out
    assert "interval below" not in printed and "95 % interval" not in printed
    assert "[5, 5]" not in printed and "IQM" not in printed
    assert "cost below base policy from 100 vessel-steps" in printed  # s0: 8 < 10
    assert "final cost 5 (one run: no interval; train several seeds for one)" in printed


def test_a_run_that_never_beats_the_base_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "worse"
    folder.mkdir()
    (folder / "evaluations.csv").write_text(
        "vessel_steps,wall_clock_seconds,evaluation_seconds,mean_cost,cost_bench_mild\n"
        "0,1.0,0.1,10.0,10.0\n100,2.5,0.1,12.0,12.0\n"
    )
    (folder / "run.json").write_text(json.dumps({"config": {"base": "nn_dsc"}}))
    assert curves_main([str(folder), "--out", str(tmp_path / "c")]) == 0
    printed = capsys.readouterr().out
    assert "never within the runs' evaluations (to 100 vessel-steps)" in printed
    assert "never within the runs' evaluations (to 2.5 s)" in printed


def test_cpf_curves_reads_cpf_distill_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # Evaluation episodes of 20 steps (cpf-distill evaluates whole episodes), to keep it fast.
    monkeypatch.setattr(
        distill_command, "ValidationEvaluator", functools.partial(ValidationEvaluator, max_steps=20)
    )
    config = tmp_path / "student.toml"
    config.write_text(STUDENT_TOML)
    logs = []
    for seed in (0, 1):
        out, log = tmp_path / f"agent_s{seed}", tmp_path / f"run_s{seed}"
        argv = ["--config", str(config), "--seed", str(seed), "--out", str(out), "--log", str(log)]
        assert distill_main([*argv, "--eval-num-seeds", "1"]) == 0
        logs.append(str(log))
    record = json.loads((tmp_path / "run_s0" / "run.json").read_text())
    assert record["evaluation"] == {
        "split": "validation", "seed": VALIDATION_SEED, "scenarios": ["bench_mild"],
        "num_seeds": 1, "max_steps": 20
    }  # fmt: skip
    rows = list(csv.DictReader((tmp_path / "run_s0" / "evaluations.csv").open()))
    assert list(rows[0]) == ["vessel_steps", "wall_clock_seconds", "evaluation_seconds",
                             "mean_cost", "cost_bench_mild"]  # cpf-train's  # fmt: skip
    assert [int(r["vessel_steps"]) for r in rows] == [0, 100, 200]  # labelled vessel-steps
    capsys.readouterr()
    assert curves_main([*logs, "--out", str(tmp_path / "c")]) == 0  # the base: row 0
    assert "2 runs; cost of base policy" in capsys.readouterr().out
    assert curves_main([*logs, "--out", str(tmp_path / "d"), "--base-policy", "nn_dsc"]) == 0
    by_row, by_name = _curves(tmp_path / "c"), _curves(tmp_path / "d")
    assert [r["x"] for r in by_row["vessel_steps"]] == [0, 100, 200]
    # Row 0 of a student is exactly its base, nn_dsc, benched on the runs' settings.
    assert by_row["vessel_steps"][0]["base_cost"] == by_name["vessel_steps"][0]["base_cost"]
    assert by_name["vessel_steps"][0]["base_cost"] == float(rows[0]["mean_cost"])


def test_a_run_level_with_its_base_at_rounding_does_not_beat_it() -> None:
    """Three runs that all start as the base: their IQM is the base's cost to the last bits."""
    from cpf_bench.stats import iqm
    from cpf_commands.curves import Curve, first_below

    base = 118.2803639841704
    values = np.array([[base] * 3, [base - 20.0] * 3])
    mean = iqm(values, axis=1)
    curve = Curve("vessel_steps", np.array([0.0, 1000.0]), values, mean, mean, mean)
    assert first_below(curve, base) == (1000.0, 1000.0)
    slightly = Curve(
        "vessel_steps", np.array([0.0]), values[:1], mean[:1] - 1e-12, mean[:1], mean[:1]
    )
    assert first_below(slightly, base) == (None, None)
