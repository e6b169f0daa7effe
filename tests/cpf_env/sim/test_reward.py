"""Reward forms: validation, and what the log form changes against the quadratic one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from baselines import make_policy
from cpf_env import FleetSim, scenarios
from cpf_env.scenarios.reward_weights import REWARD_TERMS, RewardWeights


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"form": "cubic"}, "form must be one of"),
        ({"position": -1.0}, "position must be a finite number >= 0"),
        ({"sync_scale": 0.0}, "sync_scale must be a finite number > 0"),
        ({"speed_scale": float("inf")}, "speed_scale"),
        ({"effort": "0.1"}, "effort"),
    ],
)
def test_bad_reward_settings_say_what_to_fix(changes: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RewardWeights(**changes)


def test_default_is_the_log_form_with_task_tolerances() -> None:
    weights = RewardWeights()
    assert weights.form == "log"
    assert (weights.position_scale, weights.sync_scale) == (0.01, 0.001)
    assert weights.encode().shape == (11,)


def steady_state_costs(form: str) -> dict[str, np.ndarray]:
    """Per-term cost over the last quarter, nn_dsc and backstepping on saturation_heavy."""
    base = scenarios.get("saturation_heavy")
    scenario = base.replace(reward=dataclasses.replace(base.reward, form=form), max_steps=600)
    costs = {}
    for name in ("nn_dsc", "backstepping"):
        sim = FleetSim(scenario)
        policy = make_policy(name, scenario)
        obs = sim.reset(seeds=[0])
        tail = np.zeros(len(REWARD_TERMS))
        for t in range(scenario.max_steps):
            obs = sim.step(policy.act_batch(obs))
            if t >= 450:
                tail -= sim.arrays.reward_terms[0].sum(axis=0)
        costs[name] = tail
    return costs


def test_log_form_makes_the_path_term_the_steady_state_cost() -> None:
    """Quadratic: effort dominates the steady state and the policies' costs differ by about 1 %.
    Log: the position term dominates and the more accurate policy costs clearly less."""
    position, effort = REWARD_TERMS.index("position"), REWARD_TERMS.index("effort")
    quadratic, log = steady_state_costs("quadratic"), steady_state_costs("log")
    assert quadratic["nn_dsc"][effort] > 5 * quadratic["nn_dsc"][position]
    assert log["nn_dsc"][position] > 5 * log["nn_dsc"][effort]
    quadratic_gap = quadratic["nn_dsc"].sum() / quadratic["backstepping"].sum() - 1.0
    log_gap = log["nn_dsc"].sum() / log["backstepping"].sum() - 1.0
    assert log_gap > 10 * abs(quadratic_gap)


@pytest.mark.parametrize("form", ["log", "quadratic"])
def test_leaving_the_path_costs_the_rest_of_the_episode_at_the_limit(form: str) -> None:
    """On the step a fleet terminates every vessel pays w_fail (T - t) w_pos rho(d_max / s_pos),
    once; so ending early is never cheaper than staying at the termination distance."""
    reward = RewardWeights(form=form, failure=0.7, position=1.3, position_scale=0.02)
    scenario = scenarios.get("wang2014").replace(reward=reward, max_path_error=1.5)
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    actions = np.zeros((2, 5, sim.act_dim))
    actions[0, :, 0] = -9.2  # fleet 0 backs away from its path; fleet 1 drifts, slowly
    step = 0
    while not sim.arrays.terminated[0]:
        obs = sim.step(actions)
        step += 1
        assert step < 500
    failure = REWARD_TERMS.index("failure")
    terms = sim.arrays.reward_terms
    x = 1.5 / 0.02 if form == "log" else 1.5
    at_limit = 1.3 * (np.log1p(x**2) if form == "log" else x**2)
    expected = -0.7 * (scenario.max_steps - step) * scenario.dt * at_limit
    np.testing.assert_allclose(terms[0, :, failure], expected, rtol=1e-12)
    np.testing.assert_allclose(sim.arrays.reward[0], terms[0].sum(axis=1), rtol=1e-12)
    assert not sim.arrays.terminated[1] and np.all(terms[1, :, failure] == 0.0)
    del obs
