"""MixtureVecEnv and padded neighbour slots: one learner input for every fleet size and graph."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from agents import FleetVecEnv, TrainConfig, load_policy, train
from agents.envs.mixture_env import MixtureVecEnv, split_fleets
from agents.training.algorithms import make_env
from cpf_commands.train import train_main
from cpf_env import FleetSim, scenarios
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.model.graph import Graph
from cpf_env.model.paths import Sinusoid
from cpf_env.scenarios.splits import split_scenario
from cpf_env.scenarios.suite import SUITE
from cpf_env.sim.fleet import observation_layout

MIX = ("bench_mild", "bench_switching", "bench_large_fleet")
TINY = {"fleets": 3, "n_steps": 16, "batch_size": 80, "n_epochs": 1, "net_arch": (16, 16)}


def fleet_of(n: int, graph: Graph) -> scenarios.Scenario:
    """``bench_mild`` with n vessels on ``graph``, 4 m apart."""
    base = scenarios.get("bench_mild")
    offsets = [4.0 * (k - (n - 1) / 2) for k in range(n)]
    initial = dataclasses.replace(
        base.initial, eta=tuple((0.0, y + 1.0, 0.0) for y in offsets), nu=None, theta=None
    )
    return base.replace(
        name=f"bench_mild_n{n}",
        paths=tuple(Sinusoid(y0=y, amplitude=2.0, wavenumber=0.2) for y in offsets),
        topology=graph,
        initial=initial,
    )


def test_padded_slots_are_empty_and_the_base_sees_its_own_observation() -> None:
    """K = 2 padded to 6: the input holds the observation, then 4 all-zero slots."""
    scenario = scenarios.get("bench_lossy_links")
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    plain = ResidualController(scenario, None, 2, ResidualConfig(extras=("base_action",)))
    padded = ResidualController(
        scenario, None, 2, ResidualConfig(extras=("base_action",), neighbour_slots=6)
    )
    a, b = plain.observe(obs), padded.observe(obs)
    size = observation_layout(scenario).size
    assert b.shape[-1] == a.shape[-1] + 4 * 4 == padded.input_size
    np.testing.assert_array_equal(b[..., :size], a[..., :size])
    np.testing.assert_array_equal(b[..., size : size + 16], 0.0)
    np.testing.assert_array_equal(b[..., size + 16 :], a[..., size:])  # extras after the slots


def test_a_graph_of_higher_degree_than_the_slots_is_refused_with_the_limit_named() -> None:
    star = fleet_of(10, Graph.star(10, center=4, leaders=(4,)))
    with pytest.raises(ValueError, match=r"at most 6 neighbours.*gives a vessel 9"):
        ResidualConfig(neighbour_slots=6).input_size(observation_layout(star))
    with pytest.raises(ValueError, match="neighbour_slots must be an integer >= 1"):
        ResidualConfig(neighbour_slots=0)


def test_every_group_is_the_fleet_vec_env_of_its_scenario_bit_for_bit() -> None:
    """300 steps through auto-resets: group g equals a FleetVecEnv on its seeds."""
    mixture = MixtureVecEnv(MIX, base_policy="nn_dsc", num_fleets=5)
    seeds = mixture.seed(7)
    assert seeds == list(range(7, 12))  # distinct seeds across groups
    sizes = split_fleets(5, 3)
    alone = []
    offset = 0
    for name, fleets in zip(MIX, sizes, strict=True):
        env = FleetVecEnv(
            name, fleets, base_policy="nn_dsc", residual=ResidualConfig(neighbour_slots=4)
        )
        env.seed(7 + offset)
        offset += fleets
        alone.append(env)
    obs = mixture.reset()
    rng = np.random.default_rng(0)
    expected = np.concatenate([env.reset() for env in alone])
    np.testing.assert_array_equal(obs, expected)
    for _ in range(300):
        action = rng.uniform(-1, 1, (mixture.num_envs, 3)).astype(np.float32)
        obs, rewards, dones, _ = mixture.step(action)
        starts = np.cumsum([0, *(env.num_envs for env in alone)])
        parts = [
            env.step(action[a:b]) for env, a, b in zip(alone, starts[:-1], starts[1:], strict=True)
        ]
        np.testing.assert_array_equal(obs, np.concatenate([p[0] for p in parts]))
        np.testing.assert_array_equal(rewards, np.concatenate([p[1] for p in parts]))
        np.testing.assert_array_equal(dones, np.concatenate([p[2] for p in parts]))
    assert mixture.num_envs == 2 * 5 + 2 * 5 + 1 * 10


def test_ending_slots_name_their_scenario() -> None:
    env = MixtureVecEnv(MIX, base_policy="nn_dsc", num_fleets=3)
    env.seed(0)
    env.reset()
    names: set[str] = set()
    for _ in range(scenarios.get("bench_mild").max_steps):
        _, _, dones, infos = env.step(np.zeros((env.num_envs, 3)))
        names |= {info["scenario"] for info, done in zip(infos, dones, strict=True) if done}
    assert names == set(MIX)


def test_mixture_refuses_what_it_cannot_mix() -> None:
    with pytest.raises(ValueError, match="two or more distinct scenarios"):
        MixtureVecEnv(["bench_mild"], 2, base_policy="nn_dsc")
    with pytest.raises(ValueError, match="two or more distinct"):
        MixtureVecEnv(["bench_mild", "bench_mild"], 2, base_policy="nn_dsc")
    with pytest.raises(ValueError, match="at least 3 fleets"):
        MixtureVecEnv(MIX, 2, base_policy="nn_dsc")
    with pytest.raises(ValueError, match="share a message size"):
        MixtureVecEnv(
            ["bench_mild", scenarios.get("bench_switching").replace(message_size=2)],
            2,
            base_policy="nn_dsc",
        )


def test_train_config_mixture_fields() -> None:
    config = TrainConfig(scenario=list(SUITE))
    assert config.scenarios == SUITE and config.home_scenario == "bench_mild"
    assert config.residual.neighbour_slots == 4  # the suite's largest degree (bench_switching)
    assert TrainConfig(scenario=["bench_mild"]).scenario == "bench_mild"
    assert TrainConfig.from_json(config.to_json()) == config
    with pytest.raises(ValueError, match="distinct names"):
        TrainConfig(scenario=("bench_mild", "bench_mild"))
    with pytest.raises(ValueError, match="unknown reward field"):
        TrainConfig(reward_overrides={"headings": 1.0})
    with pytest.raises(ValueError, match="heading_scale must be a finite number > 0"):
        TrainConfig(reward_overrides={"heading_scale": 0.0})
    tuned = TrainConfig(scenario=MIX, reward_overrides={"heading": 1.0}, fleets=3)
    env = make_env(tuned)
    assert isinstance(env, MixtureVecEnv)
    for group in env.groups:
        assert group.scenario.reward.heading == 1.0
        assert scenarios.get(group.scenario.name).reward.heading != 1.0


def test_a_mixture_agent_runs_on_every_fleet_size_and_supported_graph(tmp_path: Path) -> None:
    """Trained on three scenarios with 6 slots: runs on the suite, the shift split, n = 3 .. 10."""
    config = TrainConfig(
        scenario=MIX, residual=ResidualConfig(neighbour_slots=6), timesteps=640, seed=0, **TINY
    )  # type: ignore[arg-type]
    folder = train(config, tmp_path / "mix", progress=False)
    targets = [scenarios.get(name) for name in SUITE]
    targets += [split_scenario(name, "shift") for name in SUITE]
    targets += [fleet_of(3, Graph.path(3)), fleet_of(10, Graph.ring(10))]
    for scenario in targets:
        policy = load_policy(folder, scenario=scenario)
        sim = FleetSim(scenario, num_fleets=2)
        obs = sim.reset(seeds=[0, 1])
        for _ in range(3):
            obs = sim.step(policy.act_batch(obs))
        assert np.all(np.isfinite(obs)), scenario.name
    with pytest.raises(ValueError, match="at most 6 neighbours"):
        load_policy(folder, scenario=fleet_of(10, Graph.star(10, center=4, leaders=(4,))))


def test_cpf_train_expands_suite_and_refuses_shift_scenarios(tmp_path: Path) -> None:
    out = tmp_path / "suite"
    # no evaluations: 10 whole episodes of the 7 scenarios, twice, were 3/4 of the time
    code = train_main(
        ["--scenarios", "suite", "-n", "100", "--fleets", "7", "--set", "n_steps=16",
         "--set", "batch_size=80", "--set", "n_epochs=1", "--set", "reward_overrides={heading=1.0}",
         "--eval-every", "0", "--out", str(out), "--quiet"]
    )  # fmt: skip
    assert code == 0
    record = load_policy(out).config
    assert record.scenarios == SUITE and record.reward_overrides == {"heading": 1.0}
    with pytest.raises(SystemExit):
        train_main(["--scenarios", "bench_mild_shift", "--out", str(tmp_path / "x")])
    with pytest.raises(SystemExit):
        train_main(["--set", "reward_overrides={heading}", "--out", str(tmp_path / "y")])


def test_balanced_rewards_divide_each_scenario_by_its_running_mean_cost() -> None:
    """Group g's rewards divided by the mean cost per step of everything g has seen."""
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.envs.mixture_env import BalancedRewards

    mixture = MixtureVecEnv(["bench_mild", "bench_lossy_links"], base_policy="nn_dsc", num_fleets=2)
    env = BalancedRewards(VecMonitor(mixture), mixture)
    env.seed(0)
    env.reset()
    raw_sums, balanced, raw_steps = np.zeros(2), [], []
    for _ in range(50):
        _, rewards, _, _ = env.step(np.zeros((env.num_envs, 3)))
        raw = np.concatenate([g.sim.arrays.reward.reshape(-1) for g in mixture.groups])
        raw_sums += np.bincount(mixture.group_of_slot, weights=-raw)
        raw_steps.append(raw)
        balanced.append(rewards)
    counts = 50 * np.bincount(mixture.group_of_slot)
    np.testing.assert_allclose(env.scales, raw_sums / counts, rtol=1e-6)
    last_scale = env.scales[mixture.group_of_slot]
    np.testing.assert_allclose(balanced[-1], raw_steps[-1] / last_scale, rtol=1e-6)
    assert env.scales[0] != env.scales[1]


