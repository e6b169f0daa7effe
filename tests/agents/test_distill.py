"""DAgger of a local residual student from a teacher policy, and ``cpf-distill``."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from agents import load_policy
from agents.distill import DistillConfig, FleetwiseBase, _labels, distill, student_actor
from agents.train_config import TrainConfig
from agents.vec_env import FleetVecEnv
from baselines import make_policy
from cpf_commands.distill import distill_main
from cpf_env import scenarios
from cpf_env.envs.residual import ResidualConfig
from cpf_env.scenarios.sampler import ScenarioDistribution

TINY = DistillConfig(rounds=2, steps=30, epochs=3, batch_size=256)


def _config(**changes: object) -> TrainConfig:
    fields: dict[str, object] = {"scenario": "bench_current_waves", "fleets": 2, "net_arch": (32,)}
    fields.update(changes)
    return TrainConfig(**fields)  # type: ignore[arg-type]


def _env_after(steps: int, residual: ResidualConfig, base: str = "nn_dsc") -> FleetVecEnv:
    env = FleetVecEnv("bench_current_waves", num_fleets=2, base_policy=base, residual=residual)
    env.seed(4)
    env.reset()
    for _ in range(steps):
        env.step(np.zeros((env.num_envs, residual.action_size), dtype=np.float32))
    return env


def test_teacher_names_are_checked() -> None:
    for name in ("mpc", "oracle", "nn_dsc_privileged", "nn_dsc"):
        assert DistillConfig(teacher=name).teacher == name
    with pytest.raises(ValueError, match=r"baselines.POLICIES or baselines.PRIVILEGED.*'mpc'"):
        DistillConfig(teacher="mpc_oracle")
    with pytest.raises(ValueError, match="procedural must be an integer >= 0"):
        DistillConfig(procedural=-1)


@pytest.mark.parametrize("teacher", ["nn_dsc_privileged", "mpc", "oracle"])
def test_an_unclipped_force_and_rate_label_reproduces_the_teachers_command(teacher: str) -> None:
    residual = ResidualConfig(mode="force_and_rate", scale=1.0)
    env = _env_after(5, residual)
    policy = make_policy(teacher, env.sim)
    twin = make_policy(teacher, env.sim)  # the same teacher, acting once more
    label = _labels(env, policy)
    assert label.shape == (2, 5, 4)
    # a student that outputs the label: the env composes the teacher's command
    command = env.controller.compose(np.clip(label, -1.0, 1.0))[..., :4]
    wanted = np.asarray(twin.act_batch(env.sim.arrays.obs))[..., :4]
    inside = np.abs(label) <= 1.0
    assert inside[..., :3].any() and inside[..., 3].any()
    np.testing.assert_allclose(command[inside], wanted[inside], rtol=1e-12, atol=1e-9)
    assert not np.allclose(label[..., 3], 0.0)  # the teacher sets its own path-variable rate


def test_force_labels_leave_the_rate_to_the_base() -> None:
    env = _env_after(5, ResidualConfig(mode="force", scale=1.0))
    label = _labels(env, make_policy("mpc", env.sim))
    assert label.shape == (2, 5, 3)


def test_fleetwise_base_acts_as_the_batched_policy() -> None:
    scenario = scenarios.get("bench_current_waves")
    env = _env_after(3, ResidualConfig())
    obs = env.sim.arrays.obs
    batched, fleetwise = make_policy("mpc", scenario), FleetwiseBase("mpc", scenario, 2)
    for _ in range(2):
        np.testing.assert_array_equal(fleetwise.act_batch(obs), batched.act_batch(obs))
    fleetwise.reset_fleets(np.array([False, True]))
    alone = fleetwise.act_batch(obs[1:], fleets=np.array([1]))
    np.testing.assert_array_equal(alone, make_policy("mpc", scenario).act_batch(obs[1:]))


def test_the_student_starts_as_the_base() -> None:
    network = student_actor(_config(), 26, 4)
    assert not network(torch.ones(3, 26)).any()


def test_distill_writes_a_loadable_deterministic_student(tmp_path: Path) -> None:
    report = distill(_config(), TINY, tmp_path / "a")
    again = distill(_config(), TINY, tmp_path / "b")
    assert again.losses == report.losses and report.samples == 2 * 30 * 2 * 5
    assert len(report.losses) == 2 and all(np.isfinite(report.losses))
    assert report.losses[-1] < report.zero_loss  # it learned some of the teacher's correction
    first = load_file(str(tmp_path / "a" / "policy.safetensors"))
    second = load_file(str(tmp_path / "b" / "policy.safetensors"))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    other = distill(_config(seed=1), TINY, tmp_path / "c")
    assert other.losses != report.losses
    policy = load_policy(tmp_path / "a")
    env = FleetVecEnv("bench_current_waves", num_fleets=1)
    obs = env.sim.reset(seeds=[1])
    action = np.asarray(policy.act_batch(obs))
    assert action.shape == (1, 5, 5) and np.all(np.isfinite(action))


def test_a_mixture_student_on_an_mpc_base_with_rate_labels(tmp_path: Path) -> None:
    config = _config(
        scenario=("bench_mild", "bench_large_fleet"),
        base="mpc",
        mode="force_and_rate",
        scale=1.0,
        fleets=3,
    )
    settings = DistillConfig(teacher="oracle", rounds=2, steps=8, epochs=2, procedural=1)
    report = distill(config, settings, tmp_path / "s")
    again = distill(config, settings, tmp_path / "t")
    draw = ScenarioDistribution(max_degree=2).sample(0)  # K = 2, the ring's degree
    assert report.samples == 2 * 8 * (5 + 10 + draw.n)
    first = load_file(str(tmp_path / "s" / "policy.safetensors"))
    second = load_file(str(tmp_path / "t" / "policy.safetensors"))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    assert again.losses == report.losses
    assert first["output.weight"].shape[0] == 4
    record = json.loads((tmp_path / "s" / "config.json").read_text())
    assert record["distillation"]["teacher"] == "oracle"
    assert record["distillation"]["procedural"] == 1
    policy = load_policy(tmp_path / "s", scenario="bench_mild")
    obs = FleetVecEnv("bench_mild", num_fleets=1).sim.reset(seeds=[3])
    assert np.all(np.isfinite(policy.act_batch(obs)))


def test_distill_refuses_what_it_cannot_do(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="held-out shift split"):
        distill(_config(scenario="bench_current_waves_shift"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="held-out shift split"):
        distill(_config(scenario=("bench_mild", "bench_mild_shift")), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="evaluation seeds"):
        distill(_config(seed=10_000), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="evaluation seeds"):
        distill(
            _config(scenario=("bench_mild", "bench_switching"), seed=9_999), TINY, tmp_path / "x"
        )
    with pytest.raises(ValueError, match="algo='sac'"):
        distill(_config(algo="sac"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="mode='kinematic'"):
        distill(_config(mode="kinematic"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match=r"encoder and history \(got encoder=None, history=2"):
        distill(_config(history=2), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="got encoder='deepsets'"):
        distill(_config(encoder="deepsets", shared_slot_statistics=True), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="at least one fleet each; got fleets=2"):
        distill(
            _config(scenario=("bench_mild", "bench_switching")),
            DistillConfig(procedural=1),
            tmp_path / "x",
        )
    assert not (tmp_path / "x").exists()


STUDENT_TOML = """
scenario = "bench_mild"
fleets = 2
net_arch = [16]
mode = "force_and_rate"
scale = 1.0

