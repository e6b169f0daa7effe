"""Checkpoints, --resume and Ctrl-C: a resumed run ends with the files of an uninterrupted one."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.callbacks import BaseCallback

from agents import TrainConfig, load_policy, train
from agents.training.evaluation import ValidationEvaluator
from agents.training.schedule import RunSchedule, TrainingInterrupted
from cpf_env.scenarios.splits import VALIDATION_SEED

#: 2 fleets x 5 vessels x 16 steps = 160 vessel-steps per PPO rollout.
TINY = {"fleets": 2, "n_steps": 16, "batch_size": 80, "n_epochs": 1, "net_arch": (16, 16)}
SCHEDULE = RunSchedule(eval_every=160, checkpoint_every=320)
#: Columns that hold wall-clock times (they cannot repeat).
CLOCK = ("time/", "wall_clock_seconds", "evaluation_seconds")


def _config(algo: str) -> TrainConfig:
    extra = {"buffer_size": 2_000, "batch_size": 32} if algo == "sac" else {}
    return TrainConfig(
        algo=algo,
        scenario="bench_mild",
        timesteps=640,
        seed=3,
        **{**TINY, **extra},  # type: ignore[arg-type]
    )


def _evaluator() -> ValidationEvaluator:
    return ValidationEvaluator(["bench_mild"], num_seeds=2, max_steps=20)


class _KillAt(BaseCallback):
    """Raises (a killed process) once training passes ``steps`` vessel-steps."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        if self.model.num_timesteps >= self.steps:
            raise RuntimeError("killed")
        return True


class _CtrlCAt(_KillAt):
    """Sends this process SIGINT (Ctrl-C) once, after ``steps`` vessel-steps."""

    def _on_step(self) -> bool:
        if self.model.num_timesteps >= self.steps and self.steps >= 0:
            self.steps = -1
            os.kill(os.getpid(), signal.SIGINT)
        return True


def _rows(text: str) -> list[dict[str, str]]:
    """CSV rows without the wall-clock columns."""
    rows = list(csv.DictReader(io.StringIO(text)))
    return [{k: v for k, v in row.items() if not k.startswith(CLOCK)} for row in rows]


def _assert_same_run(a: Path, b: Path) -> None:
    for name in ("policy.safetensors", "normalization.json", "manifest.json"):
        if name == "manifest.json":
            continue  # it hashes config.json, whose training time differs
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    for name in ("policy.safetensors", "normalization.json"):
        assert (a / "best" / name).read_bytes() == (b / "best" / name).read_bytes(), name
    assert _rows((a / "evaluations.csv").read_text()) == _rows((b / "evaluations.csv").read_text())
    assert _rows((a / "progress.csv").read_text()) == _rows((b / "progress.csv").read_text())
    record_a, record_b = (json.loads((f / "config.json").read_text()) for f in (a, b))
    for record in (record_a, record_b):
        for field in ("train_seconds", "vessel_steps_per_second", "evaluation_seconds",
                      "wall_clock_seconds"):  # fmt: skip
            del record[field]
    assert record_a == record_b


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_a_killed_run_resumes_to_the_same_files(tmp_path: Path, algo: str) -> None:
    config = _config(algo)
    whole = train(config, tmp_path / "whole", False, evaluate=_evaluator(), schedule=SCHEDULE)
    parts = tmp_path / "parts"
    with pytest.raises(RuntimeError, match="killed"):  # after the checkpoint at 320
        train(config, parts, False, callbacks=[_KillAt(490)], evaluate=_evaluator(),
              schedule=SCHEDULE)  # fmt: skip
    assert (parts / "checkpoint" / "state.json").is_file()
    assert not (parts / "manifest.json").exists()  # no agent yet: it was killed
    assert len(_rows((parts / "evaluations.csv").read_text())) > 3  # evaluated past 320
    # killed between the two renames of a checkpoint swap, and while evaluating
    (parts / "checkpoint").rename(parts / ".checkpoint.old-x1")
    (parts / ".checkpoint.new-x2").mkdir()
    (parts / ".evaluating-x3").mkdir()
    train(config, parts, False, evaluate=_evaluator(), schedule=SCHEDULE, resume=True)
    assert not list(parts.glob(".*"))  # put back and tidied
    _assert_same_run(whole, parts)
    evaluated = [int(r["vessel_steps"]) for r in _rows((parts / "evaluations.csv").read_text())]
    assert evaluated == [0, 160, 320, 480, 640]


