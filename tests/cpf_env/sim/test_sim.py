"""FleetSim: integration accuracy, saturation, determinism, locality, links."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import (
    NO_DISTURBANCES,
    TAU_MAX,
    TAU_MIN,
    assert_unchanged,
    fast_member,
    fast_switching,
    free_scenario,
    random_actions,
    reference_matrices,
    rotation_matrix,
    snapshot,
)

from cpf_env import scenarios
from cpf_env.model.disturbances import Disturbances, OceanCurrent
from cpf_env.model.links import LinkImpairments
from cpf_env.model.vessel import CYBERSHIP2
from cpf_env.scenarios import Scenario, SpeedSchedule
from cpf_env.sim.fleet import PARALLEL_MIN_FLEETS, FleetSim
from cpf_env.sim.observation import ObsLayout

LAYOUT_FIELDS = ("nu", "z1", "t1", "t2", "theta", "tau", "leader", "v0")


def run(sim: FleetSim, actions: np.ndarray, steps: int) -> None:
    for _ in range(steps):
        sim.step(actions)


def union_slots(scenario: Scenario) -> list[list[int]]:
    """Neighbours of each vessel in the union of the topology's graphs, ascending."""
    graphs = scenario.switching.graphs
    union = np.max([g.adjacency for g in graphs], axis=0)
    return [list(np.flatnonzero(row)) for row in union]


def has_randomness(scenario: Scenario) -> bool:
    d, init = scenario.disturbances, scenario.initial
    return bool(
        scenario.model_spread > 0
        or init.position_std > 0
        or init.heading_std > 0
        or init.theta_std > 0
        or scenario.links.loss_probability > 0
        or d.current.std > 0
        or any(d.waves.std)
        or any(d.wind.std)
    )


# --- integration ------------------------------------------------------------------------

CURRENT = (0.1, -0.05)
COMMANDS = np.array([[6.0, -3.0, 1.5], [-5.0, 2.0, -1.0], [8.0, 2.0, -2.0]])


def final_state(substeps: int, current: bool, steps: int = 20) -> np.ndarray:
    """eta and nu of three vessels after `steps` control periods of 0.2 s, constant commands."""
    psi0 = 0.3
    velocity = np.array([*CURRENT, 0.0]) if current else np.zeros(3)
    disturbances = Disturbances(current=OceanCurrent(velocity=CURRENT if current else (0, 0)))
    nu0 = rotation_matrix(psi0).T @ velocity  # at rest relative to the water
    scenario = free_scenario(
        [nu0] * 3, disturbances=disturbances, psi0=psi0, dt=0.2, substeps=substeps
    )
    sim = FleetSim(scenario)
    sim.reset(seeds=[0])
    actions = np.zeros((1, 3, sim.act_dim))
    actions[0, :, :3] = COMMANDS
    actions[0, :, 3] = 0.1
    states = []
    for _ in range(steps):
        sim.step(actions)
        states.append(np.concatenate([sim.arrays.eta[0], sim.arrays.nu[0]], axis=1))
    return np.array(states)


@pytest.mark.parametrize("current", [False, True], ids=["still_water", "current"])
def test_rk4_error_shrinks_16x_per_halving(current: bool) -> None:
    """Fourth order: halving the sub-step divides the error after 4 s by about 2^4.

    Nonlinear plant (quadratic damping, paper's unmodeled terms with sin t) under
    commands that keep every relative velocity away from zero: abs() in D(nu) makes
    the right-hand side non-smooth at zero crossings, which would cost an order.
    """
    reference = final_state(256, current)
    # nu_r of the current run is nu of the still-water run (next test): check its signs.
    nu_r_sign = np.sign(final_state(256, False)[:, :, 3:])
    assert np.all(nu_r_sign == nu_r_sign[0])  # no zero crossing along the run
    errors = [np.abs(final_state(s, current)[-1] - reference[-1]).max() for s in (1, 2, 4, 8)]
    assert errors[-1] > 1e-10  # far above round-off
    ratios = [errors[k] / errors[k + 1] for k in range(3)]
    assert all(12.0 < ratio < 20.0 for ratio in ratios), ratios


