"""Residual control: the composition rule, what the base is told, the ParallelEnv's form."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import cpf_env
from baselines import make_policy
from cpf_env import FleetSim, scenarios
from cpf_env.envs.parallel import CooperativePathFollowingEnv
from cpf_env.envs.residual import EXTRAS, ResidualConfig, ResidualController

SCENARIO = "bench_lossy_links"  # random starts and packet loss: every seed differs


def wrapped(steps: int = 300, **options: object) -> CooperativePathFollowingEnv:
    scenario = cpf_env.scenarios.make_scenario(SCENARIO, max_steps=steps)
    return cpf_env.parallel_env(
        scenario,
        info_level="full",
        base_policy=make_policy("nn_dsc", scenario),
        residual=ResidualConfig(**options),  # type: ignore[arg-type]
    )


@pytest.mark.parametrize("mode", ["force", "force_and_rate", "kinematic"])
def test_zero_residual_reproduces_the_base_policy_bit_for_bit(mode: str) -> None:
    """A whole episode (300 steps, lossy links, random start) with a = 0 equals the base alone."""
    reference = cpf_env.parallel_env(SCENARIO, max_steps=300)
    policy = make_policy("nn_dsc", reference)
    expected, _ = reference.reset(seed=7)
    env = wrapped(300, mode=mode, extras=("multiscale_errors",) if mode == "kinematic" else ())
    observations, _ = env.reset(seed=7)
    d = reference.layout.size
    steps = 0
    while reference.agents:
        actions = policy.act(expected)
        expected, rewards, terms, truncs, _ = reference.step(actions)
        zero = {agent: np.zeros(env.core.action_size, np.float32) for agent in env.agents}
        observations, got_rewards, got_terms, got_truncs, infos = env.step(zero)
        for agent in expected:
            assert np.array_equal(observations[agent][:d], expected[agent])
            assert got_rewards[agent] == rewards[agent]
            assert np.array_equal(infos[agent]["residual"], np.zeros(env.core.action_size))
        assert (got_terms, got_truncs) == (terms, truncs)
        steps += 1
    assert steps == 300 and not env.agents


def test_force_residual_is_composed_in_physical_units_before_saturation() -> None:
    """tau0 = tau_base + scale * tau_limit * a; the plant saturation is the only clip."""
    scenario = scenarios.get("wang2014")
    sim = FleetSim(scenario, num_fleets=2)
    loop = ResidualController(
        scenario,
        make_policy("nn_dsc", scenario),
        2,
        ResidualConfig(mode="force_and_rate", scale=0.5),
    )
    loop.observe(sim.reset(seeds=[0, 1]))
    base = loop.base_actions.copy()
    a = np.random.default_rng(0).uniform(-1.0, 1.0, size=(2, 5, 4))
    command = loop.compose(a)
    limit = np.array([9.2, 4.5, 3.0])
    np.testing.assert_allclose(
        command[..., :3], base[..., :3] + 0.5 * limit * a[..., :3], rtol=1e-14
    )
    np.testing.assert_allclose(command[..., 3], base[..., 3] + 0.5 * 1.0 * a[..., 3], rtol=1e-14)
    assert np.array_equal(command[..., 4:], base[..., 4:])  # messages stay the base's
    sim.step(command)
    applied = sim.arrays.tau_applied
    assert np.array_equal(applied, np.clip(command[..., :3], -limit, limit))


def test_out_of_range_residual_is_clipped_to_the_unit_box() -> None:
    scenario = scenarios.get("wang2014")
    loop = ResidualController(scenario, make_policy("nn_dsc", scenario), 1)
    loop.observe(FleetSim(scenario).reset(seeds=[0]))
    base = loop.base_actions.copy()
    command = loop.compose(np.full((1, 5, 3), 7.0))
    np.testing.assert_allclose(command[..., :3], base[..., :3] + 0.2 * np.array([9.2, 4.5, 3.0]))


@pytest.mark.parametrize("hide", [True, False])
def test_what_the_auxiliary_system_sees_of_a_residual(hide: bool) -> None:
    """Hidden (default): a constant, unsaturating residual leaves pi at rounding level.
    Shown: pi settles near residual / K_pi, the residual looks like saturation."""
    scenario = scenarios.get("wang2014")
    sim = FleetSim(scenario)
    base = make_policy("nn_dsc", scenario)
    loop = ResidualController(
        scenario, base, 1, ResidualConfig(scale=0.05, hide_residual_from_base=hide)
    )
    obs = sim.reset(seeds=[0])
    for _ in range(600):  # past the saturated start
        loop.observe(obs)
        obs = sim.step(loop.compose(np.zeros((1, 5, 3))))
    residual = np.zeros((1, 5, 3))
    residual[..., 0] = 1.0  # +0.46 N surge
    for _ in range(100):
        loop.observe(obs)
        obs = sim.step(loop.compose(residual))
    assert not np.any(sim.arrays.tau_command != sim.arrays.tau_applied)  # nothing saturates
    pi = base.diagnostics["aux_state"][0, :, 0]
    expected = 0.05 * 9.2 / 200.0  # residual / K_pi
    if hide:
        assert np.all(np.abs(pi) < 1e-3 * expected)
    else:
        np.testing.assert_allclose(pi, expected, rtol=0.05)


def test_extras_are_the_documented_signals() -> None:
    scenario = scenarios.get("wang2014")
    config = ResidualConfig(extras=("base_action", "base_signals", "multiscale_errors"))
    base = make_policy("nn_dsc", scenario)
    loop = ResidualController(scenario, base, 1, config)
    obs = FleetSim(scenario).reset(seeds=[0])
    inputs = loop.observe(obs)
    d = loop.layout.size
    assert inputs.shape == (1, 5, d + sum(EXTRAS.values()))
    assert np.array_equal(inputs[..., :d], obs)
    action = inputs[..., d : d + 4]
    np.testing.assert_allclose(
        action[..., :3] * np.array([9.2, 4.5, 3.0]), loop.base_actions[..., :3]
    )
    signals = inputs[..., d + 4 : d + 11]
    np.testing.assert_array_equal(signals[..., 0], base.diagnostics["speed_estimate"])
    np.testing.assert_array_equal(signals[..., 1:4], base.diagnostics["nubar_dot"])
    z1 = obs[..., loop.layout.z1].astype(np.float64)
    np.testing.assert_allclose(inputs[..., d + 11 : d + 14], np.tanh(z1 / 0.01))
    np.testing.assert_allclose(inputs[..., d + 17 : d + 20], np.tanh(z1 / 1.0))


def test_a_residual_yields_to_a_base_at_an_actuator_limit() -> None:
    """With yield_at_limit, a pull back from a limit the base commands is dropped, axis by axis."""
    scenario = scenarios.get("wang2014")
    sim = FleetSim(scenario, num_fleets=1)
    obs = sim.reset(seeds=[0])
    limit = np.array([9.2, 4.5, 3.0])
    # per vessel: the base's force (N, N, N m) and the residual's sign on every axis
    base = np.array(
        [
            limit,  # at tau_max
            limit * 1.5,  # past tau_max (an analytic base saturating)
            limit * (1 - 0.5e-3),  # within the tolerance of tau_max
            limit * (1 - 0.01),  # inside the limits
            -limit,  # at tau_min
        ]
    )
    signs = np.array([-1, 1, -1])  # the residual pulls back on surge and yaw, pushes on sway
    a = np.tile(0.4 * signs, (1, 5, 1)).astype(np.float64)
    commands = {}
    for gate in (False, True):
        loop = ResidualController(
            scenario,
            make_policy("nn_dsc", scenario),
            1,
            ResidualConfig(scale=0.5, yield_at_limit=gate),
        )
        loop.observe(obs)
        loop.base_actions[0, :, :3] = base
        commands[gate] = loop.compose(a)
        applied_residual = loop.residual.copy()
    force = 0.5 * limit * a[0]
    np.testing.assert_allclose(commands[False][0, :, :3], base + force, rtol=1e-14)
    pulled_back = np.zeros((5, 3), dtype=bool)
    pulled_back[:3] = signs < 0  # at or past tau_max, the negative residuals
    pulled_back[4] = signs > 0  # at tau_min, the positive one
    expected = np.where(pulled_back, base, base + force)
    np.testing.assert_allclose(commands[True][0, :, :3], expected, rtol=1e-14)
    np.testing.assert_array_equal(applied_residual[0], np.where(pulled_back, 0.0, force))
    assert np.array_equal(commands[True][0, 3], commands[False][0, 3])  # inside: unchanged
    assert np.array_equal(commands[True][..., 3:], commands[False][..., 3:])  # rate, messages
    loop.base_actions[0, :, :3] = base * 0.5  # nothing at a limit: the plain rule, bit for bit
    plain = ResidualController(
        scenario, make_policy("nn_dsc", scenario), 1, ResidualConfig(scale=0.5)
    )
    plain.observe(obs)
    plain.base_actions[0, :, :3] = base * 0.5
    assert np.array_equal(loop.compose(a), plain.compose(a))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"mode": "torque"}, "residual mode"),
        ({"yield_at_limit": 1}, "yield_at_limit must be true or false"),
        ({"yield_at_limit": True, "mode": "kinematic"}, "'kinematic' mode has none"),
        ({"scale": 0.0}, "residual scale"),
        ({"scale": float("nan")}, "residual scale"),
        ({"extras": ("v0_of_everyone",)}, "extras"),
        ({"extras": ("base_action",), "mode": "kinematic"}, "not available in 'kinematic'"),
        ({"kinematic_scale": (0.1, -0.1, 0.1)}, "kinematic_scale"),
        ({"messages": -1}, "messages must be an integer >= 0"),
        ({"messages": True}, "messages must be an integer >= 0"),
        ({"messages": 1.5}, "messages must be an integer >= 0"),
    ],
)
def test_bad_residual_configuration_says_what_to_fix(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ResidualConfig(**options)


@pytest.mark.filterwarnings("ignore:reset ignores options")  # api_test passes a dummy option
def test_wrapper_passes_the_pettingzoo_api_test() -> None:
    parallel_api_test(wrapped(40, extras=("base_action",)), num_cycles=50)


def test_wrapper_rejects_bad_corrections_before_any_state_changes() -> None:
    env = wrapped(50)
    env.reset(seed=0)
    before = env.unwrapped.sim.arrays.eta.copy()
    good = {agent: np.zeros(3, np.float32) for agent in env.agents}
    for bad, message in [
        ({**good, "vessel_2": np.zeros(4)}, "action of vessel_2"),
        ({**good, "vessel_1": np.array([np.nan, 0, 0])}, "not finite"),
        ({**good, "vessel_0": np.array([1j, 0, 0])}, "real numbers"),
        ({k: v for k, v in good.items() if k != "vessel_4"}, "one entry per live agent"),
    ]:
        with pytest.raises(ValueError, match=message):
            env.step(bad)
    assert np.array_equal(env.unwrapped.sim.arrays.eta, before)
    env.step(good)  # still usable


def test_wrapper_infos_carry_base_command_and_residual() -> None:
    env = wrapped(50, scale=0.1)
    env.reset(seed=0)
    actions = {agent: np.full(3, 0.5, np.float32) for agent in env.agents}
    *_, infos = env.step(actions)
    for agent in env.possible_agents:
        info = infos[agent]
        np.testing.assert_allclose(info["residual"], 0.05 * np.array([9.2, 4.5, 3.0]))
        np.testing.assert_allclose(
            info["tau_command"], info["base_command"][:3] + info["residual"], rtol=1e-6
        )


class _Recorder:
    """A base policy that records the observation it is shown and commands nothing."""

    def __init__(self, act_dim: int) -> None:
        self.act_dim = act_dim
        self.shown: list[np.ndarray] = []
        self.diagnostics: dict[str, np.ndarray] = {}

    def act_batch(self, obs: np.ndarray, fleets: object = None) -> np.ndarray:
        self.shown.append(np.array(obs, dtype=np.float64))
        return np.zeros((*np.shape(obs)[:2], self.act_dim))

    def reset(self, seed: int | None = None) -> None:
        del seed

    def reset_fleets(self, fleets: object) -> None:
        del fleets


def test_kinematic_residual_shows_the_base_a_target_moved_by_the_offset() -> None:
    """a = (1, -0.5, 0.25) with kinematic_scale (0.05, 0.04, 0.02) moves the tracked point by
    d = (0.05, -0.02, 0.005) m, m, rad in the body frame: the base sees z1 - d, nothing else."""
    scenario = scenarios.get("bench_lossy_links")
    sim = FleetSim(scenario, num_fleets=2)
    recorder = _Recorder(4 + scenario.message_size)
    config = ResidualConfig(mode="kinematic", kinematic_scale=(0.05, 0.04, 0.02))
    loop = ResidualController(scenario, recorder, 2, config)
    obs = sim.reset(seeds=[3, 4]).astype(np.float64)
    loop.observe(obs)
    assert recorder.shown == []  # in kinematic mode the base acts only once the offset is known
    action = np.zeros((2, 5, 3))
    action[..., 0], action[..., 1], action[..., 2] = 1.0, -0.5, 0.25
    action[1, 2] = (-1.0, 1.0, -1.0)  # one vessel with the opposite offset
    loop.compose(action)
    (shown,) = recorder.shown
    z1 = loop.layout.z1
    expected = obs.copy()
    expected[..., z1] = obs[..., z1] - np.array([0.05, -0.02, 0.005])
    expected[1, 2, z1] = obs[1, 2, z1] - np.array([-0.05, 0.04, -0.02])
    np.testing.assert_allclose(shown, expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(loop.residual[0, 0], [0.05, -0.02, 0.005], rtol=1e-15)


def test_kinematic_residual_commands_what_the_base_commands_for_the_moved_target() -> None:
    """nn_dsc through the kinematic residual equals a second nn_dsc fed z1 - d by hand."""
    scenario = scenarios.get("wang2014")
    sim = FleetSim(scenario)
    loop = ResidualController(
        scenario, make_policy("nn_dsc", scenario), 1, ResidualConfig(mode="kinematic")
    )
    reference = make_policy("nn_dsc", scenario)
    obs = sim.reset(seeds=[0])
    action = np.random.default_rng(1).uniform(-1.0, 1.0, size=(1, 5, 3))
    offset = 0.05 * action  # the default kinematic_scale, m, m, rad
    unmoved = make_policy("nn_dsc", scenario).act_batch(obs)
    for step in range(3):
        loop.observe(obs)
        command = loop.compose(action)
        moved = obs.astype(np.float64)
        moved[..., loop.layout.z1] -= offset
        np.testing.assert_array_equal(command, reference.act_batch(moved))
        if step == 0:  # the moved target changes the force: the offset is not dropped
            assert np.all(np.abs(command[..., :3] - unmoved[..., :3]) > 1e-6)
        obs = sim.step(command)


@pytest.mark.parametrize("mode", ["force", "force_and_rate", "kinematic"])
def test_learned_messages_are_broadcast_after_the_base_entries(mode: str) -> None:
    """The action's last L entries become the message's last L; the rest is the base's."""
    scenario = scenarios.make_scenario("bench_lossy_links", message_size=4)
    sim, plain_sim = FleetSim(scenario, num_fleets=2), FleetSim(scenario, num_fleets=2)
    config = ResidualConfig(mode=mode, messages=3)
    loop = ResidualController(scenario, make_policy("nn_dsc", scenario), 2, config)
    plain = ResidualController(
        scenario, make_policy("nn_dsc", scenario), 2, ResidualConfig(mode=mode)
    )
    assert loop.action_size == plain.action_size + 3
    rng = np.random.default_rng(0)
    loop.observe(sim.reset(seeds=[3, 4]))
    plain.observe(plain_sim.reset(seeds=[3, 4]))
    for _ in range(50):
        correction = rng.uniform(-1.0, 1.0, (2, scenario.n, plain.action_size))
        messages = rng.uniform(-1.0, 1.0, (2, scenario.n, 3))
        command = loop.compose(np.concatenate([correction, messages], axis=-1))
        expected = plain.compose(correction)
        assert np.array_equal(command[..., 5:], messages)  # entries 1-3 of m = 4
        assert np.array_equal(command[..., :5], expected[..., :5])  # forces, rate, speed
        loop.observe(sim.step(command))
        plain.observe(plain_sim.step(expected))
    assert np.array_equal(loop.residual, plain.residual)