def test_ctrl_c_saves_a_complete_agent_and_resumes_exactly(tmp_path: Path) -> None:
    config = _config("ppo")
    whole = train(config, tmp_path / "whole", False, evaluate=_evaluator(), schedule=SCHEDULE)
    parts = tmp_path / "parts"
    previous = signal.getsignal(signal.SIGINT)  # SIG_IGN when pytest runs as a background job
    with pytest.raises(TrainingInterrupted) as stop:
        train(config, parts, False, callbacks=[_CtrlCAt(170)], evaluate=_evaluator(),
              schedule=SCHEDULE)  # fmt: skip
    assert stop.value.timesteps == 320  # the update in progress finished first
    assert signal.getsignal(signal.SIGINT) is previous  # handler restored
    record = json.loads((parts / "config.json").read_text())
    assert record["interrupted"] is True and record["timesteps_done"] == 320
    policy = load_policy(parts)  # a complete, verified agent folder
    assert np.all(np.isfinite(policy.act_batch(np.zeros((1, 5, policy.obs_dim)))))
    train(config, parts, False, evaluate=_evaluator(), schedule=SCHEDULE, resume=True)
    assert "interrupted" not in json.loads((parts / "config.json").read_text())
    _assert_same_run(whole, parts)


def test_resume_refuses_what_it_cannot_continue(tmp_path: Path) -> None:
    config = _config("ppo")
    with pytest.raises(ValueError, match="nothing to resume"):
        train(config, tmp_path / "none", False, resume=True)
    folder = train(config, tmp_path / "run", False, schedule=RunSchedule(checkpoint_every=0))
    with pytest.raises(ValueError, match="no checkpoint"):
        train(config, folder, False, resume=True)
    with pytest.raises(ValueError, match=r"differ from it: \['seed'\]"):
        train(TrainConfig(**{**config.to_json(), "seed": 4}), folder, False, resume=True)
    shutil.rmtree(folder)
    folder = train(config, folder, False, schedule=SCHEDULE)
    before = {path.name: path.read_bytes() for path in folder.iterdir() if path.is_file()}
    for budget in (640, 100):  # reached already: refused, the folder untouched
        shorter = TrainConfig(**{**config.to_json(), "timesteps": budget})
        with pytest.raises(ValueError, match="has trained 640 vessel-steps already"):
            train(shorter, folder, False, schedule=SCHEDULE, resume=True)
    assert {path.name: path.read_bytes() for path in folder.iterdir() if path.is_file()} == before


def test_a_run_evaluated_on_the_test_seeds_is_not_resumed_on_the_validation_seeds(
    tmp_path: Path,
) -> None:
    """A run recorded before the validation seeds: resuming would mix seeds in best/."""
    config = _config("ppo")
    folder = train(config, tmp_path / "run", False, evaluate=_evaluator(), schedule=SCHEDULE)
    record = json.loads((folder / "run.json").read_text())
    assert record["evaluation"]["seed"] == VALIDATION_SEED
    del record["evaluation"]["seed"]  # as recorded before: the test seeds
    (folder / "run.json").write_text(json.dumps(record))
    longer = TrainConfig(**{**config.to_json(), "timesteps": 960})
    with pytest.raises(ValueError, match="seeds from 10000, and this run evaluates from 9000"):
        train(longer, folder, False, evaluate=_evaluator(), schedule=SCHEDULE, resume=True)
    train(longer, folder, False, schedule=SCHEDULE, resume=True)  # no evaluation: nothing mixed


def test_resume_extends_a_finished_run(tmp_path: Path) -> None:
    """A checkpoint is written at the end: a larger budget continues where it stopped."""
    config = _config("ppo")
    longer = TrainConfig(**{**config.to_json(), "timesteps": 960})
    whole = train(longer, tmp_path / "whole", False, schedule=SCHEDULE)
    folder = train(config, tmp_path / "run", False, schedule=SCHEDULE)
    assert (
        json.loads((folder / "checkpoint" / "state.json").read_text())["extra"]["last_checkpoint"]
        == 640
    )
    train(longer, folder, False, schedule=SCHEDULE, resume=True)
    assert (whole / "policy.safetensors").read_bytes() == (
        folder / "policy.safetensors"
    ).read_bytes()


def test_resume_is_exact_across_fleet_restarts(tmp_path: Path) -> None:
    """Fleet 1 of 2 restarts at step 600 (staggered) and 1800 of bench_saturation (1,200-step
    episodes); the checkpoint at step 1,024 lies between, so the resumed part restarts a fleet
    from its restored generator and continues the other fleet's episode."""
    config = TrainConfig(scenario="bench_saturation", timesteps=19_200, seed=5,
                         **{**TINY, "n_steps": 64, "batch_size": 640})  # type: ignore[arg-type]  # fmt: skip
    schedule = RunSchedule(checkpoint_every=10_240)
    whole = train(config, tmp_path / "whole", False, schedule=schedule)
    parts = tmp_path / "parts"
    with pytest.raises(RuntimeError, match="killed"):
        train(config, parts, False, callbacks=[_KillAt(12_000)], schedule=schedule)
    train(config, parts, False, schedule=schedule, resume=True)
    assert (whole / "policy.safetensors").read_bytes() == (
        parts / "policy.safetensors"
    ).read_bytes()
    assert (whole / "normalization.json").read_bytes() == (
        parts / "normalization.json"
    ).read_bytes()
    rows = _rows((whole / "progress.csv").read_text())
    assert _rows((parts / "progress.csv").read_text()) == rows
    assert float(rows[-1]["rollout/ep_len_mean"]) > 0  # episodes did end during the run