def rotation_matrix_batch(psi: np.ndarray) -> np.ndarray:
    return np.array([[rotation_matrix(p) for p in row] for row in psi])


def test_constant_current_only_shifts_the_motion() -> None:
    """Galilean invariance: in a uniform current, nu_r and psi evolve as in still water
    and the position drifts by V_c t (Fossen 2011, section 10.3). Up to the RK4 error,
    which differs between the two state trajectories: 2e-8 m with 5 sub-steps of 0.04 s,
    under 1e-10 m with 20."""
    still, moving = final_state(20, False, steps=100), final_state(20, True, steps=100)
    time = 0.2 * np.arange(1, 101)[:, None]
    drift = np.stack([CURRENT[0] * time, CURRENT[1] * time], axis=-1)
    np.testing.assert_allclose(moving[:, :, :2], still[:, :, :2] + drift, atol=1e-10)
    np.testing.assert_allclose(moving[:, :, 2], still[:, :, 2], atol=1e-12)
    nu_c = np.einsum(
        "tnji,j->tni", rotation_matrix_batch(moving[:, :, 2]), np.array([*CURRENT, 0.0])
    )
    np.testing.assert_allclose(moving[:, :, 3:] - nu_c, still[:, :, 3:], atol=1e-12)


@pytest.mark.parametrize(
    ("nu", "psi0"),
    [((0.3, 0.05, 0.1), 0.4), ((0.4, -0.05, -0.1), -2.0), ((-0.2, 0.08, 0.15), 3.0)],
)
def test_trimmed_vessel_moves_on_the_kinematic_circle(
    nu: tuple[float, float, float], psi0: float
) -> None:
    """With tau = C(nu) nu + D(nu) nu, nu is an equilibrium and eta' = J(psi) nu integrates
    to a circular arc: psi = psi0 + r t, position in closed form."""
    _, coriolis, damping = reference_matrices(CYBERSHIP2, nu)
    tau = (coriolis + damping) @ np.array(nu)
    assert np.all(np.abs(tau) < [9.2, 4.5, 3.0])  # no saturation
    scenario = free_scenario([nu], psi0=psi0, dt=0.05, substeps=5)
    sim = FleetSim(scenario)
    sim.reset(seeds=[0])
    actions = np.zeros((1, 1, sim.act_dim))
    actions[0, 0, :3] = tau
    steps = 200
    run(sim, actions, steps)
    u, v, r = nu
    t = steps * 0.05
    psi = psi0 + r * t
    x = (u * (np.sin(psi) - np.sin(psi0)) + v * (np.cos(psi) - np.cos(psi0))) / r
    y = (u * (np.cos(psi0) - np.cos(psi)) + v * (np.sin(psi) - np.sin(psi0))) / r
    np.testing.assert_allclose(sim.arrays.nu[0, 0], nu, atol=1e-12)
    np.testing.assert_allclose(sim.arrays.eta[0, 0], [x, y, psi], atol=1e-9)
    np.testing.assert_array_equal(sim.arrays.tau_applied[0, 0], tau)


def test_nonfinite_state_raises() -> None:
    sim = FleetSim(free_scenario([[1e160, 0.0, 0.0]]))
    sim.reset(seeds=[0])
    with pytest.raises(RuntimeError, match="non-finite"):
        sim.step(np.zeros((1, 1, sim.act_dim)))


# --- saturation and clipping ------------------------------------------------------------


def saturation_scenario() -> Scenario:
    return scenarios.get("wang2014").replace(
        tau_max=TAU_MAX, tau_min=TAU_MIN, theta_dot_max=0.3, message_size=2, message_max=1.5
    )


