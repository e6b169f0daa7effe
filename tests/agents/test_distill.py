"""DAgger of a local residual student from a teacher policy, and ``cpf-distill``."""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import ROOT, STUDENT_TOML
from safetensors.torch import load_file

from agents import load_policy
from agents.distill.config import DistillConfig, check_distillation, draw_seeds
from agents.distill.dagger import (
    _applied_bounds,
    _group,
    _groups,
    _labels,
    _loss,
    _rollout,
    distill,
    student_actions,
    student_actor,
)
from agents.envs.vec_env import FleetVecEnv
from agents.folder.actor import build_actor
from agents.folder.format import read_agent
from agents.training.config import TrainConfig
from agents.training.evaluation import ValidationEvaluator
from baselines import make_policy
from cpf_commands.bench.run import run_bench
from cpf_commands.distill import distill_main, read_distill_config
from cpf_env import scenarios
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.residual import ResidualConfig
from cpf_env.scenarios.sampler import NOMINAL_TAU_MAX, ScenarioDistribution
from cpf_env.scenarios.splits import VALIDATION_SEED
from cpf_env.sim.fleet import observation_layout
from cpf_env.sim.observation import SLOTS

TINY = DistillConfig(rounds=2, steps=30, epochs=3, batch_size=256)


#: ``ResidualConfig`` fields, which ``_config`` passes on as the run's ``residual``.
RESIDUAL_FIELDS = {f.name for f in dataclasses.fields(ResidualConfig)}


def _config(**changes: object) -> TrainConfig:
    """A small ``TrainConfig``; ``ResidualConfig`` fields among ``changes`` make its residual."""
    residual = {key: changes.pop(key) for key in list(changes) if key in RESIDUAL_FIELDS}
    fields: dict[str, object] = {"scenario": "bench_current_waves", "fleets": 2, "net_arch": (32,)}
    fields.update(changes)
    return TrainConfig(**fields, residual=ResidualConfig(**residual))  # type: ignore[arg-type]


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
    with pytest.raises(ValueError, match=r"baselines \(deployable or privileged\).*'mpc'"):
        DistillConfig(teacher="mpc_oracle")
    with pytest.raises(ValueError, match="procedural must be an integer >= 0"):
        DistillConfig(procedural=-1)
    with pytest.raises(ValueError, match="set procedural >= 1"):
        DistillConfig(redraw=True)
    with pytest.raises(ValueError, match="redraw must be true or false"):
        DistillConfig(procedural=1, redraw=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="fit_applied must be true or false"):
        DistillConfig(fit_applied="yes")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"label_base must be one of \['env', 'twin'\]"):
        DistillConfig(label_base="shadow")


def test_the_procedural_distribution_is_checked() -> None:
    settings = DistillConfig(procedural=1, distribution={"v0": [0.1, 0.6]})
    assert settings.distribution == {"v0": (0.1, 0.6)}  # TOML lists become ranges
    with pytest.raises(ValueError, match=r"unknown keys \['max_degree'\].*slots"):
        DistillConfig(procedural=1, distribution={"max_degree": 3})
    with pytest.raises(ValueError, match=r"distribution: ScenarioDistribution.force_scale"):
        DistillConfig(procedural=1, distribution={"force_scale": [0.0, 1.0]})
    with pytest.raises(ValueError, match=r"v0 = \(0.5,\) must be a range \(lo, hi\) of two"):
        DistillConfig(procedural=1, distribution={"v0": [0.5]})
    with pytest.raises(ValueError, match="must be a table"):
        DistillConfig(procedural=1, distribution="wide")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="set procedural >= 1"):
        DistillConfig(distribution={"v0": [0.1, 0.6]})