def test_neighbours_read_learned_messages_as_the_links_deliver_them() -> None:
    """On ideal links vessel j's message reaches its neighbours' slots one step later."""
    scenario = scenarios.make_scenario("wang2014", message_size=3)
    sim = FleetSim(scenario, num_fleets=1)
    loop = ResidualController(
        scenario, make_policy("nn_dsc", scenario), 1, ResidualConfig(messages=2)
    )
    loop.observe(sim.reset(seeds=[0]))
    # in [-1, 1] and exact in float32
    sent = np.arange(scenario.n * 2, dtype=np.float64).reshape(1, scenario.n, 2) / 16.0
    obs = sim.step(loop.compose(np.concatenate([np.zeros((1, scenario.n, 3)), sent], -1)))
    layout, adjacency = loop.layout, scenario.topology.adjacency
    for i in range(scenario.n):
        heard = [obs[0, i, layout.slot(k)] for k in range(layout.n_slots)]
        linked = [slot[3 + 1 :] for slot in heard if slot[0] != 0.0]
        neighbours = np.flatnonzero(adjacency[i])
        assert len(linked) == len(neighbours) > 0
        assert sorted(map(tuple, linked)) == sorted(tuple(sent[0, j]) for j in neighbours)


def test_learned_messages_must_fit_after_the_base_entries() -> None:
    """The base's declared entries stay its own; an undeclared base keeps all m."""
    crossing = scenarios.get("hard_crossing")  # m = 6
    mpc = make_policy("mpc_tuned", crossing)
    assert mpc.message_entries == 1
    ResidualController(crossing, mpc, 1, ResidualConfig(messages=5))
    with pytest.raises(ValueError, match=r"ask for at most 5 learned messages.*>= 7"):
        ResidualController(crossing, mpc, 1, ResidualConfig(messages=6))
    safe = make_policy("mpc_tuned_safe", crossing)
    with pytest.raises(ValueError, match=r"'mpc_tuned_safe' writes 6 of .*at most 0"):
        ResidualController(crossing, safe, 1, ResidualConfig(messages=1))

    class Undeclared:
        act_dim, diagnostics = 10, {}

        def act_batch(self, obs: np.ndarray, fleets: object = None) -> np.ndarray:
            return np.zeros((*np.shape(obs)[:2], 10))

        def reset(self, seed: int | None = None) -> None:
            pass

    with pytest.raises(ValueError, match="writes 6 of"):
        ResidualController(crossing, Undeclared(), 1, ResidualConfig(messages=1))  # type: ignore[arg-type]
    ResidualController(crossing, None, 1, ResidualConfig(messages=6))  # no base: all six free


def test_input_statistics_pass_learned_messages_as_sent() -> None:
    """The base alone never sends them: their columns get mean 0 and variance 1."""
    from cpf_env.envs.input_statistics import estimate_input_statistics

    scenario = scenarios.make_scenario("bench_lossy_links", message_size=3)
    config = ResidualConfig(messages=2)
    stats = estimate_input_statistics(scenario, make_policy("nn_dsc", scenario), config, steps=5)
    plain = estimate_input_statistics(
        scenario, make_policy("nn_dsc", scenario), ResidualConfig(), steps=5
    )
    columns = config.message_inputs(FleetSim(scenario).layout)
    layout = FleetSim(scenario).layout
    assert len(columns) == 2 * layout.n_slots
    assert all((c - layout.slot(0).start) % layout.slot_size in (4, 5) for c in columns)
    assert np.all(stats.mean[columns] == 0.0) and np.all(stats.var[columns] == 1.0)
    assert np.all(plain.var[columns] == 0.0)  # measured: constant zeros
    others = np.setdiff1d(np.arange(stats.size), columns)
    assert np.array_equal(stats.mean[others], plain.mean[others])
