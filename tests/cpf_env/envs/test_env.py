"""The PettingZoo env: API conformance, episode logic, bad input, reward, batch equivalence."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import (
    TAU_MAX,
    TAU_MIN,
    assert_unchanged,
    fast_switching,
    random_actions,
    rotation_matrix,
    snapshot,
)
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test

import cpf_env
from cpf_env import scenarios
from cpf_env.envs.core import INFO_LEVELS
from cpf_env.envs.parallel import CooperativePathFollowingEnv
from cpf_env.model.links import LinkImpairments
from cpf_env.scenarios import Scenario, SpeedSchedule
from cpf_env.scenarios.reward_weights import REWARD_TERMS, RewardWeights
from cpf_env.sim.fleet import FleetSim

SCENARIO_NAMES = scenarios.list_scenarios()
INFO_KEYS = {
    "path_error",
    "heading_error",
    "sync_error",
    "speed_error",
    "tau_command",
    "tau_applied",
    "saturated",
    "eta",
    "nu",
    "theta",
}


def as_dict(env: CooperativePathFollowingEnv, batch: np.ndarray) -> dict[str, np.ndarray]:
    return {agent: batch[0, i] for i, agent in enumerate(env.possible_agents)}


# --- PettingZoo conformance -------------------------------------------------------------


# PettingZoo's API tests reset with options={"options": 1}; the env warns that it ignores them.
_IGNORED_OPTIONS = "reset ignores options ['options']"


@pytest.mark.filterwarnings("ignore:reset ignores options")
@pytest.mark.filterwarnings("error::UserWarning")
@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_parallel_api(name: str) -> None:
    parallel_api_test(cpf_env.parallel_env(name, max_steps=25), num_cycles=60)


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_aec_api(name: str) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        api_test(cpf_env.env(name, max_steps=25), num_cycles=60)
    # No warning but the one about the test's own reset options (bounds are finite).
    unexpected = [str(w.message) for w in caught if not str(w.message).startswith(_IGNORED_OPTIONS)]
    assert not unexpected


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_seed_tests(name: str) -> None:
    parallel_seed_test(lambda: cpf_env.parallel_env(name, max_steps=25), num_cycles=30)
    seed_test(lambda: cpf_env.env(name, max_steps=25), num_cycles=30)


def test_metadata_and_factories() -> None:
    env = cpf_env.parallel_env()
    assert isinstance(env, CooperativePathFollowingEnv)
    assert cpf_env.raw_env is CooperativePathFollowingEnv
    assert env.metadata["name"] == "cooperative_path_following_v0"
    assert env.metadata["render_modes"] == ["human", "rgb_array"]
    assert env.scenario == scenarios.get("wang2014")
    assert env.possible_agents == [f"vessel_{i}" for i in range(5)]
    assert env.agents == []
    custom = scenarios.get("large_fleet").replace(max_steps=9)
    assert cpf_env.parallel_env(custom).scenario is custom
    assert cpf_env.parallel_env("lossy_links", dt=0.1).scenario.dt == 0.1


@pytest.mark.parametrize(
    ("args", "kwargs", "error", "match"),
    [
        ((), {"bogus": 1}, ValueError, "unknown Scenario field.*bogus"),
        (("no_such_scenario",), {}, ValueError, "unknown scenario 'no_such_scenario'.*wang2014"),
        ((42,), {}, TypeError, "scenario must be a name"),
        ((), {"render_mode": "ansi"}, ValueError, "render_mode must be one of"),
        ((), {"info_level": "some"}, ValueError, "info_level must be one of.*'minimal'"),
    ],
)
def test_bad_factory_arguments(args: tuple, kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        cpf_env.parallel_env(*args, **kwargs)


def test_spaces_are_cached_and_match_the_scenario() -> None:
    env = cpf_env.parallel_env("wang2014", tau_max=TAU_MAX, tau_min=TAU_MIN, message_size=2)
    for i, agent in enumerate(env.possible_agents):
        assert env.action_space(agent) is env.action_space(agent)
        assert env.observation_space(agent) is env.observation_space(agent)
        action_space = env.action_space(agent)
        assert action_space.dtype == np.float32 and action_space.shape == (6,)
        np.testing.assert_array_equal(action_space.low, np.float32([*TAU_MIN[i], -1, -10, -10]))
        np.testing.assert_array_equal(action_space.high, np.float32([*TAU_MAX[i], 1, 10, 10]))
        obs_space = env.observation_space(agent)
        assert obs_space.dtype == np.float32 and obs_space.shape == (18 + 2 * (3 + 2),)
    with pytest.raises(ValueError, match="unknown agent 'vessel_5'"):
        env.action_space("vessel_5")
    with pytest.raises(ValueError, match="unknown agent"):
        env.observation_space("boat_0")


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_reset_state_and_infos(name: str) -> None:
    env = cpf_env.parallel_env(name, info_level="full")
    observations, infos = env.reset(seed=3)
    assert env.agents == env.possible_agents
    assert set(observations) == set(infos) == set(env.possible_agents)
    rng = np.random.default_rng(0)
    for _ in range(2):
        for agent in env.possible_agents:
            obs = observations[agent]
            assert obs.dtype == np.float32 and env.observation_space(agent).contains(obs)
            assert INFO_KEYS <= set(infos[agent])
            info = infos[agent]
            for key in ("tau_command", "tau_applied", "saturated", "eta", "nu"):
                assert np.shape(info[key]) == (3,), key
            assert info["saturated"].dtype == bool
            for key in ("path_error", "heading_error", "sync_error", "speed_error", "theta"):
                assert isinstance(info[key], float), key
        state = env.state()
        assert state.shape == env.state_space.shape == (env.scenario.n * 10,)
        assert state.dtype == np.float32
        a = env.sim.arrays
        per_vessel = np.concatenate([a.eta[0], a.nu[0], a.theta[0][:, None], a.tau_applied[0]], 1)
        np.testing.assert_array_equal(state, per_vessel.astype(np.float32).ravel())
        observations, *_, infos = env.step(as_dict(env, random_actions(rng, env.sim)))


def test_infos_report_command_saturation_and_state() -> None:
    env = cpf_env.parallel_env("wang2014", info_level="full", tau_max=TAU_MAX, tau_min=TAU_MIN)
    env.reset(seed=0)
    rng = np.random.default_rng(4)
    for _ in range(20):
        batch = random_actions(rng, env.sim, overdrive=2.0)
        *_, infos = env.step(as_dict(env, batch))
        a = env.sim.arrays
        for i, agent in enumerate(env.possible_agents):
            command = batch[0, i, :3]
            applied = np.clip(command, TAU_MIN[i], TAU_MAX[i])
            info = infos[agent]
            np.testing.assert_array_equal(info["tau_command"], command)
            np.testing.assert_array_equal(info["tau_applied"], applied)
            np.testing.assert_array_equal(info["saturated"], command != applied)
            np.testing.assert_array_equal(info["eta"], a.eta[0, i])
            np.testing.assert_array_equal(info["nu"], a.nu[0, i])
            assert info["theta"] == a.theta[0, i]


def test_info_levels_carry_less_but_the_same_values() -> None:
    envs = {level: cpf_env.parallel_env("lossy_links", info_level=level) for level in INFO_LEVELS}
    rng = np.random.default_rng(5)
    first = {level: env.reset(seed=2) for level, env in envs.items()}
    for step in range(30):
        if step:
            batch = random_actions(rng, envs["full"].sim)
            first = {level: env.step(as_dict(env, batch)) for level, env in envs.items()}
        observations = {level: out[0] for level, out in first.items()}
        infos = {level: out[-1] for level, out in first.items()}
        for agent in envs["full"].possible_agents:
            np.testing.assert_array_equal(observations["none"][agent], observations["full"][agent])
            assert infos["none"][agent] == {}
            errors = ("path_error", "heading_error", "sync_error", "speed_error")
            assert set(infos["minimal"][agent]) == set(errors)
            for key in errors:
                assert infos["minimal"][agent][key] == infos["full"][agent][key]


def test_render_accepts_the_construction_mode_positionally() -> None:
    env = cpf_env.parallel_env("wang2014", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render("rgb_array")  # RLlib's ParallelPettingZooEnv calls render(mode)
    np.testing.assert_array_equal(frame, env.render())
    with pytest.raises(ValueError, match=r"render mode 'human' differs.*render_mode='human'"):
        env.render("human")
    env.close()


# --- episode end --------------------------------------------------------------------------


def test_termination_when_a_vessel_leaves_its_path() -> None:
    env = cpf_env.parallel_env("wang2014", info_level="minimal", max_path_error=3.0)
    env.reset(seed=0)
    actions = {agent: np.zeros(5, dtype=np.float32) for agent in env.agents}
    actions["vessel_2"] = np.array([9.2, 0.0, 0.0, 0.0, 0.0], dtype=np.float32)  # full ahead
    steps = 0
    while steps < 400:
        _, _, terminations, truncations, infos = env.step(actions)
        steps += 1
        errors = np.array([infos[agent]["path_error"] for agent in env.possible_agents])
        expected = bool(np.any(errors > 3.0))
        assert terminations == dict.fromkeys(env.possible_agents, expected)
        assert truncations == dict.fromkeys(env.possible_agents, False)
        if expected:
            assert np.argmax(errors) == 2 and errors[2] < 3.1  # right at the threshold
            break
    else:
        pytest.fail("vessel_2 never left its path")
    assert steps > 20 and env.agents == []
    with pytest.raises(RuntimeError, match="episode is over"):
        env.step(actions)
    env.reset()
    assert env.agents == env.possible_agents


def test_truncation_at_max_steps() -> None:
    env = cpf_env.parallel_env("lossy_links", max_steps=7)
    for _ in range(2):  # a second episode after reset behaves the same
        env.reset(seed=1)
        actions = {agent: np.zeros(5, dtype=np.float32) for agent in env.agents}
        for step in range(1, 8):
            _, _, terminations, truncations, _ = env.step(actions)
            assert not any(terminations.values())
            assert truncations == dict.fromkeys(env.possible_agents, step == 7)
        assert env.agents == []
        with pytest.raises(RuntimeError, match="call reset"):
            env.step(actions)


def test_step_before_reset_raises() -> None:
    env = cpf_env.parallel_env()
    with pytest.raises(RuntimeError, match="reset"):
        env.step({agent: np.zeros(5) for agent in env.possible_agents})


# --- bad input ----------------------------------------------------------------------------

GOOD = np.array([1.0, -0.5, 0.2, 0.1, 0.3])


def bad_actions(kind: str) -> object:
    actions: dict[str, object] = {f"vessel_{i}": GOOD.copy() for i in range(5)}
    if kind == "missing":
        del actions["vessel_2"]
    elif kind == "extra":
        actions["vessel_9"] = GOOD.copy()
    elif kind == "short":
        actions["vessel_2"] = GOOD[:4]
    elif kind == "long":
        actions["vessel_2"] = np.append(GOOD, 0.0)
    elif kind == "2d":
        actions["vessel_2"] = GOOD[None, :]
    elif kind == "scalar":
        actions["vessel_2"] = 1.0
    elif kind == "nan":
        actions["vessel_2"] = np.array([1.0, np.nan, 0.0, 0.1, 0.0])
    elif kind == "inf":
        actions["vessel_2"] = np.array([1.0, 0.0, 0.0, np.inf, 0.0])
    elif kind == "not_a_dict":
        return np.tile(GOOD, (5, 1))
    return actions


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("missing", r"missing \['vessel_2'\]"),
        ("extra", r"unexpected \['vessel_9'\]"),
        ("short", r"vessel_2 has shape \(4,\); expected \(5,\)"),
        ("long", r"vessel_2 has shape \(6,\); expected \(5,\)"),
        ("2d", r"vessel_2 has shape \(1, 5\)"),
        ("scalar", r"vessel_2 has shape \(\)"),
        ("nan", r"vessel_2 is not finite"),
        ("inf", r"vessel_2 is not finite"),
        ("not_a_dict", r"actions must be a dict"),
    ],
)
def test_bad_actions_raise_and_change_nothing(kind: str, match: str) -> None:
    env, twin = cpf_env.parallel_env("lossy_links"), cpf_env.parallel_env("lossy_links")
    rng = np.random.default_rng(0)
    for e in (env, twin):
        e.reset(seed=5)
    for _ in range(5):
        batch = random_actions(rng, env.sim)
        env.step(as_dict(env, batch))
        twin.step(as_dict(twin, batch))
    before, agents = snapshot(env.sim), list(env.agents)
    with pytest.raises(ValueError, match=match):
        env.step(bad_actions(kind))  # type: ignore[arg-type]
    assert_unchanged(before, env.sim)
    assert env.agents == agents
    # Nothing hidden moved either: the next good step matches an env that never saw the error.
    batch = random_actions(rng, env.sim)
    results = [e.step(as_dict(e, batch)) for e in (env, twin)]
    for agent in env.possible_agents:
        assert np.array_equal(results[0][0][agent], results[1][0][agent])
        assert results[0][1][agent] == results[1][1][agent]


@pytest.mark.parametrize(
    ("first", "second", "match"),
    [
        ("nan", "short", r"vessel_1 is not finite"),
        ("short", "nan", r"vessel_1 has shape \(4,\)"),
        ("complex", "nan", r"action of vessel_1 must be real numbers"),
    ],
)
def test_the_first_bad_action_in_agent_order_is_reported(
    first: str, second: str, match: str
) -> None:
    """Checked in one pass, the actions still fail on the first bad agent, as one by one."""
    bad = {"nan": np.array([0.0, np.nan, 0, 0, 0]), "short": GOOD[:4], "complex": GOOD + 1j}
    env = cpf_env.parallel_env("wang2014")
    env.reset(seed=0)
    before = snapshot(env.sim)
    actions = {agent: GOOD.copy() for agent in env.agents}
    actions["vessel_1"], actions["vessel_3"] = bad[first], bad[second]
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    assert_unchanged(before, env.sim)


def test_observations_and_info_arrays_are_each_agents_own() -> None:
    """Rows of one copy per quantity: writing one agent's entry changes nothing else."""
    env = cpf_env.parallel_env("wang2014", info_level="full")
    env.reset(seed=0)
    observations, *_, infos = env.step(
        as_dict(env, random_actions(np.random.default_rng(1), env.sim))
    )
    before = snapshot(env.sim)
    kept_obs, kept_eta = observations["vessel_1"].copy(), infos["vessel_1"]["eta"].copy()
    for key in ("tau_command", "tau_applied", "eta", "nu", "reward_terms"):
        infos["vessel_0"][key][:] = 7.0
    infos["vessel_0"]["saturated"][:] = True
    observations["vessel_0"][:] = 7.0
    assert_unchanged(before, env.sim)
    assert np.array_equal(observations["vessel_1"], kept_obs)
    assert np.array_equal(infos["vessel_1"]["eta"], kept_eta)


