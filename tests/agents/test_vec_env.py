"""FleetVecEnv: SB3's VecEnv contract, bit-for-bit equivalence through auto-resets, locality."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from agents import FleetVecEnv
from baselines import make_policy
from cpf_env import FleetSim, scenarios
from cpf_env.envs.residual import ResidualConfig

ALL_EXTRAS = ("base_action", "base_signals", "multiscale_errors")


def reference_run(
    scenario_name: str, seed: int, horizons: list[int], steps: int, **overrides: object
) -> dict[str, list]:
    """One fleet on its own FleetSim with nn_dsc, reset by hand after each episode."""
    scenario = scenarios.get(scenario_name).replace(**overrides)
    sim = FleetSim(scenario)
    policy = make_policy("nn_dsc", scenario)
    obs = sim.reset(seeds=[seed]).copy()
    record: dict[str, list] = {"obs": [], "reward": [], "done": [], "terminal": [], "truncated": []}
    horizon = horizons[0]
    episode = 0
    for _ in range(steps):
        obs = sim.step(policy.act_batch(obs)).copy()
        record["reward"].append(sim.arrays.reward[0].copy())
        terminated = bool(sim.arrays.terminated[0])
        done = terminated or sim.arrays.step[0] >= horizon
        record["done"].append(done)
        if done:
            record["terminal"].append(obs[0].copy())
            record["truncated"].append(not terminated)
            obs = sim.reset(seeds=[None]).copy()
            policy.reset()
            episode += 1
            horizon = horizons[min(episode, len(horizons) - 1)]
        record["obs"].append(obs[0].copy())
    return record


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        ("bench_saturation", {"max_steps": 60}),  # truncations, staggered
        ("bench_saturation", {"max_steps": 400, "max_path_error": 3.6}),  # some fleets fail
    ],
)
def test_zero_actions_reproduce_the_base_policy_fleet_for_fleet(name: str, overrides: dict) -> None:
    """300 steps through auto-resets: every fleet equals its own single-fleet run bit for bit
    (observations, rewards of ending fleets, dones, terminal observations, truncation flags)."""
    B, seed, steps = 4, 11, 300
    env = FleetVecEnv(name, num_fleets=B, base_policy="nn_dsc", **overrides)
    env.seed(seed)
    obs = env.reset()
    n, max_steps = env.n, env.scenario.max_steps
    references = [
        reference_run(
            name, seed + k, [max_steps - k * max_steps // B, max_steps], steps, **overrides
        )
        for k in range(B)
    ]
    terminated_any = False
    for t in range(steps):
        obs, rewards, dones, infos = env.step(np.zeros((env.num_envs, 3), np.float32))
        for k, ref in enumerate(references):
            rows = slice(k * n, (k + 1) * n)
            assert np.array_equal(obs[rows], ref["obs"][t]), (t, k)
            assert np.array_equal(rewards[rows], ref["reward"][t].astype(np.float32)), (t, k)
            assert np.all(dones[rows] == ref["done"][t])
            if ref["done"][t]:
                episode = sum(ref["done"][: t + 1]) - 1
                for i in range(n):
                    info = infos[k * n + i]
                    assert np.array_equal(info["terminal_observation"], ref["terminal"][episode][i])
                    assert info["TimeLimit.truncated"] == ref["truncated"][episode]
                terminated_any |= not ref["truncated"][episode]
                assert np.any(ref["reward"][t] != 0.0)  # the last step's reward is not lost
            else:
                assert all(not infos[k * n + i] for i in range(n))
    assert sum(sum(ref["done"]) for ref in references) >= B
    if "max_path_error" in overrides:
        assert terminated_any


def test_a_fleet_reset_leaves_the_other_fleets_base_states_alone() -> None:
    env = FleetVecEnv("bench_mild", base_policy="nn_dsc", num_fleets=3, max_steps=30, stagger=False)
    env.seed(0)
    env.reset()
    base = env.controller.base
    for _ in range(5):
        env.step(np.zeros((env.num_envs, 3), np.float32))
    before = {key: value.copy() for key, value in base._states._asdict().items()}  # type: ignore[attr-defined]
    env.controller.reset_fleets(np.array([False, True, False]))
    for key, value in base._states._asdict().items():  # type: ignore[attr-defined]
        assert np.array_equal(value[[0, 2]], before[key][[0, 2]]), key
        assert not np.any(value[1]), key


def test_seed_gives_fleet_k_seed_s_plus_k_on_the_next_reset_only() -> None:
    env = FleetVecEnv("bench_mild", base_policy="nn_dsc", num_fleets=3, max_steps=20)
    assert env.seed(5) == [5, 6, 7]
    obs = env.reset()
    for k in range(3):
        single = FleetSim(env.scenario).reset(seeds=[5 + k])
        assert np.array_equal(obs[k * 5 : (k + 1) * 5], single[0])
    again = env.reset()  # no new seed: the generators continue, a new episode
    assert not np.array_equal(again, obs)
    env.seed(5)
    assert np.array_equal(env.reset(), obs)


def test_vec_env_contract_and_sb3_wrappers() -> None:
    env = FleetVecEnv(
        "bench_mild",
        base_policy="nn_dsc",
        num_fleets=2,
        max_steps=15,
        residual=ResidualConfig(extras=ALL_EXTRAS),
    )
    assert env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low))
    assert np.all(np.isfinite(env.observation_space.high))
    assert env.env_is_wrapped(Monitor) == [False] * env.num_envs
    assert env.get_attr("n", indices=[0, 3]) == [5, 5]
    assert env.env_method("seed", 3, indices=0) == [[3, 4]]
    normalized = VecNormalize(VecMonitor(env), norm_reward=False)
    obs = normalized.reset()
    assert isinstance(obs, np.ndarray) and obs.shape == (10, env.observation_space.shape[0])
    assert obs.dtype == np.float32
    episodes = []
    for _ in range(20):
        obs, _, _, infos = normalized.step(np.zeros((10, 3), np.float32))
        episodes += [info["episode"] for info in infos if "episode" in info]
    # fleet 0 runs its 15 steps, fleet 1's first horizon is staggered to 15 - 15 // 2 = 8
    assert sorted(int(e["l"]) for e in episodes) == [8] * 5 + [15] * 5

    class Zero:
        def predict(self, observation, state=None, episode_start=None, deterministic=True):
            return np.zeros((len(observation), 3), np.float32), None

    mean, std = evaluate_policy(
        Zero(), VecMonitor(FleetVecEnv("bench_mild", 2, base_policy="nn_dsc", max_steps=15)), 4
    )
    assert np.isfinite(mean) and mean < 0.0 and std > 0.0  # random starts: episodes differ


def test_bad_arguments_and_actions() -> None:
    with pytest.raises(ValueError, match="unknown base policy"):
        FleetVecEnv("wang2014", 2, base_policy="pid")
    with pytest.raises(ValueError, match="num_fleets"):
        FleetVecEnv("wang2014", 0, base_policy="nn_dsc")
    with pytest.raises(ValueError, match="unknown Scenario field"):
        FleetVecEnv("wang2014", 2, base_policy="nn_dsc", max_cycles=3)
    env = FleetVecEnv("wang2014", 2, base_policy="nn_dsc", max_steps=10)
    env.reset()
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((10, 4), np.float32))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full((10, 3), np.nan, np.float32))


def test_from_scratch_commands_forces_and_rate_as_fractions_of_the_limits() -> None:
    env = FleetVecEnv("wang2014", 1, base_policy=None, max_steps=10)
    env.reset()
    assert env.action_space.shape == (4,)
    action = np.tile(np.array([1.0, -0.5, 0.25, 0.1], np.float32), (5, 1))
    env.step(action)
    a = env.sim.arrays
    np.testing.assert_allclose(a.tau_command[0], np.tile([9.2, -2.25, 0.75], (5, 1)), rtol=1e-6)
    np.testing.assert_allclose(a.theta_dot[0], 0.1, rtol=1e-6)
    assert not np.any(a.message)


def test_locality_a_non_neighbour_does_not_reach_a_vessels_input() -> None:
    """In wang2014's chain 0-1-2-3-4, moving vessel 3 changes nothing vessel 0 sees
    (observation and every extra) at the next step; it does change vessel 3's own input."""
    config = ResidualConfig(extras=ALL_EXTRAS)
    envs = [
        FleetVecEnv("wang2014", 1, base_policy="nn_dsc", residual=config, max_steps=50)
        for _ in range(2)
    ]
    for env in envs:
        env.seed(0)
        env.reset()
        env.step(np.zeros((5, 3), np.float32))
    sim = envs[1].sim
    sim.arrays.eta[0, 3, :2] += (0.7, -0.4)
    sim.arrays.nu[0, 3] += (0.05, 0.02, 0.01)
    inputs = [env.step(np.full((5, 3), 0.3, np.float32))[0] for env in envs]
    assert np.array_equal(inputs[0][0], inputs[1][0])
    assert not np.array_equal(inputs[0][3], inputs[1][3])


