"""Privileged references: moot information changes nothing, real information helps."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import baselines
from cpf_bench.rollout import rollout, rollout_group
from cpf_env import FleetSim, scenarios
from cpf_env.evaluation.privileged import ideal_link_observations, lumped_uncertainty, true_dynamics
from cpf_env.model.vessel import coriolis_matrix, damping_matrix
from cpf_env.scenarios import make_scenario
from cpf_env.sim.observation import SLOT_AGE, SLOT_MSG, SLOTS


def _no_uncertainty(name: str = "wang2014"):
    """The scenario without the paper's unmodeled dynamics: nominal model = true model."""
    scenario = scenarios.get(name)
    calm = dataclasses.replace(scenario.disturbances, unmodeled_scale=0.0)
    return dataclasses.replace(scenario, disturbances=calm)


def test_privileged_references_are_listed_apart_and_refuse_to_act_unbound():
    assert {"nn_dsc_privileged", "backstepping_privileged"} <= set(baselines.PRIVILEGED)
    assert not set(baselines.PRIVILEGED) & set(baselines.POLICIES)  # never a training base
    scenario = scenarios.get("wang2014")
    policy = baselines.make_policy("nn_dsc_privileged", scenario)
    sim = FleetSim(scenario)
    obs = sim.reset(seeds=[0])
    with pytest.raises(RuntimeError, match="bind_simulator"):
        policy.act_batch(obs)
    with pytest.raises(ValueError, match="built for scenario"):
        policy.bind_simulator(FleetSim(scenarios.get("lossy_links")))
    policy.bind_simulator(sim)
    with pytest.raises(ValueError, match="not those of the fleets"):
        policy.act_batch(obs + 1.0)
    with pytest.raises(ValueError, match="bind it to the fleets"):
        policy.act_batch(obs, fleets=[0])


def test_ideal_link_observations_are_the_observations_on_ideal_links():
    sim = FleetSim(scenarios.get("wang2014"), num_fleets=2)
    policy = baselines.make_policy("nn_dsc", sim)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(30):
        np.testing.assert_array_equal(ideal_link_observations(sim), obs)
        obs = sim.step(policy.act_batch(obs))


def test_ideal_link_observations_hold_the_neighbours_current_values_under_loss_and_delay():
    scenario = scenarios.get("lossy_links")
    sim = FleetSim(scenario)
    policy = baselines.make_policy("nn_dsc", sim)
    obs = sim.reset(seeds=[3])
    for _ in range(60):
        obs = sim.step(policy.act_batch(obs))
    ideal = ideal_link_observations(sim)[0]
    m, slots, theta = scenario.message_size, sim.constants.slots, sim.arrays.theta[0]
    np.testing.assert_array_equal(ideal[:, :SLOTS], obs[0, :, :SLOTS])
    for k in range(slots.shape[1]):
        base = SLOTS + k * (SLOT_MSG + m)
        used = obs[0, :, base] != 0.0
        j = slots[used, k]
        truth = (theta[j] - theta[used]).astype(np.float32)
        np.testing.assert_array_equal(ideal[used, base + 1], truth)
        np.testing.assert_array_equal(ideal[:, base + SLOT_AGE], 0.0)
        message = sim.arrays.message[0, j, 0].astype(np.float32)
        np.testing.assert_array_equal(ideal[used, base + SLOT_MSG], message)
    assert obs[0, :, SLOTS + SLOT_AGE].max() > 0  # the real links were stale


def test_the_lumped_uncertainty_is_coriolis_and_damping_without_disturbances():
    """Hand calculation: with no unmodeled terms, f = C(nu) nu + D(nu) nu of the true model."""
    sim = FleetSim(_no_uncertainty(), num_fleets=2)
    policy = baselines.make_policy("nn_dsc", sim)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(20):
        obs = sim.step(policy.act_batch(obs))
    nu, params = sim.arrays.nu, sim.arrays.params
    expected = np.einsum(
        "bnij,bnj->bni", coriolis_matrix(params, nu) + damping_matrix(params, nu), nu
    )
    np.testing.assert_allclose(lumped_uncertainty(sim), expected, rtol=1e-12, atol=1e-12)


