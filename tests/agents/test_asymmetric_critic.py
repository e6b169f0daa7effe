"""The asymmetric critic: the unobserved state, the env appending it, the policy hiding it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from agents import TrainConfig, load_policy, train
from agents.envs.vec_env import FleetVecEnv
from agents.training.algorithms import (
    AsymmetricActorCriticPolicy,
    LocalInputs,
    make_env,
    unobserved_columns,
)
from agents.training.init_from import read_init_source
from agents.training.run_folder import TrainingRun
from agents.training.schedule import RunSchedule
from baselines import make_policy
from cpf_commands.train import train_main
from cpf_env import FleetSim, scenarios
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.evaluation.privileged import UNOBSERVED_SIZE, lumped_uncertainty, unobserved_state
from cpf_env.sim.observation import THETA

TINY = {"fleets": 2, "n_steps": 16, "batch_size": 80, "n_epochs": 1, "net_arch": (16, 16)}
STUDENT = Path(__file__).parents[2] / "tests" / "fixtures" / "agents" / "student_mpc_deepsets"


def test_the_unobserved_state_is_the_true_force_v0_and_the_offset_from_the_fleet() -> None:
    scenario = scenarios.get("bench_switching")  # v0 steps up at 35 s
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[3, 4])
    policy = make_policy("nn_dsc", sim)
    for _ in range(int(45.0 / scenario.dt)):
        obs = sim.step(policy.act_batch(obs))
    state = unobserved_state(sim)
    assert state.shape == (2, sim.n, UNOBSERVED_SIZE) and state.dtype == np.float32
    expected = lumped_uncertainty(sim) / sim.constants.tau_scale
    np.testing.assert_array_equal(state[..., :3], expected.astype(np.float32))
    assert np.all(state[..., 3] == np.float32(scenario.v0_schedule.at(45.0)))
    assert scenario.v0_schedule.at(45.0) != scenario.v0_schedule.at(0.0)
    np.testing.assert_allclose(state[..., 4].sum(axis=1), 0.0, atol=1e-5)  # about the mean
    theta = sim.arrays.theta
    np.testing.assert_allclose(state[0, :, 4], theta[0] - theta[0].mean(), rtol=1e-6)
    one = unobserved_state(sim, [1])
    np.testing.assert_array_equal(one, state[1:])


def test_the_critic_state_is_appended_and_the_local_input_is_unchanged() -> None:
    """Hundreds of steps with staggered episode ends: the local part, bit for bit."""
    settings = {
        "num_fleets": 3,
        "base_policy": "nn_dsc",
        "residual": ResidualConfig(),
        "max_steps": 120,
    }
    plain = FleetVecEnv("bench_current_waves", **settings)  # type: ignore[arg-type]
    told = FleetVecEnv("bench_current_waves", critic_state=True, **settings)  # type: ignore[arg-type]
    size = plain.observation_space.shape[0]
    assert told.observation_space.shape == (size + UNOBSERVED_SIZE,)
    for env in (plain, told):
        env.seed(7)
    a, b = plain.reset(), told.reset()
    np.testing.assert_array_equal(b[:, :size], a)
    np.testing.assert_array_equal(b[:, size:], unobserved_state(told.sim).reshape(-1, 5))
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(300):
        action = rng.uniform(-1, 1, (plain.num_envs, 3)).astype(np.float32)
        plain.step_async(action)
        told.step_async(action)
        (a, ra, da, ia), (b, rb, db, ib) = plain.step_wait(), told.step_wait()
        np.testing.assert_array_equal(b[:, :size], a)
        np.testing.assert_array_equal(ra, rb)
        np.testing.assert_array_equal(da, db)
        for fleet in np.flatnonzero(db[:: plain.n]):
            slots = range(fleet * plain.n, (fleet + 1) * plain.n)
            terminal = np.stack([ib[k]["terminal_observation"] for k in slots])
            local = np.stack([ia[k]["terminal_observation"] for k in slots])
            np.testing.assert_array_equal(terminal[:, :size], local)
            theta = terminal[:, THETA].astype(np.float64)  # the state the fleet ended in
            np.testing.assert_allclose(terminal[:, size + 4], theta - theta.mean(), atol=1e-4)
            ended += 1
    assert ended >= 3  # every fleet ended at least once


def _predict(model: PPO, inputs: np.ndarray) -> np.ndarray:
    """SB3's deterministic actions on one torch thread, as a loaded agent folder computes them.

    Small batches take thread-dependent paths in torch, which may change the last bit.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        action, _ = model.predict(inputs, deterministic=True)
    finally:
        torch.set_num_threads(threads)
    return np.asarray(action)


