"""The separation's safety filter (``baselines.safety``) and its barrier (``baselines.barrier``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import baselines
from baselines.barrier import BARRIER_GAINS, barrier_filter
from baselines.mpc import OraclePolicy, thruster_gain
from cpf_env import scenarios
from cpf_env.model.vessel import CYBERSHIP2, coriolis_matrix, damping_matrix
from cpf_env.scenarios.crossing import crossing_fleet
from cpf_env.sim.fleet import FleetSim

CROSSING = scenarios.get("hard_crossing")
LIMITS = (np.array([-9.2, -4.5, -3.0]), np.array([9.2, 4.5, 3.0]))


def _condition(tau, x, y, psi, nu, other, distance):
    """h'' + (k1 + k2) h' + k1 k2 h of the barrier under force ``tau`` (nominal model)."""
    params = CYBERSHIP2.to_params()
    mass = CYBERSHIP2.mass_matrix()
    hydro = (coriolis_matrix(params, nu) + damping_matrix(params, nu)) @ nu
    nu_dot = np.linalg.solve(mass, tau - hydro)
    c, s = math.cos(psi), math.sin(psi)
    rot = np.array([[c, -s], [s, c]])
    velocity = rot @ nu[:2]
    acc = rot @ nu_dot[:2] + nu[2] * rot @ np.array([-nu[1], nu[0]])
    p, v = np.array([x, y]) - other[:2], velocity - other[2:]
    k1, k2 = BARRIER_GAINS
    h = p @ p - distance**2
    return 2 * v @ v + 2 * p @ acc + (k1 + k2) * 2 * p @ v + k1 * k2 * h


def test_the_barrier_brakes_a_vessel_heading_at_another_just_enough() -> None:
    """Surging at 0.3 m/s towards a hull 1 m ahead: the filtered force meets the condition."""
    nu = np.array([0.3, 0.0, 0.0])
    other = np.array([[1.0, 0.0, 0.0, 0.0]])
    tau = np.array([5.0, 0.0, 0.0])
    assert _condition(tau, 0.0, 0.0, 0.0, nu, other[0], 0.7) < 0.0
    filtered = tau.copy()
    barrier_filter(filtered, 0.0, 0.0, 0.0, nu, CYBERSHIP2.to_params(), other, 1, 0.7,
                   *BARRIER_GAINS, *LIMITS)  # fmt: skip
    assert filtered[0] < tau[0]  # it brakes
    assert _condition(filtered, 0.0, 0.0, 0.0, nu, other[0], 0.7) == pytest.approx(0.0, abs=1e-9)


def test_the_barrier_leaves_a_safe_command_and_an_absent_actuator_alone() -> None:
    nu = np.array([0.3, 0.0, 0.0])
    far = np.array([[20.0, 0.0, 0.0, 0.0]])
    tau = np.array([5.0, 1.0, 0.5])
    kept = tau.copy()
    barrier_filter(kept, 0.0, 0.0, 0.0, nu, CYBERSHIP2.to_params(), far, 1, 0.7,
                   *BARRIER_GAINS, *LIMITS)  # fmt: skip
    assert np.array_equal(kept, tau)
    no_sway = (np.array([-9.2, 0.0, -3.0]), np.array([9.2, 0.0, 3.0]))
    near = np.array([[0.0, 0.9, 0.0, -0.3]])  # a hull beside, closing sideways
    side = np.array([2.0, 0.0, 0.0])
    barrier_filter(side, 0.0, 0.0, 0.0, nu, CYBERSHIP2.to_params(), near, 1, 0.7,
                   *BARRIER_GAINS, *no_sway)  # fmt: skip
    assert side[1] == 0.0


