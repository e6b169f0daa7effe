"""DAgger of a local residual student from a privileged teacher."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from safetensors.torch import load_file

from agents import load_policy
from agents.distill import DistillConfig, _labels, distill
from agents.train_config import TrainConfig
from agents.vec_env import FleetVecEnv
from baselines import make_policy

TINY = DistillConfig(rounds=2, steps=30, epochs=3, batch_size=256)


def _config(**changes: object) -> TrainConfig:
    fields: dict[str, object] = {"scenario": "bench_current_waves", "fleets": 2, "net_arch": (32,)}
    fields.update(changes)
    return TrainConfig(**fields)  # type: ignore[arg-type]


def test_an_unclipped_label_reproduces_the_teachers_force() -> None:
    env = FleetVecEnv("bench_current_waves", num_fleets=2)
    env.seed(4)
    env.reset()
    for _ in range(5):
        env.step(np.zeros((env.num_envs, 3), dtype=np.float32))
    teacher = make_policy("nn_dsc_privileged", env.sim)
    twin = make_policy("nn_dsc_privileged", env.sim)  # the same teacher, acting once more
    label = _labels(env, teacher)
    command = env.controller.compose(np.clip(label, -1.0, 1.0))[..., :3]
    wanted = np.asarray(twin.act_batch(env.sim.arrays.obs))[..., :3]
    inside = np.abs(label) <= 1.0
    assert inside.any()
    np.testing.assert_allclose(command[inside], wanted[inside], rtol=1e-12, atol=1e-9)
    assert not np.allclose(label, 0.0)  # the teacher does correct the base here


def test_distill_writes_a_loadable_deterministic_student(tmp_path: Path) -> None:
    report = distill(_config(), TINY, tmp_path / "a")
    again = distill(_config(), TINY, tmp_path / "b")
    assert again.losses == report.losses and report.samples == 2 * 30 * 2 * 5
    assert len(report.losses) == 2 and all(np.isfinite(report.losses))
    assert report.losses[-1] < report.zero_loss  # it learned some of the teacher's correction
    first = load_file(str(tmp_path / "a" / "policy.safetensors"))
    second = load_file(str(tmp_path / "b" / "policy.safetensors"))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    policy = load_policy(tmp_path / "a")
    env = FleetVecEnv("bench_current_waves", num_fleets=1)
    obs = env.sim.reset(seeds=[1])
    action = np.asarray(policy.act_batch(obs))
    assert action.shape == (1, 5, 5) and np.all(np.isfinite(action))


def test_distill_refuses_what_it_cannot_do(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="held-out shift split"):
        distill(_config(scenario="bench_current_waves_shift"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="evaluation seeds"):
        distill(_config(seed=10_000), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="algo='sac'"):
        distill(_config(algo="sac"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="privileged reference"):
        DistillConfig(teacher="nn_dsc")
    assert not (tmp_path / "x").exists()
