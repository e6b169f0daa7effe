"""Observations handed out are the caller's: the next step never overwrites a kept one.

Each env view is stepped with actions that move the fleet, the observation
(and, where an env returns arrays in its infos, the infos) of one step is
kept, and after further steps it must still equal its snapshot taken at once.
Each test also checks that the observations did change, so that an aliased
buffer would show.
"""

from __future__ import annotations

import gymnasium
import numpy as np

import cpf_env
from baselines import make_policy
from cpf_env.envs.gym_envs import CentralizedFleetEnv, CentralizedFleetVectorEnv

SCENARIO = "wang2014"


def _snapshot(value: object) -> object:
    """A deep copy of nested dicts, tuples and arrays."""
    if isinstance(value, dict):
        return {k: _snapshot(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_snapshot(v) for v in value)
    return np.array(value, copy=True) if isinstance(value, np.ndarray) else value


def _assert_same(kept: object, snapshot: object) -> None:
    if isinstance(snapshot, dict):
        assert isinstance(kept, dict) and kept.keys() == snapshot.keys()
        for key in snapshot:
            _assert_same(kept[key], snapshot[key])
    elif isinstance(snapshot, list | tuple):
        for k, s in zip(kept, snapshot, strict=True):  # type: ignore[call-overload]
            _assert_same(k, s)
    elif isinstance(snapshot, np.ndarray):
        assert np.array_equal(kept, snapshot)
    else:
        assert kept == snapshot


def test_parallel_env_observations_and_infos_are_not_aliased() -> None:
    env = cpf_env.parallel_env(SCENARIO)
    policy = make_policy("nn_dsc", env)
    kept, infos = env.reset(seed=0)
    kept_infos = infos
    snapshot, info_snapshot = _snapshot(kept), _snapshot(kept_infos)
    observations = kept
    for step in range(3):
        observations, _r, _t, _u, infos = env.step(policy.act(observations))
        if step == 0:
            kept, kept_infos = observations, infos
            snapshot, info_snapshot = _snapshot(kept), _snapshot(kept_infos)
    _assert_same(kept, snapshot)
    _assert_same(kept_infos, info_snapshot)
    assert not np.array_equal(observations["vessel_0"], snapshot["vessel_0"])


def test_aec_env_observations_are_not_aliased() -> None:
    env = cpf_env.env(SCENARIO)
    env.reset(seed=0)
    kept = env.observe("vessel_0")
    snapshot = np.array(kept, copy=True)
    force = np.zeros(env.action_space("vessel_0").shape, np.float32)
    force[:3] = 2.0
    for _ in range(3 * len(env.possible_agents)):  # three full cycles
        env.step(force)
    assert np.array_equal(kept, snapshot)
    assert not np.array_equal(env.observe("vessel_0"), snapshot)


def _assert_single_env_not_aliased(env: gymnasium.Env) -> None:
    """The reset observation and the first step's survive two more steps unchanged."""
    first, _ = env.reset(seed=0)
    kept = [(first, first.copy())]
    action = np.full(env.action_space.shape, 0.5, np.float32)
    for step in range(3):
        observation, *_ = env.step(action)
        if step == 0:
            kept.append((observation, observation.copy()))
    for value, snapshot in kept:
        assert np.array_equal(value, snapshot)
    assert not np.array_equal(observation, kept[1][1])


def test_gymnasium_single_env_observations_are_not_aliased() -> None:
    _assert_single_env_not_aliased(CentralizedFleetEnv(SCENARIO))


def test_gymnasium_registered_env_observations_are_not_aliased() -> None:
    _assert_single_env_not_aliased(gymnasium.make("cpf_env/CentralizedFleet-v0"))


def test_gymnasium_vector_env_observations_and_infos_are_not_aliased() -> None:
    env = CentralizedFleetVectorEnv(SCENARIO, 3)
    observation, infos = env.reset(seed=0)
    kept, kept_infos = observation, infos
    snapshot, info_snapshot = kept.copy(), _snapshot(infos)
    action = np.full(env.action_space.shape, 0.5, np.float32)
    for step in range(3):
        observation, _r, _t, _u, infos = env.step(action)
        if step == 0:
            kept, kept_infos = observation, infos
            snapshot, info_snapshot = kept.copy(), _snapshot(infos)
    assert np.array_equal(kept, snapshot)
    _assert_same(kept_infos, info_snapshot)
    assert not np.array_equal(observation, snapshot)


def test_residual_wrapper_observations_and_infos_are_not_aliased() -> None:
    base = make_policy("nn_dsc", cpf_env.scenarios.get(SCENARIO))
    env = cpf_env.parallel_env(SCENARIO, info_level="full", base_policy=base)
    observations, _ = env.reset(seed=0)
    correction = {a: np.full(env.core.action_size, 0.5, np.float32) for a in env.agents}
    kept, kept_infos, snapshot, info_snapshot = None, None, None, None
    for step in range(3):
        observations, _r, _t, _u, infos = env.step(correction)
        if step == 0:
            kept, kept_infos = observations, infos
            snapshot, info_snapshot = _snapshot(kept), _snapshot(infos)
    _assert_same(kept, snapshot)
    _assert_same(kept_infos, info_snapshot)
    assert not np.array_equal(observations["vessel_0"], snapshot["vessel_0"])  # type: ignore[index]
