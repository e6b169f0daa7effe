"""``FleetwiseBase``: a whole-batch base (``mpc``) run fleet by fleet in the learners' envs."""

from __future__ import annotations

import numpy as np

from agents.envs.fleetwise import WHOLE_BATCH_BASES, FleetwiseBase
from agents.envs.vec_env import FleetVecEnv
from baselines import make_policy
from cpf_env import scenarios
from cpf_env.envs.residual import ResidualConfig


def _env_after(steps: int, base: str = "nn_dsc") -> FleetVecEnv:
    env = FleetVecEnv(
        "bench_current_waves", num_fleets=2, base_policy=base, residual=ResidualConfig()
    )
    env.seed(4)
    env.reset()
    for _ in range(steps):
        env.step(np.zeros((env.num_envs, 3), dtype=np.float32))
    return env


def test_fleetwise_base_acts_as_the_batched_policy() -> None:
    scenario = scenarios.get("bench_current_waves")
    obs = _env_after(3).sim.arrays.obs
    batched, fleetwise = make_policy("mpc", scenario), FleetwiseBase("mpc", scenario, 2)
    for _ in range(2):
        np.testing.assert_array_equal(fleetwise.act_batch(obs), batched.act_batch(obs))
    fleetwise.reset_fleets(np.array([False, True]))
    alone = fleetwise.act_batch(obs[1:], fleets=np.array([1]))
    np.testing.assert_array_equal(alone, make_policy("mpc", scenario).act_batch(obs[1:]))


def test_an_env_with_base_mpc_restarts_single_fleets() -> None:
    env = FleetVecEnv(
        "bench_current_waves",
        num_fleets=2,
        base_policy="mpc",
        max_steps=6,
        residual=ResidualConfig(),
    )
    assert isinstance(env.controller.base, FleetwiseBase)
    env.seed(1)
    env.reset()
    dones = np.zeros(env.num_envs, dtype=bool)
    for _ in range(6):  # staggered horizons: one fleet ends (and restarts) before the other
        _, _, done, _ = env.step(np.zeros((env.num_envs, 3), dtype=np.float32))
        dones |= done
    assert dones.all()


def test_every_mpc_design_is_run_fleet_by_fleet() -> None:
    assert set(WHOLE_BATCH_BASES) == {"mpc", "mpc_tuned"}
    env = FleetVecEnv(
        "bench_current_waves", num_fleets=2, base_policy="mpc_tuned", residual=ResidualConfig()
    )
    assert isinstance(env.controller.base, FleetwiseBase)
    assert env.controller.base.name == "mpc_tuned"
