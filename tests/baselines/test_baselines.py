"""The analytic policies' interface: construction, act/act_batch/predict, batching, inputs."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import baselines
import cpf_env
from baselines.cooperative import LocalObservation
from baselines.policy import virtual_control
from cpf_env import scenarios
from cpf_env.model.graph import Graph
from cpf_env.model.paths import Circle
from cpf_env.model.vessel import rotation
from cpf_env.scenarios import InitialState, Scenario
from cpf_env.sim.fleet import FleetSim

NAMES = sorted(baselines.POLICIES)


def test_make_policy_accepts_every_scenario_source():
    s = scenarios.get("wang2014")
    env = cpf_env.parallel_env(s)
    for source in (env, env.sim, s, "wang2014", gymnasium.make("cpf_env/CentralizedFleet-v0")):
        policy = baselines.make_policy("nn_dsc", source)
        assert policy.scenario == s
        assert (policy.n, policy.obs_dim, policy.act_dim) == (5, env.layout.size, 5)
    with pytest.raises(TypeError, match="scenario"):
        baselines.make_policy("nn_dsc", 3.0)


def test_unknown_policy_and_option_list_the_valid_ones():
    with pytest.raises(ValueError, match="nn_dsc_no_aux"):
        baselines.make_policy("pid", "wang2014")
    with pytest.raises(ValueError, match=r"K_pi.*Gamma_W"):
        baselines.make_policy("nn_dsc", "wang2014", K3=1.0)
    with pytest.raises(ValueError, match="'K2'"):  # backstepping has no NN
        baselines.make_policy("backstepping", "wang2014", hidden=10)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("scenario", scenarios.list_scenarios())
def test_every_policy_runs_every_scenario(name, scenario):
    s = scenarios.get(scenario)
    sim = FleetSim(s, num_fleets=2)
    policy = baselines.make_policy(name, sim)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(200):
        actions = policy.act_batch(obs)
        assert actions.shape == (2, s.n, 4 + s.message_size)
        assert np.all(np.isfinite(actions))
        obs = sim.step(actions)
    assert not sim.arrays.terminated.any()
    for name_, array in policy.diagnostics.items():
        assert array.shape[:2] == (2, s.n) and np.all(np.isfinite(array)), name_


@pytest.mark.parametrize("name", NAMES)
def test_act_dict_equals_act_batch(name):
    env = cpf_env.parallel_env("lossy_links", max_steps=100)
    by_dict = baselines.make_policy(name, env)
    by_batch = baselines.make_policy(name, env)
    observations, _ = env.reset(seed=3)
    while env.agents:
        actions = by_dict.act(observations)
        batch = by_batch.act_batch(np.stack([observations[a] for a in env.possible_agents])[None])
        for i, agent in enumerate(env.possible_agents):
            assert actions[agent].dtype == np.float64 and actions[agent].shape == (5,)
            np.testing.assert_array_equal(actions[agent], batch[0, i])
        observations, *_ = env.step(actions)


@pytest.mark.parametrize("name", NAMES)
def test_batched_fleets_equal_single_fleets_bit_for_bit(name):
    s = scenarios.get("heterogeneous")
    seeds = [4, 5, 6]
    batched_sim = FleetSim(s, num_fleets=3)
    batched = baselines.make_policy(name, s)
    obs = batched_sim.reset(seeds=seeds)
    singles = [(FleetSim(s), baselines.make_policy(name, s)) for _ in seeds]
    single_obs = [sim.reset(seeds=[seed]) for (sim, _), seed in zip(singles, seeds, strict=True)]
    for _ in range(100):
        actions = batched.act_batch(obs)
        for b, (sim, policy) in enumerate(singles):
            single = policy.act_batch(single_obs[b])
            np.testing.assert_array_equal(actions[b], single[0])
            for key, value in policy.diagnostics.items():
                np.testing.assert_array_equal(batched.diagnostics[key][b], value[0], err_msg=key)
            single_obs[b] = sim.step(single)
        obs = batched_sim.step(actions)


def test_batch_size_change_needs_reset():
    s = scenarios.get("wang2014")
    obs = FleetSim(s, num_fleets=2).reset(seeds=[0, 1])
    policy = baselines.make_policy("nn_dsc", s)
    policy.act_batch(obs)
    with pytest.raises(ValueError, match=r"B = 2.*reset\(\)"):
        policy.act_batch(obs[:1])
    policy.reset(seed=0)
    assert policy.act_batch(obs[:1]).shape == (1, 5, 5)


def test_bad_observations_raise_clear_errors():
    s = scenarios.get("wang2014")
    obs = FleetSim(s).reset(seeds=[0]).copy()
    policy = baselines.make_policy("nn_dsc", s)
    for bad in (obs[0], obs[:, :4], obs[..., :-1], np.zeros((0, 5, obs.shape[-1]))):
        with pytest.raises(ValueError, match=r"\(B, n, obs_dim\) = \(B, 5, 26\)"):
            policy.act_batch(bad)
    nan = obs.copy()
    nan[0, 2, 4] = np.nan
    with pytest.raises(ValueError, match=r"vessel_2, entry 4 \(z1_y\)"):
        policy.act_batch(nan)
    with pytest.raises(ValueError, match=r"missing \['vessel_4'\]"):
        policy.act({f"vessel_{i}": obs[0, i] for i in range(4)})
    with pytest.raises(ValueError, match="predict accepts"):
        policy.predict(np.zeros(7))
    with pytest.raises(ValueError, match="episode_start"):
        policy.predict(obs[0].reshape(-1), episode_start=np.ones(3, dtype=bool))
    assert policy.diagnostics == {}  # nothing was acted on


def test_predict_layouts_round_trip():
    s = scenarios.get("wang2014")
    obs = FleetSim(s, num_fleets=2).reset(seeds=[0, 1]).copy()  # (B, n, obs_dim)
    reference = baselines.make_policy("nn_dsc", s).act_batch(obs)
    n, d, a = 5, obs.shape[-1], 5
    layouts = [
        (obs.reshape(2, n * d), (2, n * a)),  # centralized rows
        (obs.reshape(2 * n, d), (2 * n, a)),  # vessel rows
        (obs, (2, n, a)),
    ]
    for observation, shape in layouts:
        actions, state = baselines.make_policy("nn_dsc", s).predict(observation)
        assert state is None and actions.shape == shape and actions.dtype == np.float32
        np.testing.assert_array_equal(actions.reshape(2, n, a), reference.astype(np.float32))
    single, _ = baselines.make_policy("nn_dsc", s).predict(obs[1].reshape(-1))
    assert single.shape == (n * a,)
    np.testing.assert_array_equal(single.reshape(n, a), reference[1].astype(np.float32))


@pytest.mark.parametrize("per_vessel_rows", [False, True])
def test_episode_start_resets_only_that_fleet(per_vessel_rows):
    s = scenarios.get("wang2014")
    sim = FleetSim(s, num_fleets=2)
    policy = baselines.make_policy("nn_dsc", s)
    shadow = baselines.make_policy("nn_dsc", s)  # fleet 0 without any reset
    obs = sim.reset(seeds=[0, 0])
    n, d = s.n, obs.shape[-1]

    def rows(batch):
        return batch.reshape(2 * n, d) if per_vessel_rows else batch.reshape(2, n * d)

    for _ in range(30):
        actions, _ = policy.predict(
            rows(obs), episode_start=np.zeros(2 * n if per_vessel_rows else 2)
        )
        shadow.act_batch(obs[:1])
        obs = sim.step(actions.reshape(2, n, -1).astype(np.float64))
    start = np.array([False, True])
    actions, _ = policy.predict(
        rows(obs), episode_start=np.repeat(start, n) if per_vessel_rows else start
    )
    actions = actions.reshape(2, n, -1)
    fresh = baselines.make_policy("nn_dsc", s).act_batch(obs[1:])
    np.testing.assert_array_equal(actions[1], fresh[0].astype(np.float32))
    np.testing.assert_array_equal(actions[0], shadow.act_batch(obs[:1])[0].astype(np.float32))


def test_evaluate_policy_on_the_centralized_gym_env():
    # SB3 is an optional dependency ([rl]); .ci/lower-bounds runs without it.
    evaluate_policy = pytest.importorskip("stable_baselines3.common.evaluation").evaluate_policy
    DummyVecEnv = pytest.importorskip("stable_baselines3.common.vec_env").DummyVecEnv
    envs = DummyVecEnv(
        [lambda: gymnasium.make("cpf_env/CentralizedFleet-v0", max_steps=40) for _ in range(2)]
    )
    policy = baselines.make_policy("nn_dsc", "wang2014")
    with pytest.warns(UserWarning, match="Monitor"):
        rewards, lengths = evaluate_policy(
            policy, envs, n_eval_episodes=4, deterministic=True, return_episode_rewards=True
        )
    assert lengths == [40] * 4
    # The same episode each time: the policy restarted its internal states at every episode start.
    np.testing.assert_allclose(rewards, rewards[0], rtol=1e-6)
    s = scenarios.get("wang2014")
    sim = FleetSim(s)
    reference = baselines.make_policy("nn_dsc", s)
    obs, total = sim.reset(seeds=[0]), 0.0
    for _ in range(40):
        obs = sim.step(reference.act_batch(obs).astype(np.float32))
        total += sim.arrays.reward[0].mean()
    np.testing.assert_allclose(rewards[0], total, rtol=1e-5)


def _apply_s(x: np.ndarray) -> np.ndarray:
    """S x for S = [[0, -1, 0], [1, 0, 0], [0, 0, 0]], x of shape (..., 3)."""
    return np.stack([-x[..., 1], x[..., 0], np.zeros_like(x[..., 0])], axis=-1)


def _alpha_derivative(k1, obs: LocalObservation, theta_dot, vhat, vhat_dot) -> np.ndarray:
    """Independent transcription of backstepping's analytic alpha' ([13]-[15], Remark 1)."""
    r = obs.nu[..., 2:3]
    z1_dot = -r * _apply_s(obs.z1) + obs.nu - obs.t1 * theta_dot[..., None]
    t1_dot = -r * _apply_s(obs.t1) + obs.t2 * theta_dot[..., None]
    return -k1 * z1_dot + t1_dot * vhat[..., None] + obs.t1 * vhat_dot[..., None]


def _synthetic_observation(t: float, path) -> tuple[LocalObservation, float, float]:
    """Local observation along a smooth made-up trajectory; returns (obs, theta', vhat)."""
    eta = np.array([0.8 * t - 0.5, 2.0 + 0.3 * np.sin(t), 0.2 + 0.4 * np.cos(0.7 * t)])
    eta_dot = np.array([0.8, 0.3 * np.cos(t), -0.28 * np.sin(0.7 * t)])
    theta, theta_dot = 0.7 * t + 0.2 * np.sin(1.3 * t), 0.7 + 0.26 * np.cos(1.3 * t)
    vhat = 0.3 + 0.1 * np.sin(2.0 * t)
    point = path.evaluate(theta)  # rows eta_d, eta_d', eta_d''
    rot_t = rotation(eta[2]).T
    zero = np.zeros((1, 1, 1))
    obs = LocalObservation(
        nu=(rot_t @ eta_dot)[None, None],
        z1=(rot_t @ (eta - point[0]))[None, None],
        t1=(rot_t @ point[1])[None, None],
        t2=(rot_t @ point[2])[None, None],
        theta=np.full((1, 1), theta),
        tau_applied=np.zeros((1, 1, 3)),
        leader=np.zeros((1, 1)),
        v0=np.zeros((1, 1)),
        weight=zero,
        dtheta=zero,
        message=zero,
    )
    return obs, theta_dot, vhat


def test_backstepping_alpha_dot_matches_finite_differences_of_alpha():
    path = scenarios.get("wang2014").paths[1]
    k1 = np.array([1.0, 1.5, 2.0])
    h = 1e-5
    for t in np.linspace(0.0, 6.0, 13):
        obs, theta_dot, vhat = _synthetic_observation(t, path)
        vhat_dot = 0.2 * np.cos(2.0 * t)
        analytic = _alpha_derivative(
            k1, obs, np.full((1, 1), theta_dot), np.full((1, 1), vhat), np.full((1, 1), vhat_dot)
        )
        alpha = []
        for tk in (t - h, t + h):
            o, _, v = _synthetic_observation(tk, path)
            alpha.append(virtual_control(k1, o.z1, o.t1, np.full((1, 1), v)))
        np.testing.assert_allclose(analytic, (alpha[1] - alpha[0]) / (2 * h), rtol=1e-6, atol=1e-8)


def test_backstepping_alpha_dot_along_the_closed_loop():
    s = scenarios.get("wang2014").replace(dt=0.01, substeps=1)
    sim = FleetSim(s)
    policy = baselines.make_policy("backstepping", sim)
    obs = sim.reset(seeds=[0])
    alpha, alpha_dot = [], []
    for _ in range(600):
        obs = sim.step(policy.act_batch(obs))
        alpha.append(policy.diagnostics["alpha"][0].copy())
        alpha_dot.append(policy.diagnostics["nubar_dot"][0].copy())
    alpha, alpha_dot = np.array(alpha[100:]), np.array(alpha_dot[100:])
    difference = (alpha[1:] - alpha[:-1]) / s.dt
    scale = np.abs(alpha_dot).max(axis=(0, 1))
    assert np.all(np.abs(difference - alpha_dot[:-1]).max(axis=(0, 1)) < 0.02 * scale)


def test_backstepping_kernel_alpha_dot_equals_the_transcription():
    """The compiled alpha' is the formula checked above, on the inputs the policy used."""
    s = scenarios.get("lossy_links")
    sim = FleetSim(s, num_fleets=2)
    policy = baselines.make_policy("backstepping", sim)
    g = policy.gains
    obs = sim.reset(seeds=[1, 2])
    for _ in range(200):
        local = LocalObservation.parse(policy.layout, obs.astype(np.float64))
        actions = policy.act_batch(obs)
        vhat = policy.diagnostics["speed_estimate"]
        degree = local.weight.sum(axis=-1)
        neighbours = (local.weight * local.message).sum(axis=-1)
        vhat_dot = -g.k5 * (degree * vhat - neighbours) - g.k6 * local.leader * (vhat - local.v0)
        expected = _alpha_derivative(np.array(g.K1), local, actions[..., 3], vhat, vhat_dot)
        np.testing.assert_allclose(policy.diagnostics["nubar_dot"], expected, rtol=1e-9, atol=1e-12)
        obs = sim.step(actions)


@pytest.mark.parametrize("name", NAMES)
def test_lone_vessel_without_neighbour_slots(name):
    """n = 1, K = 0: the cooperative layer has nothing to sum and the vessel still follows."""
    scenario = Scenario(
        name="lone",
        paths=(Circle(radius=5.0),),
        topology=Graph.path(1, leaders=(0,)),
        initial=InitialState(eta=((5.5, 0.0, 1.6),)),
        max_steps=1200,
    )
    env = cpf_env.parallel_env(scenario, info_level="minimal")
    assert env.layout.n_slots == 0
    observations, _ = env.reset(seed=0)
    policy = baselines.make_policy(name, env)
    while env.agents:
        observations, _, terminations, _, infos = env.step(policy.act(observations))
    assert not terminations["vessel_0"]
    assert infos["vessel_0"]["path_error"] < 0.01


def test_the_readmes_act_loop_follows_fleetsim_bit_for_bit():
    """README's ``env.step(policy.act(observations))`` loop against FleetSim + act_batch."""
    env = cpf_env.parallel_env("bench_lossy_links", max_steps=400)
    policy = baselines.make_policy("nn_dsc", env)
    observations, _ = env.reset(seed=11)
    sim = FleetSim(env.scenario, num_fleets=1)
    reference = baselines.make_policy("nn_dsc", env.scenario)
    obs = sim.reset(seeds=[11])
    steps = 0
    while env.agents:
        observations, *_ = env.step(policy.act(observations))
        obs = sim.step(reference.act_batch(obs))
        steps += 1
        np.testing.assert_array_equal(env.sim.arrays.eta, sim.arrays.eta)
        np.testing.assert_array_equal(np.stack([observations[a] for a in env.agents or
                                                env.possible_agents]), obs[0])  # fmt: skip
    assert steps == 400
