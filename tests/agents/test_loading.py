"""load_policy of an encoder agent with a history: any number of slots, the history kept."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from test_mixture_env import fleet_of

from agents import FleetVecEnv, TrainConfig, load_policy, train
from agents.envs.history_env import HistoryVecEnv
from agents.folder.loading import TrainedPolicy
from agents.training.algorithms import build_model
from baselines import make_policy
from cpf_env import FleetSim, scenarios
from cpf_env.envs.residual import ResidualConfig
from cpf_env.model.graph import Graph

H = 3
#: Trained on bench_mild's chain padded to 6 slots, with a history of 3 entries.
CONFIG = TrainConfig(
    scenario="bench_mild",
    fleets=2,
    timesteps=64,
    n_steps=16,
    batch_size=32,
    n_epochs=1,
    net_arch=(16,),
    encoder="deepsets",
    history=H,
    residual=ResidualConfig(neighbour_slots=6),
    shared_slot_statistics=True,
    torch_threads=1,
)


@pytest.fixture(scope="module")
def agent(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny encoder agent with a history, trained by ``train`` (cpf-train's route)."""
    torch.manual_seed(0)
    return train(CONFIG, tmp_path_factory.mktemp("encoder") / "agent", progress=False)


def _recording(policy: TrainedPolicy) -> list[np.ndarray]:
    """Record the actor's actions (R, a) at each ``act_batch``."""
    actions: list[np.ndarray] = []
    actor = policy.actor

    class Recorder:
        input_size, action_size = actor.input_size, actor.action_size

        def __call__(self, rows: np.ndarray) -> np.ndarray:
            actions.append(actor(rows))
            return actions[-1]

    policy.actor = Recorder()
    return actions


def test_the_folder_is_version_3_and_describes_the_actor(agent: Path) -> None:
    manifest = json.loads((agent / "manifest.json").read_text())
    record = json.loads((agent / "config.json").read_text())
    assert (manifest["format_version"], manifest["trainer"]) == (3, "sb3")
    # own 18, 6 slots of 4; tail: 3 entries of (18 own + 3 actions + 1 valid)
    assert record["actor"] == {
        "encoder": "deepsets",
        "history": H,
        "pooling": "mean",
        "hidden": 32,
        "slot_size": 4,
        "slots": 6,
        "tail": H * 22,
    }
    statistics = json.loads((agent / "normalization.json").read_text())
    assert len(statistics["mean"]) == 18 + 6 * 4 + H * 22
    weights = statistics["mean"][18 : 18 + 24 : 4], statistics["var"][18 : 18 + 24 : 4]
    assert weights == ([0.0] * 6, [1.0] * 6)  # a_ij kept raw: an empty slot stays 0


def _compare_with_sb3(
    folder: Path, config: TrainConfig, steps: int, max_steps: int, gain: float
) -> tuple[int, np.ndarray]:
    """Step load_policy's policy beside SB3's predict inside ``HistoryVecEnv``: equal bits.

    SB3's PPO is rebuilt from the folder's weights (no pickle read; the output layer
    scaled by ``gain`` in both, so the actions are large and the history matters); it
    acts on ``HistoryVecEnv``'s inputs, normalized by ``VecNormalize``'s formula written
    out here. The loaded policy sees only the simulator's raw observations and keeps
    the history itself, reset on the fleets whose episode ended.

    Returns:
        The episode ends crossed, and every action (steps x R, a).
    """
    policy = load_policy(folder)
    network = policy.actor.network  # type: ignore[attr-defined]
    statistics = json.loads((folder / "normalization.json").read_text())
    mean, var = np.array(statistics["mean"]), np.array(statistics["var"])
    base = FleetVecEnv(
        config.home_scenario,
        num_fleets=2,
        base_policy=config.base_policy,
        residual=config.residual,
        max_steps=max_steps,  # staggered: fleet 1 restarts after max_steps / 2 steps
    )
    env = HistoryVecEnv(base, config.history)
    model = build_model(dataclasses.replace(config, batch_size=32), env)
    assert isinstance(model, PPO)
    if network.encoder is not None:
        extractor: Any = model.policy.pi_features_extractor
        extractor.encoder.load_state_dict(network.encoder.state_dict())
    layers = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        network.output.weight.mul_(gain)
        for mine, theirs in zip(network.hidden, layers, strict=True):
            theirs.weight.copy_(mine.weight)
            theirs.bias.copy_(mine.bias)
        model.policy.action_net.weight.copy_(network.output.weight)
        model.policy.action_net.bias.copy_(network.output.bias)
    base.seed(5)
    obs = env.reset()
    recorded = _recording(policy)
    ended = 0
    for _ in range(steps):
        raw = base.core.sim.arrays.obs.copy()
        policy.act_batch(raw)
        normalized = np.clip((obs - mean) / np.sqrt(var + 1e-8), -10.0, 10.0).astype(np.float32)
        expected, _ = model.predict(normalized, deterministic=True)
        np.testing.assert_array_equal(recorded[-1], expected)
        obs, _, dones, _ = env.step(expected)
        restarted = dones.reshape(2, -1).any(axis=1)
        policy.reset_fleets(restarted)
        ended += int(restarted.sum())
    return ended, np.concatenate(recorded)


