"""Delay-compensated consensus: a no-op on ideal links, a better prediction on delayed ones."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from cpf_env import FleetSim, scenarios
from cpf_env.sim.fleet import observation_layout


@pytest.mark.parametrize("name", ["nn_dsc", "backstepping"])
def test_ideal_links_give_the_parent_policy_bit_for_bit(name):
    scenario = scenarios.get("wang2014")
    runs = []
    for policy_name in (name, f"{name}_delay_comp"):
        sim = FleetSim(scenario, num_fleets=2)
        policy = baselines.make_policy(policy_name, sim)
        obs = sim.reset(seeds=[0, 1])
        actions = []
        for _ in range(40):
            actions.append(policy.act_batch(obs))
            obs = sim.step(actions[-1])
        runs.append(np.stack(actions))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_compensated_theta_differences_track_the_true_ones_under_delay():
    """With a 5-step delay, theta_j advanced by age x dt x vhat_j is closer to the truth."""
    scenario = scenarios.get("lossy_links")
    layout = observation_layout(scenario)
    sim = FleetSim(scenario)
    policy = baselines.make_policy("nn_dsc_delay_comp", sim)
    obs = sim.reset(seeds=[0])
    received_error, compensated_error = [], []
    slot_neighbour = sim.constants.slots  # (n, K) index j of each slot
    for k in range(400):
        obs = sim.step(policy.act_batch(obs))
        if k < 200:  # after the start-up transient of the speed estimates
            continue
        weight = layout.slot_weights(obs[0])
        dtheta = layout.slot_theta_differences(obs[0])
        ages = layout.slot_ages(obs[0])
        vhat = layout.slot_messages(obs[0])[..., 0]
        theta = sim.arrays.theta[0]
        truth = theta[slot_neighbour] - theta[:, None]
        used = weight > 0
        received_error.append(np.abs(dtheta - truth)[used])
        compensated_error.append(np.abs(dtheta + ages * scenario.dt * vhat - truth)[used])
    received = np.concatenate(received_error).mean()
    compensated = np.concatenate(compensated_error).mean()
    assert received > 0.0
    assert compensated < 0.2 * received
