"""Every route plays the same episodes of the same scenario, seeds and base policy.

The routes stand on one episode core (``cpf_env.envs.core``): seeding (fleet k
gets seed + k), horizons and stagger, per-fleet resets, the residual. Here
each route is stepped for 300 control steps (about eight episodes of 40 steps
per fleet) with its own defaults but for the base policy: the learning routes
(``FleetVecEnv``, ``MixtureVecEnv``'s groups, the TorchRL env by name) in the
residual form on ``nn_dsc`` with a zero correction, the env routes (ParallelEnv, the Gymnasium
vector view) in the raw form driven by ``nn_dsc`` itself. A zero correction
reproduces the base policy bit for bit, so every route must show the same
episodes: the same reset observations, the same (staggered) lengths, the same
trajectories and the same ends, bit for bit.
"""

from __future__ import annotations

import dataclasses
import importlib.util
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import cpf_env
from agents import FleetVecEnv, MixtureVecEnv
from baselines import make_policy
from cpf_env.envs.gym_envs import CentralizedFleetEnv, CentralizedFleetVectorEnv

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
    env = FleetVecEnv(SCENARIO, FLEETS, base_policy="nn_dsc", max_steps=MAX_STEPS)
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
        base_policy="nn_dsc",
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


def torchrl_env(env: Any = None) -> list[list[Episode]]:
    """``agents.marl.make_env`` on ``nn_dsc`` (or the given TorchRL env of the same)."""
    import torch

    from agents.marl.envs import make_env
    from cpf_env.envs.torchrl_env import GROUP

    if env is None:
        env = make_env(SCENARIO, FLEETS, "nn_dsc", seed=SEED, max_steps=MAX_STEPS)
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


def parallel_env_fleet(
    fleet: int, episodes: int, make: Callable[[], Any] | None = None
) -> list[Episode]:
    """Fleet k's episodes on the ParallelEnv (one fleet, no stagger), reset with seed SEED + k."""
    env = cpf_env.parallel_env(SCENARIO, max_steps=MAX_STEPS) if make is None else make()
    policy = make_policy("nn_dsc", SCENARIO)
    found: list[Episode] = []
    for e in range(episodes):
        observations, _ = env.reset(seed=SEED + fleet if e == 0 else None)
        policy.reset()
        trajectory = [np.stack([observations[a] for a in policy.agents])]
        terminated = done = False
        while not done:
            observations, _r, terminations, truncations, _i = env.step(policy.act(observations))
            trajectory.append(np.stack([observations[a] for a in policy.agents]))
            terminated = terminations["vessel_0"]
            done = terminated or truncations["vessel_0"]
        found.append((np.stack(trajectory), terminated))
    return found


def aec_fleet(fleet: int, episodes: int) -> list[Episode]:
    """Fleet k's episodes on the AEC form (``cpf_env.env``), agents acting in turn."""
    env = cpf_env.env(SCENARIO, max_cycles=MAX_STEPS)
    policy = make_policy("nn_dsc", SCENARIO)
    found: list[Episode] = []
    for e in range(episodes):
        env.reset(seed=SEED + fleet if e == 0 else None)
        policy.reset()
        observe = lambda: {a: env.observe(a) for a in policy.agents}  # noqa: E731
        trajectory, done, terminated = [np.stack(list(observe().values()))], False, False
        while not done:
            actions = policy.act(observe())
            for agent in env.agent_iter(len(env.agents)):  # one turn each, then the fleet steps
                env.step(actions[agent])
            trajectory.append(np.stack(list(observe().values())))
            _o, _r, terminated, truncated, _i = env.last()
            done = terminated or truncated
        found.append((np.stack(trajectory), bool(terminated)))
    return found


def gym_single_fleet(fleet: int, episodes: int) -> list[Episode]:
    """Fleet k's episodes on ``CentralizedFleetEnv`` (one fleet), reset with seed SEED + k."""
    env = CentralizedFleetEnv(SCENARIO, max_steps=MAX_STEPS)
    policy = make_policy("nn_dsc", SCENARIO)
    shape = (env.scenario.n, -1)
    found: list[Episode] = []
    for e in range(episodes):
        obs, _ = env.reset(seed=SEED + fleet if e == 0 else None)
        policy.reset()
        trajectory, done, terminated = [obs.reshape(shape)], False, False
        while not done:
            action = policy.act_batch(obs.reshape(1, *shape)).reshape(-1)
            obs, _r, terminated, truncated, _i = env.step(action)
            trajectory.append(obs.reshape(shape))
            done = terminated or truncated
        found.append((np.stack(trajectory), terminated))
    return found


