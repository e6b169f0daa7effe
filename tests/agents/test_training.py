"""Training and loading: PPO and SAC on FleetVecEnv, residual and from scratch; load_policy."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecMonitor

from agents import TrainConfig, load_policy, train
from agents.folder.files import AgentFolderError
from agents.training.algorithms import ALGORITHMS, build_model, make_env
from baselines import make_policy
from cpf_commands.train import train_main
from cpf_env import FleetSim, scenarios
from cpf_env.envs.gym_envs import CentralizedFleetEnv
from cpf_env.envs.residual import ResidualController

TINY = {"fleets": 2, "n_steps": 16, "batch_size": 80, "n_epochs": 1, "net_arch": (16, 16)}


@pytest.mark.parametrize("algo", ["ppo", "sac"])
@pytest.mark.parametrize("base", ["nn_dsc", "none"])
def test_train_and_load_round_trip(tmp_path: Path, algo: str, base: str) -> None:
    """A few hundred vessel-steps of training; the loaded policy acts like the saved model."""
    config = TrainConfig(
        algo=algo,
        scenario="bench_mild",
        base_policy=base,
        timesteps=320,
        seed=1,
        **TINY,  # type: ignore[arg-type]
    )
    folder = train(config, tmp_path / "run", progress=False)
    record = json.loads((folder / "config.json").read_text())
    assert record["timesteps_done"] >= 320
    assert TrainConfig.from_json(record["config"]) == config
    assert (folder / "progress.csv").is_file() and not (folder / "vecnormalize.pkl").exists()
    assert (folder / "manifest.json").is_file() and (folder / "policy.safetensors").is_file()

    policy = load_policy(folder)
    sim = FleetSim(policy.scenario, num_fleets=3)
    obs = sim.reset(seeds=[5, 6, 7])
    actions = policy.act_batch(obs)
    assert actions.shape == (3, 5, 5) and np.all(np.isfinite(actions))
    again = load_policy(folder).act_batch(obs)
    assert np.array_equal(actions, again)  # deterministic, reproducible after loading
    # the same numbers through SB3's own Model.load (it unpickles model.zip, which this test
    # wrote itself) and VecNormalize's evaluation formula written out by hand
    venv = make_env(config, num_fleets=3)
    statistics = json.loads((folder / "normalization.json").read_text())
    model = ALGORITHMS[algo].load(folder / "model.zip", device="cpu")
    controller = ResidualController(
        policy.scenario,
        None if base == "none" else make_policy(base, policy.scenario),
        3,
        venv.controller.config,
    )
    inputs = controller.observe(obs).reshape(15, -1).astype(np.float32)
    mean, var = np.array(statistics["mean"]), np.array(statistics["var"])
    normalized = np.clip((inputs - mean) / np.sqrt(var + 1e-8), -10.0, 10.0).astype(np.float32)
    action, _ = model.predict(normalized, deterministic=True)
    np.testing.assert_array_equal(actions, controller.compose(action.reshape(3, 5, -1)))
    if base == "nn_dsc":
        base_actions = make_policy("nn_dsc", policy.scenario).act_batch(obs)
        residual = actions[..., :3] - base_actions[..., :3]
        assert np.all(np.abs(residual) <= 0.2 * np.array([9.2, 4.5, 3.0]) + 1e-9)
        assert np.array_equal(actions[..., 3:], base_actions[..., 3:])


def test_a_fresh_residual_agent_is_exactly_the_base_policy() -> None:
    """Zero-initialized output layer: the mean residual is 0, so the deterministic agent
    commands the base policy's actions exactly."""
    for algo in ("ppo", "sac"):
        config = TrainConfig(algo=algo, scenario="bench_mild", **TINY)  # type: ignore[arg-type]
        env = make_env(config)
        model = build_model(config, VecMonitor(env))
        obs = env.reset()
        action, _ = model.predict(obs, deterministic=True)
        assert np.all(action == 0.0), algo