def test_saturation_per_axis_and_per_vessel() -> None:
    scenario = saturation_scenario()
    sim = FleetSim(scenario, num_fleets=3)
    sim.reset(seeds=[0, 1, 2])
    rng = np.random.default_rng(0)
    low, high = np.array(TAU_MIN), np.array(TAU_MAX)
    saturated = np.zeros(3, dtype=int)
    for _ in range(50):
        actions = np.empty((3, 5, sim.act_dim))
        actions[..., :3] = rng.uniform(-15.0, 15.0, size=(3, 5, 3))
        actions[..., 3] = rng.uniform(-1.0, 1.0, size=(3, 5))
        actions[..., 4:] = rng.uniform(-4.0, 4.0, size=(3, 5, 2))
        theta = sim.arrays.theta.copy()
        sim.step(actions)
        a = sim.arrays
        expected = np.minimum(np.maximum(actions[..., :3], low), high)
        np.testing.assert_array_equal(a.tau_command, actions[..., :3])
        np.testing.assert_array_equal(a.tau_applied, expected)
        np.testing.assert_array_equal(a.obs[..., sim.layout.tau], expected.astype(np.float32))
        rate = np.clip(actions[..., 3], -0.3, 0.3)
        np.testing.assert_array_equal(a.theta_dot, rate)
        np.testing.assert_array_equal(a.theta, theta + 0.05 * rate)
        np.testing.assert_array_equal(a.message, np.clip(actions[..., 4:], -1.5, 1.5))
        saturated += ((actions[..., :3] > high) | (actions[..., :3] < low)).sum(axis=(0, 1))
    assert np.all(saturated > 100)  # both sides were exercised on every axis


def test_plant_sees_only_the_saturated_force() -> None:
    """Overdriven commands and their clipped values give bit-identical motion."""
    scenario = saturation_scenario()
    sims = [FleetSim(scenario, num_fleets=2) for _ in range(2)]
    for sim in sims:
        sim.reset(seeds=[5, 6])
    rng = np.random.default_rng(1)
    for _ in range(40):
        actions = random_actions(rng, sims[0], overdrive=3.0)
        clipped = actions.copy()
        clipped[..., :3] = np.clip(actions[..., :3], np.array(TAU_MIN), np.array(TAU_MAX))
        sims[0].step(actions)
        sims[1].step(clipped)
        for name in ("eta", "nu", "theta", "tau_applied", "obs", "reward"):
            assert np.array_equal(getattr(sims[0].arrays, name), getattr(sims[1].arrays, name))
    assert not np.array_equal(sims[0].arrays.tau_command, sims[1].arrays.tau_command)


# --- observations -----------------------------------------------------------------------


def test_layout_named_slices_cover_the_observation() -> None:
    layout = FleetSim(scenarios.get("wang2014")).layout
    assert layout == ObsLayout(n_slots=2, msg_size=1)
    covered = np.concatenate(
        [np.arange(layout.size)[getattr(layout, name)] for name in LAYOUT_FIELDS]
        + [np.arange(layout.size)[layout.slot(k)] for k in range(layout.n_slots)]
    )
    np.testing.assert_array_equal(np.sort(covered), np.arange(layout.size))
    assert layout.size == 18 + 2 * 4 == len(layout.names())


@pytest.mark.parametrize("name", ["wang2014", "heterogeneous", "current_and_waves"])
def test_own_state_block_matches_definitions(name: str) -> None:
    """nu, z1 = J^T (eta - eta_d) (heading wrapped), t1 = J^T eta_d', t2 = J^T eta_d'', theta."""
    scenario = scenarios.get(name)
    sim = FleetSim(scenario, num_fleets=2)
    sim.reset(seeds=[0, 1])
    rng = np.random.default_rng(2)
    layout = sim.layout
    for step in range(60):
        obs = sim.step(random_actions(rng, sim, rate=0.3)) if step else sim.arrays.obs
        a = sim.arrays
        for b in range(2):
            for i, path in enumerate(scenario.paths):
                point = path.evaluate(a.theta[b, i])
                J = rotation_matrix(a.eta[b, i, 2])
                z1 = J.T @ (a.eta[b, i] - point[0])
                z1[2] = (a.eta[b, i, 2] - point[0, 2] + np.pi) % (2 * np.pi) - np.pi
                o = obs[b, i].astype(np.float64)
                np.testing.assert_allclose(o[layout.nu], a.nu[b, i], rtol=1e-6, atol=1e-7)
                np.testing.assert_allclose(o[layout.z1], z1, rtol=1e-6, atol=1e-6)
                np.testing.assert_allclose(o[layout.t1], J.T @ point[1], rtol=1e-6, atol=1e-7)
                np.testing.assert_allclose(o[layout.t2], J.T @ point[2], rtol=1e-6, atol=1e-7)
                assert o[layout.theta][0] == np.float32(a.theta[b, i])


