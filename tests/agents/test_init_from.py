"""``--init-from``: PPO started from a distilled student (actor, statistics), on base ``mpc``."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecNormalize

from agents import TrainConfig, load_policy, train
from agents.training.init_from import read_init_source
from agents.training.run_folder import TrainingRun
from agents.training.schedule import RunSchedule
from cpf_commands.train import train_main

STUDENTS = Path(__file__).parents[2] / "tests" / "fixtures" / "agents"
MLP = STUDENTS / "student_mpc_k6"
DEEPSETS = STUDENTS / "student_mpc_deepsets"
#: The students' recipe on one scenario; 1 fleet x 5 vessels x 8 steps a PPO rollout.
RECIPE = {"base_policy": "mpc", "net_arch": (64, 64)}
#: The students' residual.
RESIDUAL = {"scale": 0.5, "neighbour_slots": 6}
TINY = {"fleets": 1, "n_steps": 8, "batch_size": 40, "n_epochs": 1, "torch_threads": 1}


def _config(
    folder: Path, residual: dict[str, object] | None = None, **changes: object
) -> TrainConfig:
    own = json.loads((folder / "config.json").read_text())["config"]
    recipe = {k: own[k] for k in ("encoder", "history", "shared_slot_statistics") if k in own}
    fields = {"scenario": "bench_saturation", "timesteps": 80, **RECIPE, **recipe, **TINY}
    fields.update(changes)
    return TrainConfig(**fields, residual={**RESIDUAL, **(residual or {})})  # type: ignore[arg-type]


@pytest.mark.parametrize("folder", [MLP, DEEPSETS], ids=["mlp", "deepsets_history"])
def test_the_initial_policy_is_the_folders(tmp_path: Path, folder: Path) -> None:
    config = _config(folder)
    source = read_init_source(folder, config)
    run = TrainingRun(config, tmp_path, RunSchedule(), None, None, None, init_from=source)
    assert isinstance(run.env, VecNormalize)
    run.env.training = False  # the statistics as loaded (a training reset updates them)
    normalized = run.env.reset()
    raw = run.env.get_original_obs().astype(np.float32)
    ppo, _ = run.model.predict(normalized, deterministic=True)
    loaded = load_policy(folder, scenario="bench_saturation").actor(raw)
    np.testing.assert_array_equal(ppo, loaded)
    assert np.abs(loaded).max() > 0.01  # the student's residual, not the zero start
    std = run.model.policy.log_std.detach().numpy()  # type: ignore[operator]
    np.testing.assert_array_equal(std, np.full(3, config.log_std_init, dtype=np.float32))


def test_a_folder_of_another_recipe_is_refused_and_nothing_written(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with pytest.raises(
        ValueError, match=r"differ from the run's: residual.scale \(folder 0.5, run 0.2\)"
    ):
        train(_config(MLP, {"scale": 0.2}), out, False, init_from=MLP)
    assert not out.exists()
    with pytest.raises(ValueError, match=r"neighbour_slots \(folder 6, run 4\)"):
        train(_config(MLP, {"neighbour_slots": 4}), out, False, init_from=MLP)
    with pytest.raises(ValueError, match="algo"):
        train(_config(MLP, algo="sac"), out, False, init_from=MLP)
    with pytest.raises(ValueError, match="not an agent folder"):
        train(_config(MLP), out, False, init_from=tmp_path)
    assert not out.exists()


def test_cpf_train_init_from_on_mpc_records_the_folder_and_resumes_exactly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    common = ["--scenarios", "bench_saturation", "--base-policy", "mpc", "--fleets", "1"]
    common += ["--set", "residual.scale=0.5", "residual.neighbour_slots=6", "n_steps=8"]
    common += ["--set", "batch_size=40"]
    common += ["n_epochs=1", "checkpoint_every=40", "--eval-every", "0", "--quiet"]
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    start = ["--init-from", str(MLP)]
    assert train_main([*common, *start, "-n", "80", "--out", str(whole)]) == 0
    assert train_main([*common, *start, "-n", "40", "--out", str(parts)]) == 0
    assert train_main(["--resume", "--out", str(parts), "-n", "80", "--quiet"]) == 0
    capsys.readouterr()
    for name in ("policy.safetensors", "normalization.json"):
        assert (whole / name).read_bytes() == (parts / name).read_bytes(), name
    frozen = json.loads((MLP / "normalization.json").read_text())
    assert json.loads((whole / "normalization.json").read_text()) == frozen
    assert (whole / "policy.safetensors").read_bytes() != (MLP / "policy.safetensors").read_bytes()
    digest = hashlib.sha256((MLP / "manifest.json").read_bytes()).hexdigest()
    wanted = {"folder": str(MLP), "manifest_sha256": digest}
    for folder in (whole, parts):
        assert json.loads((folder / "run.json").read_text())["init_from"] == wanted
        record = json.loads((folder / "config.json").read_text())
        assert record["init_from"] == wanted
        assert record["config"]["log_std_init"] == -2.5
    with pytest.raises(SystemExit):
        train_main(["--resume", "--out", str(parts), "-n", "120", *start])
    assert "drop --init-from" in capsys.readouterr().err
