"""Held-out evaluation during training, the best model, the progress bar and cpf-train's flags."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from agents import TrainConfig, load_policy, train
from agents.training.evaluation import ValidationEvaluator
from agents.training.schedule import RunSchedule
from cpf_commands.bench.cli import bench_main
from cpf_commands.train import train_main
from cpf_env.scenarios.splits import VALIDATION_SEED

TINY = {"fleets": 2, "n_steps": 16, "batch_size": 80, "n_epochs": 1, "net_arch": (16, 16)}
#: cpf-train flags of a tiny run (160 vessel-steps per rollout).
ARGV = ["--scenarios", "bench_mild", "--fleets", "2", "--eval-num-seeds", "2",
        "--set", "n_steps=16", "batch_size=80", "n_epochs=1"]  # fmt: skip


def _rows(folder: Path) -> list[dict[str, str]]:
    return list(csv.DictReader((folder / "evaluations.csv").open()))


def test_evaluations_are_the_numbers_cpf_bench_prints_and_best_is_the_lowest(
    tmp_path: Path,
) -> None:
    config = TrainConfig(scenario="bench_mild", timesteps=480, seed=2, learning_rate=0.05,
                         **TINY)  # type: ignore[arg-type]  # fmt: skip
    evaluate = ValidationEvaluator(["bench_mild"], num_seeds=2, max_steps=30)
    folder = train(config, tmp_path / "run", False, evaluate=evaluate,
                   schedule=RunSchedule(eval_every=160))  # fmt: skip
    rows = _rows(folder)
    assert [int(r["vessel_steps"]) for r in rows] == [0, 160, 320, 480]
    assert list(rows[0]) == ["vessel_steps", "wall_clock_seconds", "evaluation_seconds",
                             "mean_cost", "cost_bench_mild"]  # fmt: skip
    costs = [float(r["mean_cost"]) for r in rows]
    assert len(set(costs)) == len(costs)  # the agent changed between evaluations
    seconds = [float(r["wall_clock_seconds"]) for r in rows]
    assert seconds == sorted(seconds) and all(float(r["evaluation_seconds"]) > 0 for r in rows)
    load_policy(folder / "best")  # a complete agent folder
    argv = ["--policies", str(folder / "best"), "--scenarios", "bench_mild", "--split", "test",
            "--num-seeds", "2", "--max-steps", "30", "--quiet", "--no-figures"]  # fmt: skip

    def bench_cost(*extra: str) -> float:
        out = tmp_path / f"bench{len(extra)}"
        assert bench_main([*argv, "--out", str(out), *extra]) == 0
        summary = list(csv.DictReader((out / "summary.csv").open()))
        return next(float(r["mean"]) for r in summary if r["metric"] == "cost")

    # the same number, bit for bit, on the validation seeds, and best/ holds the best
    assert bench_cost("--seed", str(VALIDATION_SEED)) == min(costs)
    assert bench_cost() != min(costs)  # the test seeds played no part
    best_record = json.loads((folder / "best" / "config.json").read_text())
    assert best_record["timesteps_done"] == int(rows[int(np.argmin(costs))]["vessel_steps"])


def test_evaluation_needs_a_positive_number_of_seeds() -> None:
    with pytest.raises(ValueError, match="seeds must be an integer >= 1"):
        ValidationEvaluator(["bench_mild"], num_seeds=0)
    with pytest.raises(ValueError, match="more than the 1000 validation seeds"):
        ValidationEvaluator(["bench_mild"], num_seeds=1001)
    with pytest.raises(ValueError, match="every must be an integer >= 0"):
        RunSchedule(eval_every=-1)


def test_cpf_train_prints_the_rounding_and_the_bar_shows_the_evaluation_cost(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert train_main([*ARGV, "-n", "10", "--eval-every", "160", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert "budget of 10 vessel-steps is rounded up to 160" in captured.out
    assert "n_steps x num_envs = 16 x 10 = 160" in captured.out
    assert "-n 10 rounded up to whole rollouts" in captured.out
    assert "eval_cost=" in captured.err and "eval_s=" in captured.err
    assert "episodic_cost" not in captured.err
    assert (out / "best" / "manifest.json").is_file() and len(_rows(out)) == 2
    run = json.loads((out / "run.json").read_text())
    assert run["evaluation"] == {"split": "validation", "seed": VALIDATION_SEED,
                                 "scenarios": ["bench_mild"], "num_seeds": 2,
                                 "max_steps": None}  # fmt: skip
    assert run["device"] == "cpu"  # the default, recorded beside the configuration


def test_cpf_train_tensorboard_log_and_resume_flags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, board = tmp_path / "run", tmp_path / "tb"
    argv = [*ARGV, "-n", "160", "--eval-every", "0", "--out", str(out), "--quiet"]
    assert train_main([*argv, "--tensorboard-log", str(board)]) == 0
    assert list((board / "run").glob("events.out.tfevents.*"))
    assert not (out / "evaluations.csv").exists()
    capsys.readouterr()
    with pytest.raises(SystemExit):
        train_main(["--resume", "--out", str(out), "--fleets", "3"])
    assert "drop --fleets" in capsys.readouterr().err
    assert (
        train_main(["--resume", "--out", str(out), "-n", "320", "--quiet", "--device", "auto"]) == 0
    )
    assert "for 320 vessel-steps" in capsys.readouterr().out
    assert json.loads((out / "run.json").read_text())["config"]["timesteps"] == 320


def test_cpf_train_help_lists_the_new_options(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        train_main(["--help"])
    text = capsys.readouterr().out
    for flag in ("--eval-every", "--eval-num-seeds", "--set", "--resume", "--tensorboard-log",
                 "--device"):  # fmt: skip
        assert flag in text


def test_the_bar_ends_on_the_final_evaluation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert train_main([*ARGV, "-n", "10", "--eval-every", "100000", "--out", str(out)]) == 0
    first, final = _rows(out)  # at 0 vessel-steps and at the end of training
    assert int(final["vessel_steps"]) == 160 and final["mean_cost"] != first["mean_cost"]
    assert f"eval_cost={float(final['mean_cost']):.4g}" in capsys.readouterr().err