def test_the_procedural_fleets_are_drawn_from_the_configured_distribution(
    tmp_path: Path,
) -> None:
    config = _config(scenario=("bench_mild",), fleets=2, neighbour_slots=4)
    wide = {"v0": (0.55, 0.6), "force_scale": (0.5, 0.5)}
    settings = DistillConfig(rounds=1, steps=4, epochs=1, procedural=1, distribution=wide)
    fleet = _groups(config, settings)[-1].env.sim.scenario
    expected = ScenarioDistribution(max_degree=4, **wide).sample(0)
    assert fleet == expected and fleet.name == "procedural_0"
    np.testing.assert_array_equal(fleet.tau_limits[1], np.tile(NOMINAL_TAU_MAX, (fleet.n, 1)) / 2)
    assert 0.55 <= fleet.v0_schedule.values[0] <= 0.6
    plain = _groups(config, DistillConfig(rounds=1, steps=4, epochs=1, procedural=1))[-1]
    assert plain.env.sim.scenario == ScenarioDistribution(max_degree=4).sample(0) != fleet
    distill(config, settings, tmp_path / "s")
    record = json.loads((tmp_path / "s" / "config.json").read_text())["distillation"]
    assert record["distribution"] == {"v0": [0.55, 0.6], "force_scale": [0.5, 0.5]}


@pytest.mark.parametrize("teacher", ["nn_dsc_privileged", "mpc", "oracle"])
def test_an_unclipped_force_and_rate_label_reproduces_the_teachers_command(teacher: str) -> None:
    residual = ResidualConfig(mode="force_and_rate", scale=1.0)
    env = _env_after(5, residual)
    policy = make_policy(teacher, env.sim)
    again = make_policy(teacher, env.sim)  # the same teacher, acting once more
    label = _labels(env, policy)
    assert label.shape == (2, 5, 4)
    # a student that outputs the label: the env composes the teacher's command
    command = env.controller.compose(np.clip(label, -1.0, 1.0))[..., :4]
    wanted = np.asarray(again.act_batch(env.sim.arrays.obs))[..., :4]
    inside = np.abs(label) <= 1.0
    assert inside[..., :3].any() and inside[..., 3].any()
    np.testing.assert_allclose(command[inside], wanted[inside], rtol=1e-12, atol=1e-9)
    assert not np.allclose(label[..., 3], 0.0)  # the teacher sets its own path-variable rate


def test_force_labels_leave_the_rate_to_the_base() -> None:
    env = _env_after(5, ResidualConfig(mode="force", scale=1.0))
    label = _labels(env, make_policy("mpc", env.sim))
    assert label.shape == (2, 5, 3)


def _constant_residual_labels(
    label_base: str, residual: float, steps: int, seed: int = 0, offset: int = 0, horizon: int = 0
) -> np.ndarray:
    """Labels (steps, B, n, 3) of a student whose output is (r, 0, -r) on every step.

    ``horizon``: an episode length in steps (0: the scenario's), for fleets that restart.
    """
    config = _config(base_policy="mpc_tuned", mode="force", scale=0.5, seed=seed)
    settings = DistillConfig(teacher="nn_dsc", label_base=label_base)
    scenario = scenarios.make_scenario("bench_current_waves")
    if horizon:
        scenario = scenario.replace(max_steps=horizon)
    group = _group(config, settings, scenario, 2, offset, None)
    size = group.obs.shape[1]
    student = student_actor(config, size, 3)
    with torch.no_grad():
        student.output.bias[:] = torch.tensor([residual, 0.0, -residual])
    _, labels, _ = _rollout([group], student, InputStatistics(np.zeros(size), np.ones(size)), steps)
    return labels.reshape(steps, 2, 5, 3)


def test_labels_on_the_twin_leave_out_the_residual_the_base_cancels() -> None:
    # mpc_tuned's force observer is shown the applied force minus the residual, so
    # it takes a steady residual for a disturbance and cancels it (time constant
    # 0.2 s): after 6 s the env's base commands exactly the residual less than its
    # twin shown the whole force, and a label taken on it holds the residual again.
    steps, residual = 120, 0.2
    on_env = _constant_residual_labels("env", residual, steps)
    on_twin = _constant_residual_labels("twin", residual, steps)
    difference = on_env - on_twin
    np.testing.assert_array_equal(difference[0], 0.0)  # before any residual acted
    expected = np.tile([residual, 0.0, -residual], (2, 5, 1))
    np.testing.assert_allclose(difference[-1], expected, atol=1e-6)