# --- determinism and batching -----------------------------------------------------------

SCENARIO_NAMES = scenarios.list_scenarios()
COMPARED = ("eta", "nu", "theta", "obs", "reward", "recv_theta", "recv_step")


def trajectory(scenario: Scenario, seeds: list[int], steps: int) -> list[dict[str, np.ndarray]]:
    sim = FleetSim(scenario, num_fleets=len(seeds))
    sim.reset(seeds=seeds)
    rng = np.random.default_rng(123)
    records = [{name: getattr(sim.arrays, name).copy() for name in COMPARED}]
    for _ in range(steps):
        sim.step(random_actions(rng, sim, overdrive=1.0))
        records.append({name: getattr(sim.arrays, name).copy() for name in COMPARED})
    return records


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_same_seed_same_bits_different_seed_differs(name: str) -> None:
    scenario = scenarios.get(name).replace(max_path_error=1e6)
    first = trajectory(scenario, [3, 4], 300)
    second = trajectory(scenario, [3, 4], 300)
    for step, (x, y) in enumerate(zip(first, second, strict=True)):
        for field in COMPARED:
            assert np.array_equal(x[field], y[field]), f"{field} differs at step {step}"
    other = trajectory(scenario, [5, 4], 300)
    differs = any(not np.array_equal(x["obs"], y["obs"]) for x, y in zip(first, other, strict=True))
    assert differs == has_randomness(scenario)
    # Fleet 1 kept its seed: the other fleet's seed does not leak into it.
    for x, y in zip(first, other, strict=True):
        assert np.array_equal(x["obs"][1], y["obs"][1])


@pytest.mark.parametrize("num_fleets", [4, PARALLEL_MIN_FLEETS + 4], ids=["serial", "parallel"])
@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_fleet_k_of_a_batch_equals_a_single_sim(name: str, num_fleets: int) -> None:
    """Every array of fleet 2 of a batch equals a single simulator's, bit for bit.

    The single simulator runs the serial kernel; the larger batch the parallel one.
    """
    scenario = scenarios.get(name).replace(max_path_error=1e6)
    batch, single = FleetSim(scenario, num_fleets=num_fleets), FleetSim(scenario)
    batch.reset(seeds=list(range(10, 10 + num_fleets)))
    single.reset(seeds=[12])
    rng = np.random.default_rng(123)
    for step in range(150):
        actions = random_actions(rng, batch, overdrive=1.0)
        batch.step(actions)
        single.step(actions[2:3])
        for field, value in batch.arrays._asdict().items():
            assert np.array_equal(value[2], getattr(single.arrays, field)[0]), (
                f"{field} differs at step {step}"
            )


def test_resetting_one_fleet_leaves_the_others_alone() -> None:
    scenario = scenarios.get("current_and_waves")
    sim = FleetSim(scenario, num_fleets=3)
    sim.reset(seeds=[0, 1, 2])
    rng = np.random.default_rng(0)
    run_actions = [random_actions(rng, sim) for _ in range(60)]
    for actions in run_actions[:30]:
        sim.step(actions)
    before = snapshot(sim)
    sim.reset(seeds=[7], fleets=[1])
    for name, value in sim.arrays._asdict().items():
        assert np.array_equal(before[name][[0, 2]], value[[0, 2]]), name
    assert sim.arrays.step.tolist() == [30, 0, 30]
    for actions in run_actions[30:]:
        sim.step(actions)
    reference = FleetSim(scenario, num_fleets=3)
    reference.reset(seeds=[0, 1, 2])
    for actions in run_actions:
        reference.step(actions)
    for name in COMPARED:
        assert np.array_equal(
            getattr(sim.arrays, name)[[0, 2]], getattr(reference.arrays, name)[[0, 2]]
        )