[distill]
teacher = "nn_dsc_privileged"
rounds = 2
steps = 10
epochs = 2
"""


def test_cpf_distill_writes_the_agent_and_its_run_files(tmp_path: Path) -> None:
    path = tmp_path / "student.toml"
    path.write_text(STUDENT_TOML)
    out, log = tmp_path / "agent", tmp_path / "log"
    assert (
        distill_main(["--config", str(path), "--seed", "3", "--out", str(out), "--log", str(log)])
        == 0
    )
    run = json.loads((log / "run.json").read_text())
    assert run["config"]["seed"] == 3 and run["distill"]["teacher"] == "nn_dsc_privileged"
    rows = list(csv.DictReader((log / "rounds.csv").open()))
    assert [int(r["round"]) for r in rows] == [0, 1] and int(rows[1]["samples"]) == 200
    assert load_policy(out).config.mode == "force_and_rate"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('scenario = "bench_mild"\n', "needs a [distill] table"),
        (STUDENT_TOML + "cheat = 1\n", "[distill] has unknown keys ['cheat']"),
        ("gamma2 = 1\n" + STUDENT_TOML, "unknown keys ['gamma2']"),
        ("seed = 4\n" + STUDENT_TOML, "give it on the command line (--seed)"),
        (STUDENT_TOML.replace("bench_mild", "bench_mild_shift"), "held-out shift split"),
        (STUDENT_TOML.replace('"nn_dsc_privileged"', '"genius"'), "teacher must be a policy"),
        (STUDENT_TOML.replace("rounds = 2", "rounds = 0"), "rounds must be an integer >= 1"),
        ("scenario = [\n", "is not valid TOML"),
    ],
)
def test_cpf_distill_refuses_bad_configs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SystemExit):
        distill_main(["--config", str(path), "--seed", "0", "--out", str(tmp_path / "o")])
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_cpf_distill_refuses_an_existing_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "student.toml"
    path.write_text(STUDENT_TOML)
    (tmp_path / "o").mkdir()
    with pytest.raises(SystemExit):
        distill_main(["--config", str(path), "--seed", "0", "--out", str(tmp_path / "o")])
    assert "exists; pass --force" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        distill_main(["--config", str(path), "--seed", "10000", "--out", str(tmp_path / "p")])
    assert "evaluation seeds" in capsys.readouterr().err