def _run(config: TrainConfig, tmp_path: Path) -> TrainingRun:
    return TrainingRun(config, tmp_path, RunSchedule(), None, None, None)


@pytest.mark.parametrize(
    "actor",
    [{}, {"encoder": "deepsets", "shared_slot_statistics": True, "history": 2}],
    ids=["mlp", "deepsets_history"],
)
def test_the_actor_ignores_the_unobserved_state_and_the_critic_reads_it(
    tmp_path: Path, actor: dict[str, object]
) -> None:
    config = TrainConfig(scenario="bench_mild", asymmetric_critic=True, **TINY, **actor)  # type: ignore[arg-type]
    run = _run(config, tmp_path)
    policy = run.model.policy
    assert isinstance(policy, AsymmetricActorCriticPolicy)
    assert isinstance(policy.pi_features_extractor, LocalInputs)
    columns = unobserved_columns(run.model)
    local_size = FleetVecEnv(
        "bench_mild", base_policy="nn_dsc", num_fleets=1
    ).observation_space.shape[0]
    assert columns == range(local_size, local_size + UNOBSERVED_SIZE)
    with torch.no_grad():  # a critic that reads the hidden columns, an actor that does not
        for layer in policy.mlp_extractor.policy_net:
            if isinstance(layer, torch.nn.Linear):
                layer.weight.normal_()
        policy.action_net.weight.normal_()
    obs = torch.as_tensor(run.env.reset())
    moved = obs.clone()
    moved[:, columns.start : columns.stop] += 3.0
    with torch.no_grad():
        action = policy.get_distribution(obs).distribution.mean
        value = policy.predict_values(obs)
        assert torch.equal(policy.get_distribution(moved).distribution.mean, action)
        assert not torch.equal(policy.predict_values(moved), value)


def test_an_asymmetric_run_writes_a_local_agent_that_acts_as_its_actor(tmp_path: Path) -> None:
    config = TrainConfig(
        scenario="bench_mild",
        timesteps=320,
        seed=2,
        asymmetric_critic=True,
        **TINY,  # type: ignore[arg-type]
    )
    folder = train(config, tmp_path / "run", progress=False)
    record = json.loads((folder / "config.json").read_text())
    assert TrainConfig.from_json(record["config"]) == config
    statistics = json.loads((folder / "normalization.json").read_text())
    local_size = FleetVecEnv(
        "bench_mild", base_policy="nn_dsc", num_fleets=1
    ).observation_space.shape[0]
    assert len(statistics["mean"]) == local_size  # the actor's inputs only
    policy = load_policy(folder)
    sim = FleetSim(policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[5, 6])
    assert np.all(np.isfinite(policy.act_batch(obs)))
    # the trained model's actor (SB3's own load of the model.zip this test wrote) on the same
    # inputs, normalized by hand, with any unobserved state appended: the folder's actor
    venv = make_env(config, num_fleets=2)
    controller = ResidualController(
        policy.scenario, make_policy("nn_dsc", policy.scenario), 2, venv.controller.config
    )
    inputs = controller.observe(obs).reshape(10, -1).astype(np.float32)
    mean, var = np.array(statistics["mean"]), np.array(statistics["var"])
    normalized = np.clip((inputs - mean) / np.sqrt(var + 1e-8), -10.0, 10.0).astype(np.float32)
    hidden = np.random.default_rng(1).normal(size=(10, UNOBSERVED_SIZE)).astype(np.float32)
    model = PPO.load(folder / "model.zip", device="cpu")
    action = _predict(model, np.concatenate([normalized, hidden], axis=1))
    assert np.abs(action).max() > 0  # trained away from the zero start
    np.testing.assert_array_equal(policy.actor(inputs), action)