# --- reward -------------------------------------------------------------------------------

WEIGHTS = RewardWeights(
    position=0.7, heading=0.3, sync=1.3, speed=2.1, effort=0.05, form="quadratic"
)
LOG_WEIGHTS = RewardWeights(
    position=0.7,
    heading=0.3,
    sync=1.3,
    speed=2.1,
    effort=0.05,
    position_scale=0.02,
    heading_scale=0.07,
    sync_scale=0.03,
    speed_scale=0.005,
)


def reward_scenarios() -> dict[str, Scenario]:
    v0 = SpeedSchedule((0.0, 1.02), (0.1, 0.25))
    return {
        "custom_weights": scenarios.get("wang2014").replace(
            reward=WEIGHTS, tau_max=TAU_MAX, tau_min=TAU_MIN, v0=v0
        ),
        "lossy_links": scenarios.get("lossy_links").replace(
            reward=WEIGHTS, links=LinkImpairments(0.5, 3)
        ),
        "switching_topology": fast_switching(reward=WEIGHTS),
        "heterogeneous": scenarios.get("heterogeneous"),
        "log_form": scenarios.get("lossy_links").replace(
            reward=LOG_WEIGHTS, tau_max=TAU_MAX, tau_min=TAU_MIN, v0=v0
        ),
    }


