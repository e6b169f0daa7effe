"""Data-only snapshots: values round-trip, graphs restore in place, the unknown is refused."""

from __future__ import annotations

import collections
import threading

import numpy as np
import pytest
import torch

from agents.envs.fleetwise import FleetwiseBase
from agents.envs.vec_env import FleetVecEnv
from agents.training.algorithms import make_env
from agents.training.config import TrainConfig
from agents.training.snapshot import SnapshotError, capture, decode_value, encode_value, restore
from cpf_env import scenarios


def test_values_round_trip_exactly() -> None:
    value = {
        "n": 3,
        7: [1.5, None, "x", (np.float32(0.1), np.int64(-2))],
        "a": np.arange(6, dtype=np.uint32).reshape(2, 3),
        "t": torch.tensor([1.0, 2.0]),
        "q": collections.deque([{"r": 1.0}], maxlen=4),
        "o": collections.OrderedDict(b=1),
    }
    arrays: dict[str, object] = {}
    back = decode_value(encode_value(value, "v", arrays), arrays)
    assert back["n"] == 3 and back[7][:3] == [1.5, None, "x"]
    assert back[7][3][0].dtype == np.float32 and back[7][3][0] == np.float32(0.1)
    assert np.array_equal(back["a"], value["a"]) and back["a"].dtype == np.uint32
    assert torch.equal(back["t"], value["t"])
    assert back["q"].maxlen == 4 and list(back["q"]) == [{"r": 1.0}]
    assert isinstance(back["o"], collections.OrderedDict)
    with pytest.raises(SnapshotError, match="not plain data"):
        encode_value({"lock": threading.Lock()}, "v", {})


def test_an_env_restores_in_place_and_steps_as_the_original() -> None:
    env = FleetVecEnv("bench_lossy_links", base_policy="nn_dsc", num_fleets=2, max_steps=20)
    env.seed(5)
    env.reset()
    rng = np.random.default_rng(0)
    for _ in range(7):
        env.step(rng.uniform(-1, 1, (env.num_envs, 3)))
    arrays: dict[str, object] = {}
    tree = capture(env, "env", arrays)
    fresh = FleetVecEnv("bench_lossy_links", base_policy="nn_dsc", num_fleets=2, max_steps=20)
    fresh.reset()
    restore(fresh, tree, "env", arrays)
    actions = rng.uniform(-1, 1, (env.num_envs, 3))
    resets = 0
    for _ in range(30):  # lossy links, delays, disturbances, and random restarts of the fleets
        a, b = env.step(actions), fresh.step(actions)
        assert all(np.array_equal(x, y) for x, y in zip(a[:3], b[:3], strict=True))
        resets += int(a[2].any())
    assert resets >= 2  # fleets restarted from their generators after the restore
    with pytest.raises(SnapshotError, match="resume with the code and configuration"):
        other = TrainConfig(scenario="bench_lossy_links", fleets=2, base_policy="dsc")
        restore(make_env(other), tree, "env", arrays)


def test_an_object_of_an_unknown_library_is_refused_with_its_path() -> None:
    env = make_env(TrainConfig(scenario="bench_mild", fleets=1))
    env.scratch = threading.Lock()  # type: ignore[attr-defined]
    with pytest.raises(SnapshotError, match=r"env\.scratch is a _thread\.lock"):
        capture(env, "env", {})


def test_a_read_only_constant_restores_as_it_is() -> None:
    """``mpc``'s parameters are read-only arrays: kept when equal (run fleet by fleet here)."""
    scenario = scenarios.get("bench_saturation")
    env = FleetVecEnv(scenario, base_policy="nn_dsc", num_fleets=2)
    env.reset()
    saved, fresh = FleetwiseBase("mpc", scenario, 2), FleetwiseBase("mpc", scenario, 2)
    for policy in (saved, fresh):
        policy.act_batch(env.sim.arrays.obs)  # sizes its parameters
    arrays: dict[str, object] = {}
    tree = capture(saved, "base", arrays)
    constant = fresh.policies[1]._params
    assert not constant.flags.writeable
    restore(fresh, tree, "base", arrays)
    assert fresh.policies[1]._params is constant