class _CtrlCBeforeTraining(BaseCallback):
    """Sends SIGINT before the first rollout: the checkpoint is taken at 0 vessel-steps."""

    def _on_training_start(self) -> None:
        os.kill(os.getpid(), signal.SIGINT)

    def _on_step(self) -> bool:
        return True


def test_a_run_stopped_before_its_first_update_resumes_exactly(tmp_path: Path) -> None:
    config = _config("ppo")
    whole = train(config, tmp_path / "whole", False, evaluate=_evaluator(), schedule=SCHEDULE)
    parts = tmp_path / "parts"
    with pytest.raises(TrainingInterrupted) as stop:
        train(config, parts, False, callbacks=[_CtrlCBeforeTraining()], evaluate=_evaluator(),
              schedule=SCHEDULE)  # fmt: skip
    assert stop.value.timesteps == 0
    train(config, parts, False, evaluate=_evaluator(), schedule=SCHEDULE, resume=True)
    _assert_same_run(whole, parts)


@pytest.mark.slow
def test_cpf_train_stops_on_a_real_ctrl_c_with_status_130_and_resumes(tmp_path: Path) -> None:
    """The command in its own process, interrupted by SIGINT as a terminal would."""
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    argv = ["--scenarios", "bench_mild", "--fleets", "4", "-n", "400000", "--eval-every", "0",
            "--set", "n_steps=16", "batch_size=320", "n_epochs=1", "--out", str(out),
            "--quiet"]  # fmt: skip
    code = f"from cpf_commands.train import train_main; raise SystemExit(train_main({argv!r}))"
    process = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while (
        not (out / "progress.csv").is_file()
        or not (out / "progress.csv").read_text().count("\n") > 2
    ):
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "Ctrl-C: finishing this update" in stdout
    assert f"Continue with: cpf-train --resume --out {out}" in stderr
    done = json.loads((out / "config.json").read_text())["timesteps_done"]
    assert 0 < done < 400_000 and load_policy(out).n == 5
    from cpf_commands.train import train_main

    assert train_main(["--resume", "--out", str(out), "-n", str(done + 320), "--quiet"]) == 0
    assert json.loads((out / "config.json").read_text())["timesteps_done"] == done + 320


def test_a_killed_mixture_run_resumes_to_the_same_files(tmp_path: Path) -> None:
    """Two scenarios, balanced rewards: the groups and the reward scales are in the checkpoint."""
    config = TrainConfig(
        scenario=("bench_mild", "bench_large_fleet"),
        timesteps=960,
        seed=3,
        **{**TINY, "batch_size": 120},  # type: ignore[arg-type]
    )  # 2 fleets: 5 + 10 slots, 240 vessel-steps per rollout
    schedule = RunSchedule(eval_every=240, checkpoint_every=480)
    evaluate = ValidationEvaluator(config.scenarios, num_seeds=1, max_steps=20)
    whole = train(config, tmp_path / "whole", False, evaluate=evaluate, schedule=schedule)
    parts = tmp_path / "parts"
    with pytest.raises(RuntimeError, match="killed"):
        train(config, parts, False, callbacks=[_KillAt(700)], evaluate=evaluate,
              schedule=schedule)  # fmt: skip
    train(config, parts, False, evaluate=evaluate, schedule=schedule, resume=True)
    _assert_same_run(whole, parts)


def test_a_killed_encoder_run_with_history_resumes_to_the_same_files(tmp_path: Path) -> None:
    """The own histories (``HistoryVecEnv``) and the encoder's weights are in the checkpoint."""
    config = TrainConfig(
        scenario="bench_mild",
        timesteps=640,
        seed=3,
        encoder="deepsets",
        history=2,
        shared_slot_statistics=True,
        **TINY,  # type: ignore[arg-type]
    )
    whole = train(config, tmp_path / "whole", False, evaluate=_evaluator(), schedule=SCHEDULE)
    parts = tmp_path / "parts"
    with pytest.raises(RuntimeError, match="killed"):  # after the checkpoint at 320
        train(config, parts, False, callbacks=[_KillAt(490)], evaluate=_evaluator(),
              schedule=SCHEDULE)  # fmt: skip
    train(config, parts, False, evaluate=_evaluator(), schedule=SCHEDULE, resume=True)
    _assert_same_run(whole, parts)