def test_each_scenarios_episode_cost_is_logged(tmp_path: Path) -> None:
    """ScenarioEpisodes logs rollout/ep_cost/<name>: the mean of that scenario's episode costs."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.training.schedule import ScenarioEpisodes

    short = [{"max_steps": 8}, {"max_steps": 12}]
    mixture = MixtureVecEnv(
        ["bench_mild", "bench_large_fleet"],
        2,
        base_policy="nn_dsc",
        stagger=False,
        scenario_overrides=short,
    )
    monitor = VecMonitor(mixture)
    model = PPO("MlpPolicy", monitor, n_steps=24, batch_size=60, n_epochs=1, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    costs: dict[str, list[float]] = {}

    class Record(ScenarioEpisodes):
        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:
                    costs.setdefault(info["scenario"], []).append(-info["episode"]["r"])
            return super()._on_step()

    model.learn(24 * mixture.num_envs, callback=Record())
    logged = (tmp_path / "progress.csv").read_text().splitlines()
    header, row = logged[0].split(","), logged[-1].split(",")
    for name in ("bench_mild", "bench_large_fleet"):
        value = float(row[header.index(f"rollout/ep_cost/{name}")])
        assert value == pytest.approx(np.mean(costs[name]), rel=1e-6)
    assert len(costs["bench_mild"]) == 3 * 5 and len(costs["bench_large_fleet"]) == 2 * 10


def test_pooled_slot_statistics_match_all_slots_taken_together() -> None:
    """Each slot gets the mean and variance of the K slots' values pooled, component-wise."""
    from agents.envs.slot_statistics import SlotSharedVecNormalize, pool_slot_statistics

    rng = np.random.default_rng(0)
    layout_size, k, size = 18, 3, 4
    values = rng.normal(size=(500, layout_size + k * size + 2)) * rng.uniform(0.1, 3, 32)
    mean, var = values.mean(axis=0), values.var(axis=0)
    pooled_mean, pooled_var = pool_slot_statistics(mean, var, k, size)
    slots = values[:, 18 : 18 + k * size].reshape(-1, k, size).reshape(-1, size)  # all slots
    for slot in range(k):
        part = slice(18 + slot * size, 18 + (slot + 1) * size)
        np.testing.assert_allclose(pooled_mean[part], slots.mean(axis=0))
        np.testing.assert_allclose(pooled_var[part], slots.var(axis=0))
    np.testing.assert_array_equal(pooled_mean[:18], mean[:18])  # own components untouched
    np.testing.assert_array_equal(pooled_var[-2:], var[-2:])  # extras untouched
    env = SlotSharedVecNormalize(
        FleetVecEnv(
            "bench_switching", 2, base_policy="nn_dsc", residual=ResidualConfig(neighbour_slots=6)
        ),
        6,
        4,
    )
    env.seed(0)
    env.reset()
    for _ in range(20):
        env.step(np.zeros((env.num_envs, 3)))
    rms = env.obs_rms.var[18:42].reshape(6, 4)
    np.testing.assert_array_equal(rms, np.broadcast_to(rms[0], (6, 4)))  # shared by all slots