def assert_prefixes(reference: list[list[Episode]], single: Callable[[int, int], Any]) -> None:
    """Each fleet's batched episodes are prefixes of a one-fleet route's (never staggered)."""
    for k in range(FLEETS):
        episodes = single(k, len(reference[k]))
        for (obs, ended), (obs_single, ended_single) in zip(reference[k], episodes, strict=True):
            assert np.array_equal(obs, obs_single[: len(obs)])
            if len(obs) == len(obs_single):
                assert ended == ended_single


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


def test_the_one_fleet_routes_play_each_fleets_episodes(reference: list[list[Episode]]) -> None:
    assert_prefixes(reference, parallel_env_fleet)
    assert_prefixes(reference, aec_fleet)
    assert_prefixes(reference, gym_single_fleet)


@pytest.mark.benchmarl
def test_the_benchmarl_task_plays_the_same_episodes(reference: list[list[Episode]]) -> None:
    """The task's env with the task config's defaults (unnormalized inputs, to compare)."""
    pytest.importorskip("benchmarl")
    from agents.marl.tasks import CpfTask, CpfTaskConfig

    config = CpfTaskConfig(scenario=SCENARIO, max_steps=MAX_STEPS, normalize=False)
    task = CpfTask.BENCH_LOSSY_LINKS.get_task(config=dataclasses.asdict(config))
    env = task.get_env_fun(FLEETS, True, SEED, "cpu")()
    assert_same_episodes(reference, torchrl_env(env))


@pytest.mark.ray
def test_the_rllib_glue_plays_each_fleets_episodes(reference: list[list[Episode]]) -> None:
    """``examples/rllib_ppo.py``'s env creator: the ParallelEnv in RLlib's wrapper."""
    pytest.importorskip("ray.rllib")
    from conftest import ROOT

    spec = importlib.util.spec_from_file_location("rllib_ppo", ROOT / "examples" / "rllib_ppo.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def make() -> Any:
        return module.make_rllib_env({"scenario": SCENARIO, "max_steps": MAX_STEPS})

    assert_prefixes(reference, lambda k, count: parallel_env_fleet(k, count, make))


def test_every_route_has_one_base_policy_default_and_one_rule_for_names() -> None:
    """The base policy defaults to None everywhere; the env layer refuses a name alike."""
    import inspect

    from agents.envs.resolve import make_core
    from cpf_env.envs.gym_envs import CentralizedFleetEnv
    from cpf_env.envs.parallel import CooperativePathFollowingEnv

    routes = [FleetVecEnv, MixtureVecEnv, make_core, CooperativePathFollowingEnv]
    routes += [CentralizedFleetEnv, CentralizedFleetVectorEnv]
    if importlib.util.find_spec("torchrl") is not None:
        from agents.marl.envs import make_env
        from cpf_env.envs.torchrl_env import TorchRLFleetEnv

        routes += [make_env, TorchRLFleetEnv]
    for route in routes:  # a class's own __init__: TorchRL's env metaclass hides it behind *args
        signature = inspect.signature(route.__init__ if isinstance(route, type) else route)
        assert signature.parameters["base_policy"].default is None, route
    env_layer = [
        lambda: cpf_env.parallel_env(SCENARIO, base_policy="nn_dsc"),
        lambda: CentralizedFleetEnv(SCENARIO, base_policy="nn_dsc"),
        lambda: CentralizedFleetVectorEnv(SCENARIO, 2, base_policy="nn_dsc"),
    ]
    for build in env_layer:
        with pytest.raises(TypeError, match=r"'nn_dsc' is a name.*baselines.make_policy"):
            build()
    from baselines.nn_dsc import NNDSCPolicy

    assert isinstance(FleetVecEnv(SCENARIO, 2, base_policy="nn_dsc").controller.base, NNDSCPolicy)
