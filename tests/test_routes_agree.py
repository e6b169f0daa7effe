"""Every route, with its default arguments, plays the same episodes of the same scenario and seeds.

The routes stand on one episode core (``cpf_env.envs.core``): seeding (fleet k
gets seed + k), horizons and stagger, per-fleet resets, the residual. Here
each route is stepped for 300 control steps (about eight episodes of 40 steps
per fleet) with its own defaults: the learning routes (``FleetVecEnv``,
``MixtureVecEnv``'s groups, the TorchRL env by name) in the residual form on
``nn_dsc`` with a zero correction, the env routes (ParallelEnv, the Gymnasium
vector view) in the raw form driven by ``nn_dsc`` itself. A zero correction
reproduces the base policy bit for bit, so every route must show the same
episodes: the same reset observations, the same (staggered) lengths, the same
trajectories and the same ends, bit for bit.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import cpf_env
from agents import FleetVecEnv, MixtureVecEnv
from baselines import make_policy
from cpf_env.envs.gym_envs import CentralizedFleetVectorEnv

SCENARIO, FLEETS, SEED, STEPS, MAX_STEPS = "bench_lossy_links", 3, 11, 300, 40

#: An episode: its observations (length + 1, n, obs_dim) and whether it terminated.
Episode = tuple[np.ndarray, bool]


class Recorder:
    """Each fleet's finished episodes, from the observations a route returns."""

    def __init__(self, first: np.ndarray) -> None:
        self.current: list[list[np.ndarray]] = [[row.copy()] for row in first]
        self.done: list[list[Episode]] = [[] for _ in first]

    def add(self, fleet: int, obs: np.ndarray) -> None:
        self.current[fleet].append(obs.copy())

    def end(self, fleet: int, terminated: bool, reset_obs: np.ndarray) -> None:
        self.done[fleet].append((np.stack(self.current[fleet]), terminated))
        self.current[fleet] = [reset_obs.copy()]


def fleet_vec_env() -> list[list[Episode]]:
    env = FleetVecEnv(SCENARIO, FLEETS, max_steps=MAX_STEPS)
    env.seed(SEED)
    n = env.n
    record = Recorder(env.reset().reshape(FLEETS, n, -1))
    zero = np.zeros((env.num_envs, env.action_space.shape[0]), np.float32)
    for _ in range(STEPS):
        obs, _rewards, dones, infos = env.step(zero)
        obs = obs.reshape(FLEETS, n, -1)
        for k in range(FLEETS):
            if dones[k * n]:
                slots = infos[k * n : (k + 1) * n]
                record.add(k, np.stack([info["terminal_observation"] for info in slots]))
                record.end(k, not slots[0]["TimeLimit.truncated"], obs[k])
            else:
                record.add(k, obs[k])
    return record.done


def mixture_group() -> list[list[Episode]]:
    """The first group of a mixture: fleets 0 .. 2 of bench_lossy_links, seeds SEED + k."""
    env = MixtureVecEnv(
        [SCENARIO, "bench_mild"],
        2 * FLEETS,
        scenario_overrides=[{"max_steps": MAX_STEPS}] * 2,
    )
    env.seed(SEED)
    n, width = env.groups[0].n, env.groups[0].num_envs
    record = Recorder(env.reset()[:width].reshape(FLEETS, n, -1))
    zero = np.zeros((env.num_envs, env.action_space.shape[0]), np.float32)
    for _ in range(STEPS):
        obs, _rewards, dones, infos = env.step(zero)
        obs = obs[:width].reshape(FLEETS, n, -1)
        for k in range(FLEETS):
            if dones[k * n]:
                slots = infos[k * n : (k + 1) * n]
                record.add(k, np.stack([info["terminal_observation"] for info in slots]))
                record.end(k, not slots[0]["TimeLimit.truncated"], obs[k])
            else:
                record.add(k, obs[k])
    return record.done


def gym_vector_env() -> list[list[Episode]]:
    env = CentralizedFleetVectorEnv(SCENARIO, FLEETS, max_steps=MAX_STEPS)
    policy = make_policy("nn_dsc", env.scenario)
    obs, _ = env.reset(seed=SEED)
    n = env.scenario.n
    obs = obs.reshape(FLEETS, n, -1)
    record, restart = Recorder(obs), np.zeros(FLEETS, dtype=bool)
    for _ in range(STEPS):
        actions = policy.act_batch(obs).reshape(FLEETS, -1)
        flat, _rewards, terminated, truncated, _ = env.step(actions)
        obs = flat.reshape(FLEETS, n, -1)
        if restart.any():  # NEXT_STEP autoreset: these fleets were just reset
            policy.reset_fleets(restart)
        for k in range(FLEETS):
            if restart[k]:
                record.current[k] = [obs[k].copy()]
            else:
                record.add(k, obs[k])
                if terminated[k] or truncated[k]:
                    record.done[k].append((np.stack(record.current[k]), bool(terminated[k])))
        restart = terminated | truncated
    return record.done