def test_truncation_flag_and_time() -> None:
    sim = FleetSim(scenarios.get("wang2014").replace(max_steps=4), num_fleets=2)
    sim.reset(seeds=[0, 1])
    for k in range(1, 5):
        sim.step(np.zeros((2, 5, sim.act_dim)))
        assert sim.truncated.tolist() == [k >= 4] * 2
        np.testing.assert_allclose(sim.time, 0.05 * k)


def test_termination_on_the_last_step_is_not_truncation() -> None:
    # wang2014 starts up to 1.41 m off its paths: with a 1 m bound it terminates at once.
    sim = FleetSim(scenarios.get("wang2014").replace(max_steps=1, max_path_error=1.0))
    sim.reset(seeds=[0])
    sim.step(np.zeros((1, 5, sim.act_dim)))
    assert sim.arrays.terminated.tolist() == [True]
    assert sim.truncated.tolist() == [False]


# --- bad input --------------------------------------------------------------------------


def bad_batch(kind: str, sim: FleetSim) -> np.ndarray:
    actions = np.zeros((sim.num_fleets, sim.n, sim.act_dim))
    if kind == "nan":
        actions[1, 2, 3] = np.nan
    elif kind == "inf":
        actions[1, 2, 3] = -np.inf
    elif kind == "wide":
        actions = np.zeros((sim.num_fleets, sim.n, sim.act_dim + 1))
    elif kind == "no_batch_axis":
        actions = np.zeros((sim.n, sim.act_dim))
    elif kind == "few_vessels":
        actions = np.zeros((sim.num_fleets, sim.n - 1, sim.act_dim))
    return actions


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("nan", r"fleet 1, vessel_2, component 3 is nan.*finite"),
        ("inf", r"fleet 1, vessel_2, component 3 is -inf.*finite"),
        ("wide", r"shape .*\(2, 5, 5\), got \(2, 5, 6\)"),
        ("no_batch_axis", r"shape .*\(2, 5, 5\), got \(5, 5\)"),
        ("few_vessels", r"shape .*\(2, 5, 5\), got \(2, 4, 5\)"),
    ],
)
def test_bad_action_batch_raises_and_leaves_state(kind: str, match: str) -> None:
    sim = FleetSim(scenarios.get("lossy_links"), num_fleets=2)
    sim.reset(seeds=[0, 1])
    rng = np.random.default_rng(0)
    run(sim, random_actions(rng, sim), 10)
    before = snapshot(sim)
    with pytest.raises(ValueError, match=match):
        sim.step(bad_batch(kind, sim))
    assert_unchanged(before, sim)


def test_reset_arguments_are_checked() -> None:
    sim = FleetSim(scenarios.get("wang2014"), num_fleets=2)
    with pytest.raises(RuntimeError, match="reset"):
        sim.step(np.zeros((2, 5, 5)))
    with pytest.raises(ValueError, match="fleets must be indices"):
        sim.reset(fleets=[2])
    with pytest.raises(ValueError, match="one per fleet"):
        sim.reset(seeds=[1, 2, 3])
    with pytest.raises(ValueError, match="num_fleets"):
        FleetSim(scenarios.get("wang2014"), num_fleets=0)
    with pytest.raises(TypeError, match="Scenario"):
        FleetSim("wang2014")  # type: ignore[arg-type]