@pytest.mark.parametrize(("seed", "offset"), [(0, 0), (1000, 0), (1000, 3)])
def test_without_a_residual_the_twin_is_the_envs_base_through_restarts(
    seed: int, offset: int
) -> None:
    # mpc_tuned samples its plans from generators seeded at reset: the twin must be
    # seeded and restarted as the env's base is (episodes of 30 steps, staggered:
    # both fleets restart several times in 120 steps). Seeded 0 instead of 1000,
    # the twin's plans differ from step 10 on.
    env, twin = (
        _constant_residual_labels(base, 0.0, 120, seed, offset, horizon=30)
        for base in ("env", "twin")
    )
    np.testing.assert_array_equal(env, twin)
    assert np.abs(env).max() > 0.01  # the teacher is not the base: the labels are not all 0


def test_twin_labels_need_an_observer_base_that_hides_the_residual(tmp_path: Path) -> None:
    twin = dataclasses.replace(TINY, label_base="twin")
    base = {"base_policy": "mpc_tuned", "mode": "force"}
    with pytest.raises(ValueError, match=r'"twin".*hide_residual_from_base = false'):
        distill(_config(**base, hide_residual_from_base=False), twin, tmp_path / "x")
    with pytest.raises(
        ValueError, match=r'label_base = "twin".*mpc, mpc_tuned.*base_policy = "nn_dsc"'
    ):
        distill(_config(), twin, tmp_path / "x")
    with pytest.raises(ValueError, match=r'base_policy = "none"'):
        distill(_config(base_policy="none", mode="force_and_rate", scale=1.0), twin, tmp_path / "x")
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "path",
    sorted(
        p
        for p in [*(ROOT / "examples").rglob("*.toml"), *(ROOT / "studies/student").rglob("*.toml")]
        if "[distill]" in p.read_text()
    ),
    ids=lambda p: p.stem,
)
def test_the_example_distillation_files_are_valid(path: Path) -> None:
    config, settings = read_distill_config(path, seed=0)
    check_distillation(config, settings)


def test_applied_bounds_are_the_residuals_that_command_the_actuator_limits() -> None:
    # nn_dsc saturates in its start-up transient: its base sits at or past the limits
    residual = ResidualConfig(mode="force_and_rate", scale=0.5)
    env = FleetVecEnv("bench_saturation", num_fleets=2, base_policy="nn_dsc", residual=residual)
    env.seed(4)
    env.reset()
    low, high = _applied_bounds(env)
    assert low.shape == high.shape == (2, 5, 4)
    assert np.all(low <= high) and np.all(low >= -1.0) and np.all(high <= 1.0)
    assert np.all(low[..., 3] == -1.0) and np.all(high[..., 3] == 1.0)  # the rate: [-1, 1]
    tau_min, tau_max = (np.broadcast_to(t, (2, 5, 3)) for t in env.scenario.tau_limits)
    upper = np.abs(high[..., :3]) < 1.0  # the limit is within the residual's reach
    lower = np.abs(low[..., :3]) < 1.0
    assert upper.any() and (~upper).any()
    at_high = env.controller.compose(high)[..., :3]
    np.testing.assert_allclose(at_high[upper], tau_max[upper], rtol=1e-12)
    at_low = env.controller.compose(low)[..., :3]
    np.testing.assert_allclose(at_low[lower], tau_min[lower], rtol=1e-12)
    # out of reach: the residual's own limit, below the actuator's (hi = 1), or a base so
    # far past it that every residual saturates (hi = -1)
    below, beyond = high[..., :3] == 1.0, high[..., :3] == -1.0
    assert np.all(below | beyond | upper) and below.any() and beyond.any()
    assert np.all(at_high[below] <= tau_max[below]) and np.all(at_high[beyond] >= tau_max[beyond])