def torchrl_env() -> list[list[Episode]]:
    import torch

    from agents.marl.envs import make_env
    from cpf_env.envs.torchrl_env import GROUP

    env = make_env(SCENARIO, FLEETS, seed=SEED, max_steps=MAX_STEPS)
    td = env.reset()
    record = Recorder(td[GROUP, "observation"].numpy())
    zero = torch.zeros(env.full_action_spec[GROUP, "action"].shape)
    for _ in range(STEPS):
        out, td = env.step_and_maybe_reset(td.set((GROUP, "action"), zero))
        last, done = out["next", GROUP, "observation"].numpy(), out["next", "done"].numpy()
        terminated = out["next", "terminated"].numpy()
        for k in range(FLEETS):
            record.add(k, last[k])
            if done[k, 0]:
                record.end(k, bool(terminated[k, 0]), td[GROUP, "observation"][k].numpy())
    return record.done


def parallel_env_fleet(fleet: int, episodes: int) -> list[Episode]:
    """Fleet k's episodes on the ParallelEnv (one fleet, no stagger), reset with seed SEED + k."""
    env = cpf_env.parallel_env(SCENARIO, max_steps=MAX_STEPS)
    policy = make_policy("nn_dsc", env.scenario)
    found: list[Episode] = []
    for e in range(episodes):
        observations, _ = env.reset(seed=SEED + fleet if e == 0 else None)
        policy.reset()
        trajectory = [np.stack(list(observations.values()))]
        terminated = False
        while env.agents:
            observations, _r, terminations, _t, _i = env.step(policy.act(observations))
            trajectory.append(np.stack(list(observations.values())))
            terminated = any(terminations.values())
        found.append((np.stack(trajectory), terminated))
    return found


def assert_same_episodes(expected: list[list[Episode]], got: list[list[Episode]]) -> None:
    """The same episodes, as many as both finished (Gymnasium's autoreset takes a step each)."""
    for k in range(FLEETS):
        common = min(len(got[k]), len(expected[k]))
        assert common >= 6, f"fleet {k}: only {common} episodes finished"
        for (obs, ended), (obs_got, ended_got) in zip(
            expected[k][:common], got[k][:common], strict=True
        ):
            assert obs.shape == obs_got.shape  # same resets, same horizon
            assert np.array_equal(obs, obs_got) and ended == ended_got


@pytest.fixture(scope="module")
def reference() -> list[list[Episode]]:
    return fleet_vec_env()


def test_the_batched_routes_stagger_alike(reference: list[list[Episode]]) -> None:
    # fleet k's first episode ends after max_steps - k * max_steps // B steps; then full ones
    for k in range(FLEETS):
        lengths = [len(obs) - 1 for obs, terminated in reference[k] if not terminated]
        assert lengths[0] == MAX_STEPS - k * MAX_STEPS // FLEETS
        assert set(lengths[1:]) == {MAX_STEPS}
        assert len(reference[k]) >= 6


def test_the_gymnasium_vector_view_plays_the_same_episodes(
    reference: list[list[Episode]],
) -> None:
    assert_same_episodes(reference, gym_vector_env())


def test_a_mixture_group_plays_the_same_episodes(reference: list[list[Episode]]) -> None:
    assert_same_episodes(reference, mixture_group())


@pytest.mark.torchrl
def test_the_torchrl_env_plays_the_same_episodes(reference: list[list[Episode]]) -> None:
    if importlib.util.find_spec("torchrl") is None:
        pytest.skip("needs the torchrl extra")
    assert_same_episodes(reference, torchrl_env())


def test_the_parallel_env_plays_each_fleets_episodes(reference: list[list[Episode]]) -> None:
    for k in range(FLEETS):
        single = parallel_env_fleet(k, len(reference[k]))
        for (obs, ended), (obs_single, ended_single) in zip(reference[k], single, strict=True):
            # one fleet is never staggered: the batched fleet's episode is a prefix of it
            assert np.array_equal(obs, obs_single[: len(obs)])
            if len(obs) == len(obs_single):
                assert ended == ended_single