def expected_terms(w: RewardWeights, dt: float, errors: tuple[float, ...]) -> np.ndarray:
    """Each term's -dt w_k c_k from the errors (path, heading, sync, speed, ||tau/tau_max||)."""
    weights = np.array([w.position, w.heading, w.sync, w.speed, w.effort])
    x = np.array(errors)
    if w.form == "log":
        scales = np.array([w.position_scale, w.heading_scale, w.sync_scale, w.speed_scale])
        costs = np.append(np.log1p((x[:4] / scales) ** 2), x[4] ** 2)
    else:
        costs = x**2
    return np.append(-dt * weights * costs, [0.0, 0.0])  # no failure, no separation


def wrap(angle: float) -> float:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@pytest.mark.parametrize("name", list(reward_scenarios()))
def test_reward_equals_the_documented_formula(name: str) -> None:
    """r_i = -dt sum_k w_k rho(x_k / scale_k) (log form) or -dt (w_pos |z1_xy|^2 + ... +
    w_tau |tau_i / tau_max|^2) (quadratic form), s_i on the true path variables of the active
    graph; the infos' reward_terms are the terms and sum to the reward."""
    scenario = reward_scenarios()[name].replace(max_path_error=1e6)
    env = cpf_env.parallel_env(scenario, info_level="full")
    env.reset(seed=2)
    w, dt, n = scenario.reward, scenario.dt, scenario.n
    tau_scale = np.maximum(np.abs(np.array(scenario.tau_min)), np.abs(np.array(scenario.tau_max)))
    rng = np.random.default_rng(3)
    for step in range(1, 61):
        batch = random_actions(rng, env.sim, overdrive=1.5, rate=0.2)
        _, rewards, _, _, infos = env.step(as_dict(env, batch))
        v0 = scenario.v0.at((step - 1) * dt)  # the speed in force while the rate was applied
        adjacency = scenario.switching.graph_at(step).adjacency
        theta = np.array([infos[agent]["theta"] for agent in env.possible_agents])
        for i, agent in enumerate(env.possible_agents):
            info = infos[agent]
            point = scenario.paths[i].evaluate(theta[i])
            z1 = rotation_matrix(info["eta"][2]).T @ (info["eta"] - point[0])
            z1[2] = wrap(info["eta"][2] - point[0, 2])
            sync = float(np.sum(adjacency[i] * (theta[i] - theta)))
            speed = float(np.clip(batch[0, i, 3], -1.0, 1.0)) - v0
            effort = np.sqrt(np.sum((info["tau_applied"] / tau_scale[i]) ** 2))
            terms = expected_terms(w, dt, (np.hypot(z1[0], z1[1]), z1[2], sync, speed, effort))
            assert rewards[agent] == pytest.approx(terms.sum(), rel=1e-12, abs=1e-15)
            reported = info["reward_terms"]
            assert reported.shape == (len(REWARD_TERMS),)
            np.testing.assert_allclose(reported, terms, rtol=1e-11, atol=1e-15)
            assert rewards[agent] == pytest.approx(reported.sum(), rel=1e-14, abs=1e-16)
            assert info["path_error"] == pytest.approx(np.hypot(z1[0], z1[1]), rel=1e-12)
            assert info["heading_error"] == pytest.approx(z1[2], rel=1e-12, abs=1e-15)
            assert info["sync_error"] == pytest.approx(sync, rel=1e-12, abs=1e-15)
            assert info["speed_error"] == pytest.approx(speed, rel=1e-12, abs=1e-15)
    assert n == len(rewards)