def test_a_residual_that_yields_at_a_limit_has_no_bounds_of_effect_there() -> None:
    residual = ResidualConfig(mode="force_and_rate", scale=0.5)
    gated = dataclasses.replace(residual, yield_at_limit=True)
    envs = []
    for config in (residual, gated):
        env = FleetVecEnv("bench_saturation", num_fleets=2, base_policy="nn_dsc", residual=config)
        env.seed(4)
        env.reset()
        tau_min, tau_max = env.scenario.tau_limits
        env.controller.base_actions[0, 0, :3] = tau_max[0]  # at the limits, within reach
        env.controller.base_actions[0, 1, :3] = tau_min[1]
        envs.append(env)
    plain, bounds = _applied_bounds(envs[0]), _applied_bounds(envs[1])
    at_max, at_min = envs[1].controller.base_at_limits()
    at_limit = at_max | at_min
    assert at_max[0, 0].all() and at_min[0, 1].all() and (~at_limit).any()
    assert np.all(plain[0, 0, 0, :3] < 0.0) and np.all(plain[1, 0, 1, :3] > 0.0)  # plain: room
    low, high = bounds[..., :3]
    assert np.array_equal(low[at_limit], high[at_limit])  # no residual changes the force there
    np.testing.assert_array_equal(bounds[..., :3][:, ~at_limit], plain[..., :3][:, ~at_limit])
    np.testing.assert_array_equal(bounds[..., 3], plain[..., 3])  # the rate: [-1, 1]
    # every residual inside the plain bounds applies the same force on an axis at a limit
    rng = np.random.default_rng(0)
    for _ in range(5):
        a = rng.uniform(-1.0, 1.0, size=(2, 5, 4))
        command = envs[1].controller.compose(a)[..., :3]
        tau_min, tau_max = envs[1].scenario.tau_limits
        applied = np.clip(command, tau_min, tau_max)
        base = np.clip(envs[1].controller.base_actions[..., :3], tau_min, tau_max)
        np.testing.assert_allclose(applied[at_limit], base[at_limit], rtol=1e-12)


def test_a_student_that_yields_at_a_limit_yields_wherever_it_is_loaded(tmp_path: Path) -> None:
    config = _config(scenario="bench_saturation", mode="force", scale=0.5, yield_at_limit=True)
    settings = DistillConfig(rounds=1, steps=20, epochs=2, batch_size=256, fit_applied=True)
    distill(config, settings, tmp_path / "s")
    record = json.loads((tmp_path / "s" / "config.json").read_text())
    assert record["config"]["residual"]["yield_at_limit"] is True
    policy = load_policy(tmp_path / "s")  # bench_saturation, on nn_dsc: saturated at first
    sim = FleetVecEnv("bench_saturation", num_fleets=2).sim
    obs = sim.reset(seeds=[1, 2])
    pulled_back = 0
    for _ in range(20):
        command = policy.act_batch(obs)
        at_max, at_min = policy._controller.base_at_limits()
        residual = policy.diagnostics["residual"]
        assert not np.any(residual[at_max] < 0.0) and not np.any(residual[at_min] > 0.0)
        base = policy._controller.base_actions[..., :3]
        np.testing.assert_array_equal(command[..., :3], base + residual)
        pulled_back += int(np.sum((at_max | at_min) & (residual == 0.0)))
        assert np.all(residual[~(at_max | at_min)] != 0.0)  # the student acts elsewhere
        obs = sim.step(command)
    assert pulled_back > 0  # the start-up transient reached the limits, and the rule acted


def test_the_applied_loss_is_one_sided_only_where_the_target_sits_at_a_bound() -> None:
    bounds = torch.tensor([[[-1.0, -0.3, -1.0]], [[0.2, 1.0, 1.0]]])  # (2, R=1, k=3)
    targets = torch.tensor([[0.2, -0.3, 0.5]])  # at hi, at lo, inside
    past = torch.tensor([[0.9, -0.8, 0.5]])  # past both bounds, exact inside
    assert float(_loss(past, targets, bounds)) == 0.0
    assert float(_loss(past, targets, None)) > 0.0  # the plain loss pulls back to the limit
    short = torch.tensor([[0.0, -0.3, 0.5]])  # short of the limit: force lost
    assert float(_loss(short, targets, bounds)) == pytest.approx(0.04 / 3)
    inside = torch.tensor([[0.2, -0.3, 0.9]])  # past the target inside the bounds: penalized
    assert float(_loss(inside, targets, bounds)) == pytest.approx(0.16 / 3)
    output = past.clone().requires_grad_(True)
    _loss(output, targets, bounds).backward()
    assert output.grad is not None and not output.grad.any()