def test_observations_are_not_aliased_through_steps_and_auto_resets() -> None:
    """A kept observation batch, and a terminal observation, survive the next steps unchanged."""
    env = FleetVecEnv("bench_saturation", num_fleets=2, base_policy="nn_dsc", max_steps=3)
    kept = env.reset()
    snapshot = kept.copy()
    action = np.full((env.num_envs, 3), 0.5, np.float32)
    terminal, kept_step = None, None
    for step in range(5):  # through one auto-reset at step 3
        obs, _rewards, dones, infos = env.step(action)
        if step == 0:
            kept_step, step_snapshot = obs, obs.copy()
        if dones.any() and terminal is None:
            terminal = infos[int(np.flatnonzero(dones)[0])]["terminal_observation"]
            terminal_snapshot = terminal.copy()
    assert np.array_equal(kept, snapshot) and np.array_equal(kept_step, step_snapshot)
    assert terminal is not None and np.array_equal(terminal, terminal_snapshot)
    assert not np.array_equal(obs, snapshot)


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        (np.zeros((3, 20)), "shape"),  # (k, num_envs): transposed, same number of elements
        (np.zeros(60), "shape"),
        (np.zeros((20, 3), dtype=complex), "real numbers"),
        (np.ones((20, 3), dtype=bool), r"real numbers, got dtype bool \(bools are not commands"),
        (np.full((20, 3), np.inf), "finite"),
        (np.full((20, 3), -np.inf), "finite"),
        (np.full((20, 3), np.nan), "finite"),
    ],
)
def test_step_async_refuses_what_it_would_misread(actions: np.ndarray, message: str) -> None:
    env = FleetVecEnv("wang2014", base_policy="nn_dsc", num_fleets=4, max_steps=5)
    env.reset()
    stored = env._actions.copy()
    with pytest.raises(ValueError, match=message):
        env.step_async(actions)
    np.testing.assert_array_equal(env._actions, stored)


def test_seed_refuses_what_is_not_a_seed_and_keeps_the_last_one() -> None:
    env = FleetVecEnv("bench_mild", base_policy="nn_dsc", num_fleets=2, max_steps=5)
    assert env.seed(7) == [7, 8]
    for bad in (-1, 1.7, True, "3"):
        with pytest.raises(ValueError, match="seed must be an integer"):
            env.seed(bad)  # type: ignore[arg-type]
    first = env.reset()
    env.seed(7)
    np.testing.assert_array_equal(env.reset(), first)  # the refused calls left seed 7 in place


def test_stagger_must_be_a_bool() -> None:
    with pytest.raises(ValueError, match="stagger must be True or False"):
        FleetVecEnv("wang2014", base_policy="nn_dsc", num_fleets=2, stagger="no")  # type: ignore[arg-type]
