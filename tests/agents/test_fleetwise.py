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
    filtered = {"mpc_tuned_ekf", "mpc_tuned_mmae", "mpc_tuned_safe", "mpc_tuned_ekf_safe"}
    assert set(WHOLE_BATCH_BASES) == {"mpc", "mpc_tuned", *filtered}
    env = FleetVecEnv(
        "bench_current_waves", num_fleets=2, base_policy="mpc_tuned", residual=ResidualConfig()
    )
    assert isinstance(env.controller.base, FleetwiseBase)
    assert env.controller.base.name == "mpc_tuned"


def test_a_filtered_design_run_fleet_by_fleet_acts_as_the_batched_one() -> None:
    """The navigation and safety filters keep per-fleet state: fleet by fleet, the same actions."""
    scenario = scenarios.get("hard_crossing").replace(sensors=scenarios.get("hard_sensing").sensors)
    env = FleetVecEnv(scenario, num_fleets=2, base_policy="mpc_tuned_ekf_safe")
    assert isinstance(env.controller.base, FleetwiseBase)
    base = env.controller.base
    assert (base.obs_dim, base.act_dim) == (env.sim.arrays.obs.shape[-1], env.sim.act_dim)
    env.seed(2)
    env.reset()
    batched = make_policy("mpc_tuned_ekf_safe", scenario)
    fleetwise = FleetwiseBase("mpc_tuned_ekf_safe", scenario, 2)
    for _ in range(12):  # fixes every 4 steps: the filters predict, then correct
        obs = env.sim.arrays.obs
        np.testing.assert_array_equal(fleetwise.act_batch(obs), batched.act_batch(obs))
        env.step(np.zeros((env.num_envs, env.action_space.shape[0]), dtype=np.float32))


def test_a_whole_batch_of_another_size_starts_fresh_instances() -> None:
    """Input statistics are estimated on a batch of their own before the env's fleets run."""
    scenario = scenarios.get("bench_current_waves")
    obs = _env_after(2).sim.arrays.obs
    fleetwise = FleetwiseBase("mpc", scenario, 2)
    fleetwise.act_batch(obs)
    wider = np.concatenate([obs, obs, obs])
    np.testing.assert_array_equal(
        fleetwise.act_batch(wider), make_policy("mpc", scenario).act_batch(wider)
    )
    assert len(fleetwise.policies) == 6