def test_fit_applied_distills_a_deterministic_student_of_its_own(tmp_path: Path) -> None:
    config = _config(scenario="bench_saturation", mode="force", scale=0.5)
    settings = DistillConfig(rounds=2, steps=30, epochs=3, batch_size=256, fit_applied=True)
    report = distill(config, settings, tmp_path / "a")
    again = distill(config, settings, tmp_path / "b")
    plain = distill(
        config, DistillConfig(rounds=2, steps=30, epochs=3, batch_size=256), tmp_path / "c"
    )
    assert again.losses == report.losses and all(np.isfinite(report.losses))
    assert report.losses[-1] < report.zero_loss
    assert 0.0 < report.at_limit < 1.0 and report.at_limit == plain.at_limit  # same data
    assert report.losses != plain.losses
    first = load_file(str(tmp_path / "a" / "policy.safetensors"))
    second = load_file(str(tmp_path / "b" / "policy.safetensors"))
    third = load_file(str(tmp_path / "c" / "policy.safetensors"))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    assert not np.array_equal(first["output.weight"].numpy(), third["output.weight"].numpy())
    record = json.loads((tmp_path / "a" / "config.json").read_text())["distillation"]
    assert record["fit_applied"] is True and record["at_limit"] == report.at_limit


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
        base_policy="mpc",
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
    with pytest.raises(ValueError, match="held-out seeds"):
        distill(_config(seed=10_000), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="held-out seeds"):
        distill(
            _config(scenario=("bench_mild", "bench_switching"), seed=9_999), TINY, tmp_path / "x"
        )
    with pytest.raises(ValueError, match="algo='sac'"):
        distill(_config(algo="sac"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="mode='kinematic'"):
        distill(_config(mode="kinematic"), TINY, tmp_path / "x")
    with pytest.raises(ValueError, match="must stay below 10000"):
        distill(
            _config(scenario=("bench_mild", "bench_switching"), fleets=4),
            DistillConfig(rounds=5_001, procedural=2, redraw=True),
            tmp_path / "x",
        )
    with pytest.raises(ValueError, match="at least one fleet each; got fleets=2"):
        distill(
            _config(scenario=("bench_mild", "bench_switching")),
            DistillConfig(procedural=1),
            tmp_path / "x",
        )
    assert not (tmp_path / "x").exists()


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
    assert run["device"] == "cpu" and run["draws"] == [[], []]  # no procedural fleets
    assert (
        run["evaluation"] is None and not (log / "evaluations.csv").exists()
    )  # no --eval-num-seeds
    rows = list(csv.DictReader((log / "rounds.csv").open()))
    assert [int(r["round"]) for r in rows] == [0, 1] and int(rows[1]["samples"]) == 200
    assert load_policy(out).config.residual.mode == "force_and_rate"


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
    assert "held-out seeds" in capsys.readouterr().err


def _encoder_config(**changes: object) -> TrainConfig:
    fields: dict[str, object] = {
        "scenario": "bench_mild",
        "fleets": 2,
        "net_arch": (16,),
        "encoder": "deepsets",
        "history": 2,
        "shared_slot_statistics": True,
        "neighbour_slots": 3,
    }
    fields.update(changes)
    return _config(**fields)


class _Recorder:
    """A ``TorchActor`` that keeps the inputs it was given and the actions it gave."""

    def __init__(self, actor: object) -> None:
        self.actor = actor
        self.input_size = actor.input_size  # type: ignore[attr-defined]
        self.action_size = actor.action_size  # type: ignore[attr-defined]
        self.calls: list[tuple[np.ndarray, np.ndarray]] = []

    def __call__(self, rows: np.ndarray) -> np.ndarray:
        action = self.actor(rows)  # type: ignore[operator]
        self.calls.append((rows.copy(), action.copy()))
        return action


def test_an_encoder_history_student_acts_in_rollouts_as_load_policy_runs_it(
    tmp_path: Path,
) -> None:
    config = _encoder_config()
    distill(config, DistillConfig(rounds=2, steps=12, epochs=2, batch_size=64), tmp_path / "a")
    _, network, stats = read_agent(tmp_path / "a")
    assert network.encoder is not None and stats is not None
    short = scenarios.make_scenario("bench_mild", max_steps=7)  # episodes end in the run
    group = _group(config, DistillConfig(teacher="nn_dsc"), short, 2, 0, None)
    policy = load_policy(tmp_path / "a", scenario=short)
    recorder = _Recorder(policy.actor)
    policy.actor = recorder
    ends = 0
    for _ in range(16):
        rows = group.obs.copy()
        action = student_actions(network, stats, rows)  # what the rollouts apply
        policy.act_batch(group.env.sim.arrays.obs)
        seen, acted = recorder.calls[-1]
        np.testing.assert_array_equal(seen, rows)  # the same input, history stacked alike
        np.testing.assert_array_equal(acted, action)  # the same action, bit for bit
        group.view.step_async(action)
        obs, _, dones, _ = group.view.step_wait()
        group.obs = np.asarray(obs, dtype=np.float32)
        ended = np.asarray(dones).reshape(2, 5)[:, 0]
        ends += int(ended.sum())
        policy.reset_fleets(ended)
    assert ends >= 2  # the histories were cleared across episode boundaries
    assert rows[:, -1].any()  # and the history was in use: the oldest entry is valid


def test_an_encoder_student_is_a_format_2_folder_that_runs_on_any_degree(
    tmp_path: Path,
) -> None:
    config = _encoder_config(
        scenario=("bench_mild", "bench_switching"), fleets=3, neighbour_slots=4
    )
    settings = DistillConfig(rounds=3, steps=6, epochs=2, procedural=1, redraw=True)
    report = distill(config, settings, tmp_path / "a")
    again = distill(config, settings, tmp_path / "b")
    assert report.draws == ((0,), (1,), (2,)) and report.device == "cpu"
    assert again.losses == report.losses
    first = load_file(str(tmp_path / "a" / "policy.safetensors"))
    second = load_file(str(tmp_path / "b" / "policy.safetensors"))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    assert "encoder.phi.0.weight" in first
    manifest = json.loads((tmp_path / "a" / "manifest.json").read_text())
    record = json.loads((tmp_path / "a" / "config.json").read_text())
    assert (manifest["format_version"], manifest["trainer"]) == (3, "sb3")
    assert record["actor"]["encoder"] == "deepsets" and record["actor"]["history"] == 2
    assert record["distillation"]["draws"] == [[0], [1], [2]]
    # cpf-train's actor of the same TrainConfig has the same tensors and shapes
    size = config.learner_input_size()
    built = build_actor(config, size, 3).state_dict()
    assert {k: tuple(v.shape) for k, v in built.items()} == {
        k: tuple(v.shape) for k, v in first.items()
    }
    # the slots' weights stay raw (an empty slot is 0), the slots share statistics
    stats = json.loads((tmp_path / "a" / "normalization.json").read_text())
    weights = slice(SLOTS, SLOTS + 4 * 4, 4)
    assert stats["mean"][weights] == [0.0] * 4 and stats["var"][weights] == [1.0] * 4
    star = ScenarioDistribution(sizes=(10, 10), graph_families=("star",)).sample(
        10_000, evaluation=True
    )  # a held-out 10-vessel star: its centre has 9 neighbours, more than the 4 slots trained
    policy = load_policy(tmp_path / "a", scenario=star)
    assert observation_layout(star).n_slots == 9
    obs = FleetVecEnv(star, num_fleets=1).sim.reset(seeds=[3])
    assert np.all(np.isfinite(policy.act_batch(obs)))
    if importlib.util.find_spec("onnxruntime") is not None:  # the onnx extra
        from cpf_commands.export import export_main

        assert export_main([str(tmp_path / "a"), str(tmp_path / "a.onnx"), "--checks", "50"]) == 0


def test_redraw_gives_each_round_its_own_training_draws() -> None:
    assert draw_seeds(DistillConfig(procedural=3), 2) == [0, 1, 2]
    assert draw_seeds(DistillConfig(procedural=3, redraw=True), 0) == [0, 1, 2]
    assert draw_seeds(DistillConfig(procedural=3, redraw=True), 2) == [6, 7, 8]


def test_distill_refuses_a_device_it_does_not_have(tmp_path: Path) -> None:
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(ValueError, match=r"sees none.*--device cpu"):
        distill(_config(), TINY, tmp_path / "x", device="cuda")
    assert not (tmp_path / "x").exists()


def test_evaluation_rows_are_cpf_trains_and_leave_the_student_unchanged(tmp_path: Path) -> None:
    evaluate = ValidationEvaluator(["bench_current_waves"], num_seeds=1, max_steps=20)
    evaluated = distill(_config(), TINY, tmp_path / "a", evaluate=evaluate)
    plain = distill(_config(), TINY, tmp_path / "b")
    assert plain.evaluations == () and plain.losses == evaluated.losses
    first = load_file(str(tmp_path / "a" / "policy.safetensors"))
    second = load_file(str(tmp_path / "b" / "policy.safetensors"))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    rows = evaluated.evaluations
    # cpf-train's columns (tests/agents/test_schedule.py), one row before round 0 and one a round.
    assert [list(row) for row in rows] == [
        ["vessel_steps", "wall_clock_seconds", "evaluation_seconds", "mean_cost",
         "cost_bench_current_waves"]
    ] * 3  # fmt: skip
    assert [row["vessel_steps"] for row in rows] == [0, *(r["samples"] for r in evaluated.rounds)]
    seconds = [row["wall_clock_seconds"] for row in rows]
    assert seconds == sorted(seconds) and seconds[-1] <= evaluated.seconds + 5e-4  # rounded
    # Row 0 is the base itself; the last row is the student written to the folder.
    base = run_bench(["nn_dsc"], ["bench_current_waves"], 1, VALIDATION_SEED, max_steps=20)
    assert rows[0]["mean_cost"] == float(np.mean(base[0].metrics["cost"]))
    final = run_bench(
        {"s": tmp_path / "a"}, ["bench_current_waves"], 1, VALIDATION_SEED, max_steps=20,
        reference="s",
    )  # fmt: skip
    assert rows[-1]["mean_cost"] == float(np.mean(final[0].metrics["cost"]))
    assert rows[-1]["mean_cost"] != rows[0]["mean_cost"]


def test_a_distillation_file_extends_another_and_merges_its_distill_table(
    tmp_path: Path,
) -> None:
    """The student recipes are a chain: ``extends`` first, ``[distill]`` merged key by key."""
    tuned, settings = read_distill_config(ROOT / "studies/student/student_mpc_tuned.toml", 0)
    applied, applied_settings = read_distill_config(
        ROOT / "studies/student/student_mpc_tuned_applied.toml", 0
    )
    assert applied == tuned
    assert (tuned.base_policy, tuned.residual.neighbour_slots) == ("mpc_tuned", 6)
    assert applied_settings == dataclasses.replace(settings, fit_applied=True)
    (tmp_path / "base.toml").write_text('scenario = "bench_mild"\n[distill]\nrounds = 3\n')
    (tmp_path / "child.toml").write_text(
        'extends = "base.toml"\n[residual]\nscale = 0.3\n[distill]\nsteps = 7\n'
    )
    config, merged = read_distill_config(tmp_path / "child.toml", 0)
    assert (config.scenario, config.residual.scale, merged.rounds, merged.steps) == (
        "bench_mild",
        0.3,
        3,
        7,
    )
    (tmp_path / "base.toml").write_text('extends = "child.toml"\n')
    with pytest.raises(ValueError, match="comes back to a file of its chain"):
        read_distill_config(tmp_path / "child.toml", 0)