# --- locality ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "moved"), [("wang2014", 4), ("large_fleet", 5), ("switching_topology", 3)]
)
def test_observation_ignores_non_neighbours(name: str, moved: int) -> None:
    """Move one vessel (pose and path variable): only it and its neighbours see a change."""
    scenario = scenarios.get(name).replace(max_path_error=1e6)
    eta = np.array(scenario.initial.eta)
    eta[moved] += [0.7, -0.4, 0.5]
    theta = np.array(scenario.initial.theta)
    theta[moved] += 0.3
    initial = dataclasses.replace(scenario.initial, eta=tuple(map(tuple, eta)), theta=tuple(theta))
    sims = [FleetSim(s) for s in (scenario, scenario.replace(initial=initial))]
    for sim in sims:
        sim.reset(seeds=[9])
    neighbours = set(union_slots(scenario)[moved])
    strangers = [i for i in range(scenario.n) if i != moved and i not in neighbours]
    assert strangers
    rng = np.random.default_rng(0)
    seen = np.zeros(scenario.n, dtype=bool)
    for _ in range(200):
        actions = random_actions(rng, sims[0])
        obs = [sim.step(actions).copy() for sim in sims]
        assert np.array_equal(obs[0][0, strangers], obs[1][0, strangers])
        seen |= np.any(obs[0][0] != obs[1][0], axis=-1)
    assert seen[moved] and all(seen[j] for j in neighbours)  # the change is visible nearby


def test_leader_speed_only_where_heard_and_as_scheduled() -> None:
    times, values = (0.0, 2.02, 4.51), (0.1, 0.3, -0.05)
    scenario = fast_switching(v0=SpeedSchedule(times, values))
    graphs = scenario.switching.graphs
    sim = FleetSim(scenario)
    obs = sim.reset(seeds=[0])
    layout = sim.layout
    heard_steps = np.zeros(5, dtype=int)
    for step in range(131):
        if step:
            obs = sim.step(np.zeros((1, 5, sim.act_dim)))
        b = graphs[fast_member(step)].leader_links
        v0 = values[np.searchsorted(times, step * 0.05, side="right") - 1]
        np.testing.assert_array_equal(obs[0, :, layout.leader][:, 0], b)
        np.testing.assert_array_equal(obs[0, :, layout.v0][:, 0], np.float32(v0) * b)
        heard_steps += b.astype(int)
    assert heard_steps.tolist() == [51, 0, 40, 51, 40]  # the leader links do switch


@pytest.mark.parametrize("name", ["wang2014", "fast_switching", "large_fleet"])
def test_neighbour_slots_with_perfect_links(name: str) -> None:
    """Slot k of vessel i: [a_ij, theta_j - theta_i, age 0, msg_j] for the k-th union
    neighbour j while the active graph links them; an all-zero slot otherwise."""
    scenario = fast_switching() if name == "fast_switching" else scenarios.get(name)
    graphs = scenario.switching.graphs
    slots = union_slots(scenario)
    sim = FleetSim(scenario)
    obs = sim.reset(seeds=[0])
    layout = sim.layout
    assert layout.n_slots == max(len(s) for s in slots)
    rng = np.random.default_rng(1)
    empty = filled = 0
    for step in range(131 if len(graphs) > 1 else 60):
        if step:
            obs = sim.step(random_actions(rng, sim))
        adjacency = graphs[fast_member(step) if len(graphs) > 1 else 0].adjacency
        view = layout.slots(obs[0])
        a = sim.arrays
        for i in range(scenario.n):
            for k in range(layout.n_slots):
                j = slots[i][k] if k < len(slots[i]) else -1
                weight = adjacency[i, j] if j >= 0 else 0.0
                if weight == 0.0:
                    assert np.all(view[i, k] == 0.0)
                    empty += 1
                    continue
                filled += 1
                assert view[i, k, 0] == np.float32(weight)
                assert view[i, k, 1] == np.float32(a.theta[0, j] - a.theta[0, i])
                assert view[i, k, 2] == 0.0
                assert view[i, k, 3] == np.float32(a.message[0, j, 0])
    assert filled > 0 and (empty > 0) == (name != "large_fleet")


def link_run(
    links: LinkImpairments, fleets: int, steps: int
) -> tuple[FleetSim, np.ndarray, np.ndarray, np.ndarray]:
    """wang2014 over impaired links: observations, thetas and messages after every step."""
    scenario = scenarios.get("wang2014").replace(links=links)
    sim = FleetSim(scenario, num_fleets=fleets)
    obs = [sim.reset(seeds=list(range(fleets))).copy()]
    thetas = [sim.arrays.theta.copy()]
    messages = []
    rng = np.random.default_rng(2)
    for _ in range(steps):
        actions = random_actions(rng, sim, rate=0.5)
        obs.append(sim.step(actions).copy())
        thetas.append(sim.arrays.theta.copy())
        messages.append(sim.arrays.message.copy())
    return sim, np.array(obs), np.array(thetas), np.array(messages)