def test_fine_tuning_a_student_with_an_asymmetric_critic_starts_from_the_student(
    tmp_path: Path,
) -> None:
    own = json.loads((STUDENT / "config.json").read_text())["config"]
    recipe = {k: own[k] for k in ("encoder", "history", "shared_slot_statistics")}
    config = TrainConfig(
        scenario="bench_saturation", base_policy="mpc",
        residual=ResidualConfig(scale=0.5, neighbour_slots=6),
        net_arch=(64, 64), fleets=1, n_steps=8, batch_size=40, n_epochs=1, torch_threads=1,
        timesteps=80, asymmetric_critic=True, **recipe,
    )  # fmt: skip
    run = TrainingRun(
        config, tmp_path, RunSchedule(), None, None, None,
        init_from=read_init_source(STUDENT, config),
    )  # fmt: skip
    assert isinstance(run.env, VecNormalize)
    normalized = run.env.reset()  # statistics frozen: the folder's, the hidden columns unscaled
    raw = run.env.get_original_obs().astype(np.float32)
    columns = unobserved_columns(run.model)
    np.testing.assert_array_equal(
        normalized[:, columns.start : columns.stop], raw[:, columns.start : columns.stop]
    )
    ppo = _predict(run.model, normalized)
    local = np.delete(raw, list(columns), axis=1)
    loaded = load_policy(STUDENT, scenario="bench_saturation").actor(local)
    np.testing.assert_array_equal(ppo, loaded)


def test_cpf_train_takes_the_asymmetric_critic_and_refuses_it_for_sac(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert TrainConfig(asymmetric_critic=True).asymmetric_critic
    with pytest.raises(ValueError, match="asymmetric_critic is implemented for PPO"):
        TrainConfig(algo="sac", asymmetric_critic=True)
    with pytest.raises(ValueError, match="asymmetric_critic must be true or false"):
        TrainConfig(asymmetric_critic=1)  # type: ignore[arg-type]
    argv = ["--algo", "sac", "--set", "asymmetric_critic=true", "--out", str(tmp_path / "x")]
    with pytest.raises(SystemExit):
        train_main(argv)
    assert "asymmetric_critic is implemented for PPO" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_an_asymmetric_encoder_and_history_run_writes_a_folder_of_the_actors_inputs(
    tmp_path: Path,
) -> None:
    actor = {"encoder": "deepsets", "shared_slot_statistics": True, "history": 2}
    config = TrainConfig(
        scenario="bench_mild",
        timesteps=320,
        seed=3,
        asymmetric_critic=True,
        **TINY,
        **actor,  # type: ignore[arg-type]
    )
    folder = train(config, tmp_path / "run", progress=False)
    plain = TrainConfig(scenario="bench_mild", timesteps=320, seed=3, **TINY, **actor)  # type: ignore[arg-type]
    (tmp_path / "plain").mkdir()
    run = _run(plain, tmp_path / "plain")  # the same actor without the critic's columns
    statistics = json.loads((folder / "normalization.json").read_text())
    assert len(statistics["mean"]) == run.env.observation_space.shape[0]
    policy = load_policy(folder, scenario="bench_switching")  # another degree: the encoder
    sim = FleetSim(policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[1, 2])
    for _ in range(5):
        obs = sim.step(policy.act_batch(obs))
    assert np.all(np.isfinite(obs))