def test_actions_equal_sb3_inside_history_vec_env_bit_for_bit(agent: Path) -> None:
    """300 steps of 2 fleets through auto-resets (the 64-step agent's output x 50)."""
    ended, actions = _compare_with_sb3(agent, CONFIG, steps=300, max_steps=100, gain=50.0)
    assert ended >= 6  # several episode ends of both fleets crossed
    assert np.abs(actions).max() > 0.1  # the actions are not all zero


def test_an_mlp_with_history_acts_as_sb3_inside_history_vec_env(tmp_path: Path) -> None:
    """A version-2 MLP (no encoder) with 2 history entries: 50 steps, 4 episode ends."""
    from test_agent_folder import HISTORY_CONFIG, write_history_mlp

    folder = tmp_path / "mlp"
    write_history_mlp(folder)
    ended, actions = _compare_with_sb3(folder, HISTORY_CONFIG, steps=50, max_steps=20, gain=1.0)
    assert ended >= 4
    assert np.abs(actions).max() > 0.1


def test_the_history_is_kept_and_cleared_on_reset(agent: Path) -> None:
    policy = load_policy(agent)
    sim = FleetSim(policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    first = policy.act_batch(obs)
    assert policy._history is not None
    entries = policy._history.entries
    assert np.all(entries[:, 0, -1] == 1.0) and np.all(entries[:, 1:] == 0.0)
    sim.step(first)
    policy.act_batch(sim.arrays.obs)
    assert np.all(policy._history.entries[:, :2, -1] == 1.0)
    policy.reset_fleets(np.array([False, True]))  # fleet 1 restarts: its 5 vessels' rows
    valid = policy._history.entries[:, :, -1]
    assert np.all(valid[5:] == 0.0) and np.all(valid[:5, :2] == 1.0)
    policy.reset()
    again = policy.act_batch(sim.reset(seeds=[0, 1]))
    np.testing.assert_array_equal(again, first)  # a reset policy acts as a fresh one


def _inputs_recorded(policy: TrainedPolicy) -> list[np.ndarray]:
    """Record the raw inputs (R, k) the policy gives its actor at each ``act_batch``."""
    rows: list[np.ndarray] = []
    actor = policy.actor

    class Recorder:
        input_size, action_size = actor.input_size, actor.action_size

        def __call__(self, inputs: np.ndarray) -> np.ndarray:
            rows.append(inputs.copy())
            return actor(inputs)

    policy.actor = Recorder()
    return rows


def test_a_six_slot_agent_reads_all_nine_slots_of_a_ten_vessel_star(agent: Path) -> None:
    """The star's centre has 9 neighbours: the encoder reads them all, the 7th to 9th too."""
    star = fleet_of(10, Graph.star(10, center=4, leaders=(4,)))
    policy = load_policy(agent, scenario=star)
    actor: Any = policy.actor
    with torch.no_grad():
        actor.network.output.weight.mul_(50.0)  # a 64-step agent barely moved: larger actions
    seen = _inputs_recorded(policy)
    sim = FleetSim(star, num_fleets=1)
    obs = sim.reset(seeds=[0])
    for _ in range(5):
        command = policy.act_batch(obs)
        assert command.shape == (1, 10, 5) and np.all(np.isfinite(command))
        obs = sim.step(command)
    assert policy._residual.neighbour_slots == 9  # the learner's slots; the base's unchanged
    assert load_policy(agent)._residual.neighbour_slots == 6
    centre = seen[-1][4:5]
    assert centre.shape == (1, 18 + 9 * 4 + H * 22)
    assert np.all(centre[0, 18 : 18 + 9 * 4 : 4] != 0.0)  # nine neighbours: no empty slot
    action = actor(centre)
    for slot in (6, 7, 8):  # beyond the 6 slots of training
        changed = centre.copy()
        changed[0, 18 + 4 * slot + 1] += 0.5  # that neighbour's theta_j - theta_i
        assert np.abs(actor(changed) - action).max() > 1e-4, slot


def test_empty_slots_added_to_an_input_leave_the_action_unchanged(agent: Path) -> None:
    """bench_mild's inputs (6 slots) padded with 3 empty ones: the same actions to rounding."""
    policy = load_policy(agent)
    actor: Any = policy.actor
    with torch.no_grad():
        actor.network.output.weight.mul_(50.0)
    seen = _inputs_recorded(policy)
    sim = FleetSim(policy.scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(5):
        obs = sim.step(policy.act_batch(obs))
    rows = seen[-1]
    body = 18 + 6 * 4
    padded = np.concatenate([rows[:, :body], np.zeros((len(rows), 3 * 4)), rows[:, body:]], axis=1)
    action = actor(rows)
    assert np.abs(action).max() > 0.1
    np.testing.assert_allclose(actor(padded.astype(np.float32)), action, rtol=0, atol=1e-6)


def test_loading_an_agent_folder_imports_no_learning_algorithm(agent: Path) -> None:
    """Agent folders are read and run with torch and numpy only, in one fresh process.

    An encoder agent with a history, the committed MLP agent and a BenchMARL actor.
    """
    import os
    import subprocess
    import sys

    from conftest import ROOT

    mlp = ROOT / "tests/fixtures/agents/residual_ppo_lossy_links"
    marl = ROOT / "tests/fixtures/agents/mappo_lossy_links"
    code = (
        "import sys\n"
        "from agents import load_policy\n"
        f"load_policy({str(agent)!r}).act_batch\n"
        f"load_policy({str(mlp)!r}).act_batch\n"
        f"load_policy({str(marl)!r}).act_batch\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'stable_baselines3'\n"
        "    or m in ('agents.training.trainer', 'agents.training.algorithms',\n"
        "             'agents.envs.history_env', 'agents.training.run_folder',\n"
        "             'agents.envs.mixture_env', 'agents.envs.vec_env')))\n"
    )
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=environment, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_an_encoder_agent_on_another_message_size_is_refused(agent: Path) -> None:
    other = scenarios.get("bench_mild").replace(message_size=2)
    with pytest.raises(ValueError, match="slots of 4 floats but scenario 'bench_mild' gives 5"):
        load_policy(agent, scenario=other)


def test_an_sb3_agent_with_learned_messages_broadcasts_them_after_its_base(tmp_path: Path) -> None:
    """cpf-train's route: five entries after nn_dsc's one, learned, saved and sent."""
    config = TrainConfig(
        scenario="hard_crossing",  # m = 6
        base_policy="nn_dsc",
        residual={"mode": "force_and_rate", "messages": 5},  # type: ignore[arg-type]
        timesteps=64, fleets=1, n_steps=16, batch_size=64, n_epochs=1, torch_threads=1,
    )  # fmt: skip
    folder = train(config, tmp_path / "agent", False)
    policy = load_policy(folder)
    assert policy.config.residual.messages == 5 and policy.message_entries == 6
    sim, alone = FleetSim(policy.scenario), FleetSim(policy.scenario)
    base = make_policy("nn_dsc", policy.scenario)
    obs, plain = sim.reset(seeds=[3]), alone.reset(seeds=[3])
    policy.reset()
    actions, expected = policy.act_batch(obs), base.act_batch(plain)
    assert np.array_equal(actions[..., 4], expected[..., 4])  # the base's speed estimate
    assert np.any(actions[..., 5:] != 0.0) and np.all(np.abs(actions[..., 5:]) <= 1.0)
    sim.step(actions)
    assert np.array_equal(sim.arrays.message[..., 1:], actions[..., 5:])