def test_loaded_policy_runs_under_evaluate_policy_and_on_another_scenario(tmp_path: Path) -> None:
    config = TrainConfig(scenario="bench_mild", timesteps=160, **TINY)  # type: ignore[arg-type]
    folder = train(config, tmp_path / "run", progress=False)
    policy = load_policy(folder, scenario="bench_heterogeneous")  # same layout, other task
    assert policy.scenario.name == "bench_heterogeneous"
    env = Monitor(CentralizedFleetEnv("bench_heterogeneous", max_steps=20))
    mean, _ = evaluate_policy(policy, env, n_eval_episodes=2)
    assert np.isfinite(mean)
    with pytest.raises(ValueError, match="network"):
        load_policy(folder, scenario=scenarios.get("bench_mild").replace(message_size=2))


def test_load_policy_says_what_a_folder_lacks(tmp_path: Path) -> None:
    with pytest.raises(AgentFolderError, match="not a cpf-train output folder"):
        load_policy(tmp_path)


def test_cpf_train_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli"
    argv = ["--scenarios", "wang2014", "--fleets", "2", "-n", "160", "--set", "n_steps=16",
            "--set", "batch_size=32", "--set", "n_epochs=1", "--eval-every", "0", "--out", str(out),
            "--quiet"]  # fmt: skip
    assert train_main(argv) == 0
    assert "saved to" in capsys.readouterr().out
    assert (out / "model.zip").is_file()
    with pytest.raises(SystemExit):
        train_main(argv)  # the folder holds a model: refused, not overwritten
    assert "already holds a trained model" in capsys.readouterr().err
    assert train_main([*argv, "--force"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [".cli.lock", "cli"]  # no staging left
    for bad, message in ((["--out", ""], "output folder is empty"),
                         (["--seed", str(2**32)], "seed must be"),
                         (["--set", "log_std_init=1e6"], "log_std_init")):  # fmt: skip
        with pytest.raises(SystemExit):
            train_main([*argv[:-3], *bad, "--quiet"] if bad[0] == "--out" else
                       [*argv, *bad, "--force"])  # fmt: skip
        assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == [".cli.lock", "cli"]  # nothing created
    with pytest.raises(SystemExit):
        train_main(["--out", str(out), "--set", "residual.scale=0"])
    assert "residual scale" in capsys.readouterr().err


def test_the_committed_agent_loads_and_corrects_the_base() -> None:
    """The agent in results/ (docs/results.md's benchmark row) loads with today's code and acts."""
    folder = ROOT / "tests/fixtures/agents"
    policy = load_policy(folder / "residual_ppo_lossy_links")
    assert policy.scenario.name == "bench_lossy_links"
    sim = FleetSim(policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(5):
        obs = sim.step(policy.act_batch(obs))
    residual = policy.diagnostics["residual"]
    assert np.any(residual != 0.0)
    assert np.all(np.abs(residual) <= 0.2 * np.array([9.2, 4.5, 3.0]) + 1e-9)


def test_a_trained_policy_acts_the_same_whatever_the_torch_threads() -> None:
    """Evaluations on Ray workers (one thread) equal local ones (all cores), bit for bit."""
    import torch

    folder = ROOT / "tests/fixtures/agents"
    policy = load_policy(folder / "residual_ppo_lossy_links")
    before = torch.get_num_threads()
    try:
        for fleets in (1, 2, 7):  # small batches take torch's thread-dependent paths
            runs = []
            for threads in (1, 2, 4):
                torch.set_num_threads(threads)
                sim = FleetSim(policy.scenario, num_fleets=fleets)
                obs = sim.reset(seeds=list(range(fleets)))
                policy.reset()
                trajectory = []
                for _ in range(60):
                    obs = sim.step(policy.act_batch(obs))
                    trajectory.append(obs.copy())
                assert torch.get_num_threads() == threads  # the caller's setting is restored
                runs.append(np.stack(trajectory))
            np.testing.assert_array_equal(runs[0], runs[1])
            np.testing.assert_array_equal(runs[0], runs[2])
    finally:
        torch.set_num_threads(before)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("learning_rate", -1.0, "learning_rate must be a number > 0"),
        ("learning_rate", float("nan"), "learning_rate must be a number > 0"),
        ("gamma", 0.0, "gamma must be in"),
        ("gamma", 1.5, "gamma must be in"),
        ("log_std_init", float("inf"), "log_std_init must be a number in"),
        ("log_std_init", 1e6, "log_std_init must be a number in"),
        ("net_arch", (), "net_arch must list layer sizes"),
        ("net_arch", (64, 0), "net_arch must list layer sizes"),
        ("buffer_size", 0, "buffer_size must be an integer >= 1"),
        ("normalize_observations", "yes", "normalize_observations must be true or false"),
        ("residual", {"scale": -0.1}, "residual scale"),
        ("residual", {"pace": 1.0}, r"residual has unknown field\(s\) \['pace'\]"),
        ("residual", 0.2, "residual must be a ResidualConfig or a table"),
        ("base_policy", "pid", "base_policy must be one of"),
        ("fleets", 0, "fleets must be an integer >= 1"),
        ("seed", -1, "seed must be an integer in"),
        ("seed", 2**32, "seed must be an integer in"),
        ("history", -1, "history must be an integer >= 0"),
        ("history", True, "history must be an integer >= 0"),
        ("encoder", "transformer", r"encoder must be one of \['deepsets'\] or None"),
    ],
)
def test_train_config_rejects_bad_settings_before_any_training(
    field: str, value: object, message: str
) -> None:
    """A bad setting is refused when the config is built (a sweep checks it before Ray starts)."""
    with pytest.raises(ValueError, match=message):
        TrainConfig(scenario="bench_mild", **{field: value})  # type: ignore[arg-type]


def test_an_encoder_needs_ppo_and_shared_slot_statistics() -> None:
    with pytest.raises(ValueError, match="implemented for PPO"):
        TrainConfig(scenario="bench_mild", algo="sac", encoder="deepsets")
    with pytest.raises(ValueError, match="set shared_slot_statistics=true"):
        TrainConfig(scenario="bench_mild", encoder="deepsets")
    TrainConfig(scenario="bench_mild", encoder="deepsets", normalize_observations=False)


def test_cpf_train_takes_the_encoder_and_the_history(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "encoder"
    argv = ["--scenarios", "bench_mild", "--fleets", "2", "-n", "32", "--set", "n_steps=16",
            "--set", "batch_size=32", "--set", "n_epochs=1", "--eval-every", "0", "--out", str(out),
            "--quiet", "--set", "encoder=deepsets", "shared_slot_statistics=true",
            "history=2"]  # fmt: skip
    assert train_main(argv) == 0
    config = load_policy(out).config
    assert (config.encoder, config.history) == ("deepsets", 2)
    saved = (out / "hyperparameters.toml").read_text()
    assert 'encoder = "deepsets"' in saved and "history = 2" in saved
    with pytest.raises(SystemExit):
        train_main([a for a in argv if a != "shared_slot_statistics=true"] + ["--force"])
    assert "set shared_slot_statistics=true" in capsys.readouterr().err


def test_a_minibatch_larger_than_one_rollout_is_cut_to_it_with_a_warning() -> None:
    config = TrainConfig(scenario="bench_mild", **{**TINY, "batch_size": 10_000})  # type: ignore[arg-type]
    env = make_env(config)
    rollout = config.n_steps * env.num_envs
    with pytest.warns(UserWarning, match=f"larger than one rollout .* = {rollout}"):
        model = build_model(config, VecMonitor(env))
    assert model.batch_size == rollout  # type: ignore[attr-defined]
