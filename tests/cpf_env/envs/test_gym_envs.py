"""Gymnasium views: API checks, registration, autoreset, single vs vector bit for bit."""

from __future__ import annotations

import warnings
from collections.abc import Callable

import gymnasium
import numpy as np
import pettingzoo
import pytest
from conftest import assert_unchanged, snapshot
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import cpf_env
from cpf_env.envs.gym_envs import (
    GYM_ID,
    PETTINGZOO_ID,
    CentralizedFleetEnv,
    CentralizedFleetVectorEnv,
    register_envs,
    scenario_id,
)

IDS = [GYM_ID] + [scenario_id(name) for name in cpf_env.scenarios.list_scenarios()]
# Inherent to the design: physical action bounds (N, N m, 1/s), and check_env on a wrapped env.
EXPECTED_WARNINGS = ("symmetric and normalized space", "different from the unwrapped version")


def random_actions(space: gymnasium.spaces.Box, rng: np.random.Generator) -> np.ndarray:
    """Uniform actions over 1.2 x the bounds (exercises saturation and clipping)."""
    return (1.2 * rng.uniform(space.low, space.high)).astype(np.float32)


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes_every_id(env_id: str) -> None:
    for unwrapped in (True, False):
        env = gymnasium.make(env_id)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped if unwrapped else env)
        env.close()
        unexpected = [
            str(w.message)
            for w in caught
            if not any(e in str(w.message) for e in EXPECTED_WARNINGS)
        ]
        assert not unexpected


def test_make_passes_kwargs_and_truncates_itself() -> None:
    env = gymnasium.make(GYM_ID, scenario="lossy_links", max_steps=7)
    assert env.unwrapped.scenario.name == "lossy_links"  # type: ignore[attr-defined]
    env.reset(seed=1)
    ends = [env.step(np.zeros(env.action_space.shape))[2:4] for _ in range(7)]
    assert ends[-1] == (False, True) and not any(any(e) for e in ends[:-1])
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(env.action_space.shape))
    large = gymnasium.make(scenario_id("large_fleet")).unwrapped
    assert large.scenario.name == "large_fleet"  # type: ignore[attr-defined]
    assert large.observation_space.shape == (10 * 26,)  # ring: K = 2 slots of 3 + m = 4


@pytest.mark.parametrize("mode", [None, "vector_entry_point"])
def test_make_vec_uses_the_native_vector_env(mode: str | None) -> None:
    envs = gymnasium.make_vec(
        GYM_ID, num_envs=4, vectorization_mode=mode, scenario="lossy_links", info_level="minimal"
    )
    assert isinstance(envs, CentralizedFleetVectorEnv)
    assert envs.sim.num_fleets == 4 and envs.scenario.name == "lossy_links"
    assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert envs.observation_space.shape == (4, *envs.single_observation_space.shape)
    assert envs.action_space.shape == (4, *envs.single_action_space.shape)
    obs, infos = envs.reset(seed=3)
    assert obs.shape == (4, 130) and obs.dtype == np.float32
    assert infos["path_error"].shape == (4, 5) and infos["_path_error"].all()
    envs.close()
    envs.close()


def test_register_envs_is_idempotent_and_fills_pettingzoo_registry() -> None:
    before = dict(gymnasium.registry)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        register_envs()
    assert dict(gymnasium.registry) == before
    parallel = pettingzoo.make("parallel", PETTINGZOO_ID, scenario="lossy_links")
    assert isinstance(parallel, cpf_env.CooperativePathFollowingEnv)
    assert parallel.scenario.name == "lossy_links"
    assert isinstance(pettingzoo.make("aec", PETTINGZOO_ID), pettingzoo.AECEnv)


def test_vector_env_matches_single_envs_bit_for_bit() -> None:
    """Env k (vector seed s) == CentralizedFleetEnv seeded s + k, through autoresets."""
    num_envs, seed, steps = 3, 10, 250
    overrides = {"scenario": "heterogeneous", "max_steps": 60, "info_level": "minimal"}
    envs = CentralizedFleetVectorEnv(num_envs=num_envs, stagger=False, **overrides)
    singles = [CentralizedFleetEnv(**overrides) for _ in range(num_envs)]
    obs, infos = envs.reset(seed=seed)
    done = np.zeros(num_envs, dtype=bool)
    for k, env in enumerate(singles):
        single_obs, single_info = env.reset(seed=seed + k)
        assert np.array_equal(obs[k], single_obs)
        assert np.array_equal(infos["path_error"][k], single_info["path_error"])
    rng = np.random.default_rng(0)
    episodes = 0
    for _ in range(steps):
        actions = random_actions(envs.action_space, rng)
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        for k, env in enumerate(singles):
            if done[k]:  # NEXT_STEP: this step is the reset (generator continues, no seed)
                single_obs, single_info = env.reset()
                outcome = (0.0, False, False)
            else:
                single_obs, reward, term, trunc, single_info = env.step(actions[k])
                outcome = (reward, term, trunc)
            assert obs[k].dtype == single_obs.dtype == np.float32
            assert np.array_equal(obs[k], single_obs)
            assert (rewards[k], terminated[k], truncated[k]) == outcome
            for name in ("path_error", "heading_error", "sync_error", "speed_error"):
                assert np.array_equal(infos[name][k], single_info[name])
        done = terminated | truncated
        episodes += int(done.sum())
    assert episodes >= 3 * num_envs  # the comparison covered several autoresets