def test_team_reward_is_the_fleet_mean() -> None:
    base = scenarios.get("current_and_waves").replace(reward=WEIGHTS)
    team = base.replace(reward=RewardWeights(**{**WEIGHTS.__dict__, "team": True}))
    envs = [cpf_env.parallel_env(s) for s in (base, team)]
    for env in envs:
        env.reset(seed=8)
    rng = np.random.default_rng(1)
    for _ in range(30):
        batch = random_actions(rng, envs[0].sim)
        individual, shared = (env.step(as_dict(env, batch))[1] for env in envs)
        mean = np.mean(list(individual.values()))
        assert len(set(individual.values())) > 1
        for agent in envs[1].possible_agents:
            assert shared[agent] == pytest.approx(mean, rel=1e-12)


# --- equivalence with the batched simulator ----------------------------------------------


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_env_equals_fleet_k_of_a_batched_sim(name: str) -> None:
    """ParallelEnv (B = 1) and fleet k of FleetSim(B = 3), same seeds: same bits every step,
    through a re-seeded reset of fleet 1 and an unseeded reset of fleet 2."""
    envs = [cpf_env.parallel_env(name, max_path_error=1e6, max_steps=10_000) for _ in range(3)]
    sim = FleetSim(envs[0].scenario, num_fleets=3)
    seeds = [10, 11, 12]
    sim.reset(seeds=seeds)
    for env, seed in zip(envs, seeds, strict=True):
        env.reset(seed=seed)
    rng = np.random.default_rng(0)
    for step in range(300):
        if step == 100:
            sim.reset(seeds=[99], fleets=[1])
            envs[1].reset(seed=99)
        if step == 200:
            sim.reset(seeds=[None], fleets=[2])
            envs[2].reset()
        batch = random_actions(rng, sim).astype(np.float32).astype(np.float64)
        sim.step(batch)
        for k, env in enumerate(envs):
            observations, rewards, *_ = env.step(as_dict(env, batch[k : k + 1]))
            for i, agent in enumerate(env.possible_agents):
                assert np.array_equal(observations[agent], sim.arrays.obs[k, i])
                assert rewards[agent] == sim.arrays.reward[k, i]
            for field, value in sim.arrays._asdict().items():
                assert np.array_equal(getattr(env.sim.arrays, field)[0], value[k]), (
                    f"fleet {k}: {field} differs at step {step}"
                )


def test_closed_envs_are_freed_after_their_spaces_were_asked_for() -> None:
    """200 make/close cycles leave no env alive (the spaces are cached per instance)."""
    import gc
    import weakref

    from baselines import make_policy

    alive = []
    for _ in range(200):
        env = cpf_env.parallel_env("wang2014")
        inner = cpf_env.parallel_env("wang2014")
        wrapped = cpf_env.parallel_env(
            "wang2014", base_policy=make_policy("nn_dsc", inner.scenario)
        )
        for agent in env.possible_agents:
            assert env.observation_space(agent) is env.observation_space(agent)
            env.action_space(agent)
            assert wrapped.action_space(agent) is wrapped.action_space(agent)
            wrapped.observation_space(agent)
        env.close()
        wrapped.close()
        alive += [weakref.ref(env), weakref.ref(wrapped), weakref.ref(inner)]
        del env, wrapped, inner
    gc.collect()
    assert sum(ref() is not None for ref in alive) == 0