def test_the_lumped_uncertainty_closes_the_plant_balance_with_disturbances():
    """M nu'(tau) = tau - f for any force, current, waves and model spread included."""
    sim = FleetSim(make_scenario("bench_current_waves"), num_fleets=2)
    sim.reset(seeds=[4, 5])
    tau = np.random.default_rng(0).normal(0.0, 3.0, sim.arrays.tau_applied.shape)
    balance = np.einsum("bnij,bnj->bni", sim.mass_matrices(), sim.accelerations(tau))
    np.testing.assert_allclose(balance, tau - lumped_uncertainty(sim), rtol=1e-12, atol=1e-12)


def test_backstepping_privileged_acts_as_backstepping_where_the_knowledge_is_moot():
    """No model error, no disturbance, ideal links: the same actions up to rounding.

    The only difference left: the privileged f is evaluated at the simulator's
    float64 velocity, backstepping's C(nu) nu + D(nu) nu at the observed one,
    rounded to float32 (relative 6e-8), hence the tolerance.
    """
    sim = FleetSim(_no_uncertainty(), num_fleets=2)
    plain = baselines.make_policy("backstepping", sim)
    told = baselines.make_policy("backstepping_privileged", sim)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(200):
        actions = plain.act_batch(obs)
        np.testing.assert_allclose(told.act_batch(obs), actions, rtol=1e-6, atol=1e-6)
        obs = sim.step(actions)


def test_nn_dsc_privileged_uses_the_true_f_plus_m_nubar_dot_in_place_of_the_nn():
    sim = FleetSim(make_scenario("bench_heterogeneous"), num_fleets=2)
    policy = baselines.make_policy("nn_dsc_privileged", sim)
    obs = sim.reset(seeds=[0, 1])
    for _ in range(50):
        f, mass = lumped_uncertainty(sim), sim.mass_matrices()
        obs_next = sim.step(policy.act_batch(obs))
        told = f + np.einsum("bnij,bnj->bni", mass, policy.diagnostics["nubar_dot"])
        np.testing.assert_allclose(policy.diagnostics["nn_output"], told, rtol=1e-12, atol=1e-12)
        obs = obs_next


@pytest.mark.parametrize("name", ["nn_dsc", "backstepping"])
@pytest.mark.parametrize("scenario_name", ["bench_current_waves", "bench_lossy_links"])
def test_the_privileged_reference_is_better_where_the_information_matters(name, scenario_name):
    """Current and waves (true f) and lossy, delayed links (ideal links): lower cost every seed."""
    scenario = make_scenario(scenario_name)
    plain, told = (
        baselines.make_policy(policy, scenario) for policy in (name, f"{name}_privileged")
    )
    deployable, privileged = rollout_group([plain, told], scenario, [10, 11, 12])
    assert np.all(privileged["cost"] < 0.8 * deployable["cost"])
    assert np.all(
        privileged["cross_track_error_rms_window"] < deployable["cross_track_error_rms_window"]
    )


def test_a_group_rollout_gives_each_policy_its_own_runs_numbers_bit_for_bit():
    scenario = make_scenario("bench_lossy_links")
    names = ("nn_dsc", "nn_dsc_privileged", "backstepping_delay_comp")
    grouped = rollout_group(
        [baselines.make_policy(name, scenario) for name in names], scenario, [7, 8], max_steps=120
    )
    for name, metrics in zip(names, grouped, strict=True):
        alone = rollout(baselines.make_policy(name, scenario), scenario, [7, 8], max_steps=120)
        assert metrics.keys() == alone.keys()
        for metric, values in alone.items():
            np.testing.assert_array_equal(metrics[metric], values, err_msg=f"{name} {metric}")


def test_the_views_of_some_fleets_are_those_rows_of_all_fleets():
    task = scenarios.get("bench_lossy_links")
    sim = FleetSim(task, num_fleets=4)
    sim.reset(seeds=[0, 1, 2, 3])
    for _ in range(5):
        sim.step(np.zeros((4, task.n, sim.act_dim)))
    rows = np.array([3, 1])
    lumped, mass = true_dynamics(sim, rows)
    np.testing.assert_array_equal(lumped, lumped_uncertainty(sim)[rows])
    np.testing.assert_array_equal(mass, sim.mass_matrices()[rows])
    np.testing.assert_array_equal(
        ideal_link_observations(sim, rows), ideal_link_observations(sim)[rows]
    )