def test_native_vector_env_matches_sync_vector_env() -> None:
    """Same NEXT_STEP semantics as Gymnasium's own SyncVectorEnv over the single env."""
    kwargs = {"num_envs": 2, "scenario": "current_and_waves", "max_steps": 25}
    native_only = {"stagger": False}  # SyncVectorEnv has no stagger
    native = gymnasium.make_vec(
        GYM_ID, vectorization_mode="vector_entry_point", **kwargs, **native_only
    )
    sync = gymnasium.make_vec(GYM_ID, vectorization_mode="sync", **kwargs)
    assert np.array_equal(native.reset(seed=5)[0], sync.reset(seed=5)[0])
    rng = np.random.default_rng(1)
    for _ in range(80):
        actions = random_actions(native.action_space, rng)
        for a, b in zip(native.step(actions)[:4], sync.step(actions)[:4], strict=True):
            assert np.array_equal(a, b)


def test_autoreset_next_step_after_truncation_and_termination() -> None:
    envs = CentralizedFleetVectorEnv(num_envs=2, max_steps=3, stagger=False)
    first, _ = envs.reset(seed=0)
    actions = np.zeros(envs.action_space.shape, dtype=np.float32)
    for step in range(1, 4):
        _, rewards, terminated, truncated, _ = envs.step(actions)
        assert not terminated.any() and truncated.all() == (step == 3)
    wild = random_actions(envs.action_space, np.random.default_rng(2))
    obs, rewards, terminated, truncated, _ = envs.step(wild)  # ignored: this step resets
    assert np.array_equal(obs, first) and not rewards.any()
    assert not terminated.any() and not truncated.any() and not envs.sim.arrays.step.any()

    envs = CentralizedFleetVectorEnv(
        num_envs=2, max_path_error=0.5
    )  # wang2014 starts ~1 m off the path
    first, _ = envs.reset(seed=0)
    _, _, terminated, truncated, _ = envs.step(actions)
    assert terminated.all() and not truncated.any()
    obs, rewards, terminated, _, _ = envs.step(actions)
    assert np.array_equal(obs, first) and not rewards.any() and not terminated.any()
    assert envs.step(actions)[2].all()


def test_reset_seeds() -> None:
    envs = CentralizedFleetVectorEnv("heterogeneous", 3)
    obs, _ = envs.reset(seed=[7, None, 9])
    single = CentralizedFleetEnv(scenario="heterogeneous")
    assert np.array_equal(obs[2], single.reset(seed=9)[0])
    assert single.np_random is single.sim.rngs[0]
    assert not np.array_equal(envs.reset()[0], obs)  # generators continue
    with pytest.raises(ValueError, match="options"):
        envs.reset(options={"reset_mask": np.ones(3, dtype=bool)})
    with pytest.raises(ValueError, match="seeds"):
        envs.reset(seed=[1, 2])


def with_entry(actions: np.ndarray, value: float) -> np.ndarray:
    bad = actions.copy()
    bad.flat[-3] = value
    return bad


@pytest.mark.parametrize(
    ("make_bad", "match"),
    [
        (lambda a: a[..., :-1], "shape"),
        (lambda a: a[None], "shape"),
        (lambda a: with_entry(a, np.nan), "finite"),
        (lambda a: with_entry(a, -np.inf), "finite"),
    ],
)
def test_bad_action_raises_and_leaves_state_untouched(
    make_bad: Callable[[np.ndarray], np.ndarray], match: str
) -> None:
    env = CentralizedFleetEnv(scenario="lossy_links")
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape))
    before = snapshot(env.sim)
    with pytest.raises(ValueError, match=match):
        env.step(make_bad(np.zeros(env.action_space.shape, dtype=np.float32)))
    assert_unchanged(before, env.sim)

    envs = CentralizedFleetVectorEnv(  # link delay 5 < 6 steps
        "lossy_links", 2, stagger=False, max_steps=6
    )
    envs.reset(seed=0)
    for _ in range(6):
        envs.step(np.zeros(envs.action_space.shape))  # both truncated: the next step would reset
    before = snapshot(envs.sim)
    with pytest.raises(ValueError, match=match):
        envs.step(make_bad(np.zeros(envs.action_space.shape, dtype=np.float32)))
    assert_unchanged(before, envs.sim)
    envs.step(np.zeros(envs.action_space.shape))  # the pending autoreset still happens
    assert not envs.sim.arrays.step.any()


def test_step_before_reset_raises() -> None:
    with pytest.raises(RuntimeError, match="reset"):
        CentralizedFleetEnv().step(np.zeros(25))
    with pytest.raises(RuntimeError, match="reset"):
        CentralizedFleetVectorEnv(num_envs=2).step(np.zeros((2, 25)))


def test_a_changed_scenario_gets_a_new_id_version_and_the_old_id_names_it():
    assert scenario_id("bench_switching").endswith("-v1")
    with pytest.raises(gymnasium.error.DeprecatedEnv, match="bench_switching-v1"):
        gymnasium.make("cpf_env/CentralizedFleet-bench_switching-v0")
