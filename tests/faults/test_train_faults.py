"""cpf-train's run folder: the final save and --force under kills; a link as the output."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from fault_injection import killed_at

from agents import TrainConfig, train
from agents.folder.format import AgentFolderError, read_agent
from agents.training.run_folder import TrainingRun
from agents.training.schedule import RunSchedule

AGENT = ("policy.safetensors", "normalization.json", "config.json", "manifest.json")
#: 2 fleets x 5 vessels x 16 steps = 160 vessel-steps per PPO rollout; two of them.
CONFIG = TrainConfig(algo="ppo", scenario="bench_mild", timesteps=320, seed=3, fleets=2,
                     n_steps=16, batch_size=80, n_epochs=1, net_arch=(16, 16))  # fmt: skip
SCHEDULE = RunSchedule(checkpoint_every=160)


def _agent_state(folder: Path) -> str:
    """ "none" (no agent file), or the verified agent's vessel-steps; fails on a half agent."""
    if not any((folder / name).exists() for name in AGENT):
        return "none"
    try:
        record, _, _ = read_agent(folder)
    except AgentFolderError as error:
        pytest.fail(f"a half-written agent: {error}")
    return str(record["timesteps_done"])


def _leftovers(parent: Path, name: str) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith(f".{name}.") and
                  not p.name.endswith(".lock"))  # fmt: skip


def test_a_save_killed_at_any_stage_leaves_no_half_agent_and_resume_writes_it(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The probe's case: killed while saving, the folder never fails its manifest check,
    and --resume (whose checkpoint has the whole budget) writes the agent."""
    torch.set_num_threads(1)
    folder = tmp_path / "run"
    runs: list[TrainingRun] = []
    finish = TrainingRun._finish
    monkeypatch.setattr(TrainingRun, "_finish", lambda run, interrupted: runs.append(run))
    train(CONFIG, folder, progress=False, schedule=SCHEDULE)  # everything but the save
    monkeypatch.setattr(TrainingRun, "_finish", finish)
    assert _agent_state(folder) == "none"
    pristine = tmp_path / "pristine"
    shutil.copytree(folder, pristine)
    stages, between = 0, []
    for stage in range(1, 80):
        killed = killed_at(stage, lambda: finish(runs[0], False))
        if not folder.exists():  # killed between the two renames: the old folder is kept
            between.append(stage)
            (old,) = (p for p in tmp_path.iterdir() if p.name.startswith(".run.old-"))
            assert _agent_state(old) == "none"
        else:
            assert _agent_state(folder) in ("none", "320"), stage
        if not killed:
            assert _agent_state(folder) == "320"
            break
        stages += 1
        if stage in (1, *between[:1]) or stage == 12:  # rerun: --resume repairs it
            train(CONFIG, folder, progress=False, schedule=SCHEDULE, resume=True)
            assert _agent_state(folder) == "320" and _leftovers(tmp_path, "run") == []
            with pytest.raises(ValueError, match="give a larger -n"):  # and now it is whole
                train(CONFIG, folder, progress=False, schedule=SCHEDULE, resume=True)
        shutil.rmtree(folder, ignore_errors=True)
        for leftover in _leftovers(tmp_path, "run"):
            shutil.rmtree(tmp_path / leftover)
        shutil.copytree(pristine, folder)
    assert stages >= 15 and len(between) == 1


_FORCED = """
import sys
from agents import TrainConfig, train
config = TrainConfig(algo="ppo", scenario="bench_mild", timesteps=10**7, seed=4, fleets=2,
                     n_steps=16, batch_size=80, n_epochs=1, net_arch=(16, 16))
train(config, sys.argv[1], progress=False, overwrite=True)
"""


def test_force_keeps_the_old_agent_until_the_new_one_is_written(tmp_path: Path) -> None:
    """The probe's case: cpf-train --force killed (a real SIGKILL) while training."""
    folder = tmp_path / "run"
    train(CONFIG, folder, progress=False)
    before = {name: (folder / name).read_bytes() for name in AGENT}
    start = time.time()
    forced = subprocess.Popen([sys.executable, "-c", _FORCED, str(folder)])
    try:
        deadline = time.monotonic() + 120
        while not any(p.stat().st_mtime > start for p in tmp_path.rglob("progress.csv")):
            assert forced.poll() is None and time.monotonic() < deadline
            time.sleep(0.1)
        time.sleep(1.0)  # the new run trains
    finally:
        forced.kill()
        forced.wait()
    assert {name: (folder / name).read_bytes() for name in AGENT} == before
    assert _agent_state(folder) == "320"
    replaced = TrainConfig(**{**CONFIG.to_json(), "seed": 5})  # type: ignore[arg-type]
    train(replaced, folder, progress=False, overwrite=True)  # the staging folder goes too
    assert json.loads((folder / "config.json").read_text())["config"]["seed"] == 5
    assert _leftovers(tmp_path, "run") == []


def test_an_output_that_is_a_link_is_refused(tmp_path: Path) -> None:
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    with pytest.raises(ValueError, match="is a symbolic link"):
        train(CONFIG, tmp_path / "link", progress=False)
    assert list((tmp_path / "real").iterdir()) == []


def test_too_little_space_is_refused_before_training(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cpf_env.infra import atomic

    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda path: type("U", (), {"free": 2**20}))
    learned: list[object] = []
    monkeypatch.setattr(TrainingRun, "learn", lambda *a: learned.append(a))
    with pytest.raises(ValueError, match="MiB free but the outputs need about"):
        train(CONFIG, tmp_path / "run", progress=False)
    assert learned == []
    assert sorted(p.name for p in tmp_path.iterdir()) == [".run.lock"]  # nothing else left


def test_an_aborted_force_says_the_old_run_stays(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from cpf_commands.train import train_main

    def second_ctrl_c(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr("agents.training.trainer.train", second_ctrl_c)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text("{}")
    assert train_main(["--out", str(tmp_path / "run"), "--force", "--quiet"]) == 130
    assert "it holds the earlier run as it was" in capsys.readouterr().err