@pytest.mark.parametrize("delay", [1, 5])
def test_delayed_links_deliver_the_value_sent_delay_steps_before(delay: int) -> None:
    sim, obs, thetas, messages = link_run(LinkImpairments(delay_steps=delay), 2, 60)
    view = sim.layout.slots(obs)  # (T, B, n, K, 4)
    slots = union_slots(sim.scenario)
    for k in range(obs.shape[0]):
        sent = max(k - delay, 0)  # observation time of the packet's theta
        for i in range(5):
            for s, j in enumerate(slots[i]):
                np.testing.assert_array_equal(view[k, :, i, s, 2], k - sent)
                np.testing.assert_array_equal(
                    view[k, :, i, s, 1], (thetas[sent, :, j] - thetas[k, :, i]).astype(np.float32)
                )
                message = messages[sent - 1, :, j, 0] if sent >= 1 else 0.0
                np.testing.assert_array_equal(view[k, :, i, s, 3], np.float32(message))


@pytest.mark.parametrize(("loss", "delay"), [(0.3, 0), (0.7, 2)])
def test_lossy_links_deliver_one_minus_p_and_hold_the_rest(loss: float, delay: int) -> None:
    fleets, steps = 64, 150
    sim, obs, thetas, _ = link_run(LinkImpairments(loss, delay), fleets, steps)
    view = sim.layout.slots(obs)
    slots = union_slots(sim.scenario)
    delivered = {}
    for i in range(5):
        for s, j in enumerate(slots[i]):
            age = view[delay + 1 :, :, i, s, 2].astype(np.int64)  # (T', B)
            delivered[(i, j)] = age == delay
            assert np.all(age >= delay)
            # Whatever the slot holds is the packet sent `age` steps ago, unchanged.
            k = np.arange(delay + 1, steps + 1)[:, None]
            held = np.take_along_axis(thetas[:, :, j], k - age, axis=0)
            np.testing.assert_array_equal(
                view[delay + 1 :, :, i, s, 1], (held - thetas[delay + 1 :, :, i]).astype(np.float32)
            )
    everything = np.concatenate([d.ravel() for d in delivered.values()])
    fraction = everything.mean()
    assert abs(fraction - (1.0 - loss)) < 5.0 * np.sqrt(loss * (1.0 - loss) / everything.size)
    # Losses are independent per directed link.
    correlation = np.corrcoef(delivered[(0, 1)].ravel(), delivered[(1, 0)].ravel())[0, 1]
    assert abs(correlation) < 5.0 / np.sqrt(delivered[(0, 1)].size)


def test_messages_clip_and_reach_every_union_neighbour() -> None:
    scenario = scenarios.get("wang2014").replace(message_size=3, message_max=2.0)
    sim = FleetSim(scenario)
    sim.reset(seeds=[0])
    actions = np.zeros((1, 5, sim.act_dim))
    actions[0, :, 4:] = np.arange(15.0).reshape(5, 3) - 7.0
    obs = sim.step(actions)
    sent = np.clip(actions[0, :, 4:], -2.0, 2.0)
    view = sim.layout.slots(obs[0])
    for i, nbrs in enumerate(union_slots(scenario)):
        for s, j in enumerate(nbrs):
            np.testing.assert_array_equal(view[i, s, 3:], sent[j].astype(np.float32))


def test_unused_scenario_noise_is_not_drawn() -> None:
    """With every random part off, the fleet is deterministic whatever the seed."""
    scenario = free_scenario([[0.1, 0.0, 0.0]] * 3, disturbances=NO_DISTURBANCES)
    finals = []
    for seed in (0, 1):
        sim = FleetSim(scenario)
        sim.reset(seeds=[seed])
        run(sim, np.full((1, 3, sim.act_dim), 0.5), 20)
        finals.append(sim.arrays.eta.copy())
    assert np.array_equal(finals[0], finals[1])
