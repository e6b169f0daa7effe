"""OwnHistory, HistoryVecEnv: the entries are the own past; nothing crosses an episode end."""

from __future__ import annotations

import numpy as np
import pytest

from agents import FleetVecEnv
from agents.envs.history import OwnHistory
from agents.envs.history_env import HistoryVecEnv
from cpf_env.sim.observation import SLOTS

H = 3


def _env(max_steps: int = 6) -> HistoryVecEnv:
    # two fleets, staggered: fleet 1's first episode ends after 3 steps, fleet 0's after 6
    venv = FleetVecEnv("wang2014", num_fleets=2, max_steps=max_steps)
    venv.seed(0)
    return HistoryVecEnv(venv, length=H)


def _step(
    env: HistoryVecEnv, actions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    obs, rewards, dones, infos = env.step(actions)
    assert isinstance(obs, np.ndarray)
    return obs, rewards, dones, infos


def _history(env: HistoryVecEnv, obs: np.ndarray) -> np.ndarray:
    raw = obs.shape[1] - env.history.size
    return obs[:, raw:].reshape(obs.shape[0], H, env.history.entry_size)


def test_entries_are_the_last_observations_and_actions_newest_first() -> None:
    env = _env(max_steps=50)
    obs = env.reset()
    raw_size = obs.shape[1] - env.history.size
    assert np.all(_history(env, obs) == 0.0)
    rng = np.random.default_rng(0)
    seen, taken = [], []
    for _ in range(4):
        actions = rng.uniform(-1, 1, (env.num_envs, env.history.action_size)).astype(np.float32)
        seen.append(obs[:, :SLOTS].copy())
        taken.append(actions)
        obs, _, dones, _ = _step(env, actions)
        assert not dones.any()
    history = _history(env, obs)
    for k in range(H):  # entry k holds step t - 1 - k
        np.testing.assert_array_equal(history[:, k, :SLOTS], seen[-1 - k])
        np.testing.assert_array_equal(history[:, k, SLOTS:-1], taken[-1 - k])
        assert np.all(history[:, k, -1] == 1.0)
    assert obs.shape == (env.num_envs, raw_size + H * (SLOTS + env.history.action_size + 1))
    assert env.observation_space.contains(obs[0])


def test_no_history_crosses_an_episode_end() -> None:
    env = _env()
    n = env.num_envs // 2
    obs = env.reset()
    actions = np.full((env.num_envs, env.history.action_size), 0.25, dtype=np.float32)
    for step in range(1, 4):  # noqa: B007 (the last step is checked below)
        before = obs
        obs, _, dones, infos = _step(env, actions)
    assert step == 3 and dones[n:].all() and not dones[:n].any()
    # fleet 1 restarted: empty history; fleet 0 runs on with three valid entries
    assert np.all(_history(env, obs)[n:] == 0.0)
    assert np.all(_history(env, obs)[:n, :, -1] == 1.0)
    for slot in range(n, 2 * n):
        terminal = infos[slot]["terminal_observation"]
        assert terminal.shape == obs.shape[1:]
        entries = _history(env, terminal[None])[0]
        np.testing.assert_array_equal(entries[0, :SLOTS], before[slot, :SLOTS])
        np.testing.assert_array_equal(entries[0, SLOTS:-1], actions[slot])
        assert np.all(entries[:, -1] == 1.0)
    obs, _, dones, _ = _step(env, actions)
    history = _history(env, obs)
    assert np.all(history[n:, 0, -1] == 1.0) and np.all(history[n:, 1:] == 0.0)


def test_bad_arguments_are_refused() -> None:
    venv = FleetVecEnv("wang2014", num_fleets=1, max_steps=6)
    with pytest.raises(ValueError, match="integer >= 1"):
        HistoryVecEnv(venv, length=0)
    with pytest.raises(ValueError, match="own must be"):
        HistoryVecEnv(venv, length=2, own=1000)


def test_own_history_pushes_newest_first_and_clears_the_rows_given() -> None:
    history = OwnHistory(rows=3, length=2, own=2, action_size=1)
    for step in (1.0, 2.0):
        inputs = np.full((3, 4), step, dtype=np.float32)
        history.push(inputs, np.full((3, 1), -step, dtype=np.float32))
    np.testing.assert_array_equal(history.entries[0], [[2, 2, -2, 1], [1, 1, -1, 1]])
    history.clear(np.array([False, True, False]))
    assert np.all(history.entries[1] == 0.0) and np.all(history.entries[[0, 2], :, -1] == 1.0)
    assert history.append_to(np.zeros((3, 4))).shape == (3, 4 + 2 * 4)
    with pytest.raises(ValueError, match="own and action_size must be >= 1"):
        OwnHistory(rows=1, length=1, own=0)
