"""Reward forms: validation, and what the log form changes against the quadratic one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from baselines import make_policy
from cpf_env import FleetSim, scenarios
from cpf_env.reward import REWARD_TERMS, RewardWeights


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
    assert weights.encode().shape == (10,)


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