def test_the_filter_needs_room_in_the_messages_and_a_barrier_outside_the_collision() -> None:
    with pytest.raises(ValueError, match=r"message_size = 1; use a scenario with message_size"):
        baselines.make_policy("nn_dsc_safe", scenarios.get("bench_mild"))
    with pytest.raises(ValueError, match=r"^the safety filter broadcasts"):  # names no policy
        baselines.make_policy("mpc_tuned_ekf_safe", scenarios.get("bench_mild"))
    with pytest.raises(ValueError, match=r"must exceed the separation's hard_distance of 0\.5"):
        baselines.make_policy("nn_dsc_safe", CROSSING, barrier_distance=0.5)


def test_each_vessel_broadcasts_its_flag_position_and_velocity() -> None:
    sim = FleetSim(CROSSING, num_fleets=2)
    obs = sim.reset(seeds=[3, 4])
    policy = baselines.make_policy("nn_dsc_safe", CROSSING)
    for _ in range(5):
        actions = policy.act_batch(obs)
        sim.step(actions)
        obs = sim.arrays.obs
    actions = policy.act_batch(obs)
    a = sim.arrays
    np.testing.assert_allclose(actions[..., 6:8], a.eta[..., :2], atol=1e-9)
    c, s = np.cos(a.eta[..., 2]), np.sin(a.eta[..., 2])
    vx = c * a.nu[..., 0] - s * a.nu[..., 1]
    vy = s * a.nu[..., 0] + c * a.nu[..., 1]
    np.testing.assert_allclose(actions[..., 8], vx, atol=1e-9)
    np.testing.assert_allclose(actions[..., 9], vy, atol=1e-9)
    assert np.all(actions[..., 5] == 1.0)


#: ``hard_crossing`` with pairs whose formation passes 0.21 m apart: a collision unless one
#: of them gives way.
_paths, _initial, _ = crossing_fleet(2, offset=0.3)
TIGHT = CROSSING.replace(
    paths=_paths, initial=dataclasses.replace(CROSSING.initial, eta=_initial.eta)
)


def _closest(name: str, steps: int = 2000) -> tuple[float, bool]:
    """Closest approach (m) and whether the fleet collided, one episode of ``TIGHT``."""
    sim = FleetSim(TIGHT, num_fleets=1)
    obs = sim.reset(seeds=[10_000])
    policy = baselines.make_policy(name, TIGHT)
    closest = math.inf
    for _ in range(steps):
        sim.step(policy.act_batch(obs))
        obs = sim.arrays.obs
        p = sim.arrays.eta[0, :, :2]
        gap = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p)) * 1e9
        closest = min(closest, float(gap.min()))
        if sim.arrays.terminated[0]:
            return closest, True
    return closest, False


def test_the_filter_keeps_apart_the_hulls_the_bare_design_runs_into_each_other() -> None:
    """One whole episode (2,000 steps) of pairs that meet unless they give way, a test seed."""
    bare, collided = _closest("nn_dsc")
    safe, safe_collided = _closest("nn_dsc_safe")
    assert collided and bare < CROSSING.separation.hard_distance
    assert not safe_collided and safe > CROSSING.separation.hard_distance + 0.1


def test_the_planners_cap_their_velocity_gain_at_the_thrusters_bandwidth() -> None:
    assert thruster_gain(6.0, 0.0) == 6.0 and thruster_gain(6.0, 0.5) == 1.0
    assert thruster_gain(0.5, 0.5) == 0.5
    lagged = OraclePolicy(scenarios.get("hard_underactuated"))._gain_vector
    instant = OraclePolicy(scenarios.get("bench_saturation"))._gain_vector
    assert np.array_equal(lagged[3:6], [1.0, 1.0, 1.0])
    assert np.array_equal(instant[3:6], [6.0, 6.0, 6.0])
    # through a first-order lag T the velocity loop T e'' + e' + K2 e = 0 has damping
    # 1 / (2 sqrt(K2 T)): 1 / sqrt(2) at the cap
    assert 1.0 / (2.0 * math.sqrt(thruster_gain(6.0, 0.5) * 0.5)) == pytest.approx(2**-0.5)
