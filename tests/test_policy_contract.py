"""One policy contract (cpf_env.envs.policy.FleetPolicy) for every kind of policy."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT

import baselines
from cpf_commands.common import policies
from cpf_commands.common.policies import resolve_policy
from cpf_env import FleetSim, scenarios
from cpf_env.envs import residual
from cpf_env.envs.policy import FleetPolicy, fleet_mask
from cpf_env.envs.residual import ZeroPolicy


def test_the_contract_has_one_name() -> None:
    assert not hasattr(residual, "BasePolicy") and not hasattr(policies, "BenchPolicy")


@pytest.mark.parametrize("name", sorted({**baselines.POLICIES, **baselines.UNDERACTUATED}))
def test_every_baseline_meets_the_contract(name: str) -> None:
    scenario = scenarios.get("wang2014")
    policy = baselines.make_policy(name, scenario)
    assert isinstance(policy, FleetPolicy)
    obs = FleetSim(scenario, num_fleets=2).reset(seeds=[0, 1])
    actions = policy.act_batch(obs)
    assert actions.shape == (2, scenario.n, 4 + scenario.message_size)
    assert actions.dtype == np.float64
    policy.reset_fleets(np.array([True, False]))  # the batched-env member, present


def test_fleet_mask_reads_a_mask_or_indices_and_refuses_others() -> None:
    np.testing.assert_array_equal(fleet_mask([2, 0], 3), [True, False, True])
    np.testing.assert_array_equal(fleet_mask(np.array([False, True, False]), 3), [0, 1, 0])
    np.testing.assert_array_equal(fleet_mask([], 3), [False, False, False])
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        fleet_mask(np.array([True, False]), 3)
    with pytest.raises(ValueError, match=r"indices in \[0, 3\)"):
        fleet_mask([3], 3)
    with pytest.raises(ValueError, match=r"indices in \[0, 3\)"):
        fleet_mask([0.5], 3)


@pytest.mark.parametrize("name", sorted(baselines.DEPLOYABLE))
def test_reset_fleets_takes_a_mask_or_indices_alike_and_spares_the_others(name: str) -> None:
    """Restarting fleet 1 by mask or by index: the same actions after, fleet 0 untouched."""
    # Sensors, for the navigation filters; room for the safety filter's broadcast.
    scenario = scenarios.make_scenario("hard_sensing", max_steps=40).replace(message_size=6)
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    by_mask, by_index, untouched = (baselines.make_policy(name, scenario) for _ in range(3))
    for _ in range(12):
        actions = by_mask.act_batch(obs)
        by_index.act_batch(obs)
        untouched.act_batch(obs)
        obs = sim.step(actions).copy()
    by_mask.reset_fleets(np.array([False, True]))
    by_index.reset_fleets([1])
    for _ in range(8):
        actions = by_mask.act_batch(obs)
        np.testing.assert_array_equal(by_index.act_batch(obs), actions)
        np.testing.assert_array_equal(untouched.act_batch(obs)[0], actions[0])
        obs = sim.step(actions).copy()


@pytest.mark.parametrize("name", sorted(baselines.DEPLOYABLE))
def test_each_deployable_design_writes_only_the_message_entries_it_declares(name: str) -> None:
    """What a learner's messages rely on: the entries after ``message_entries`` stay zero."""
    scenario = scenarios.make_scenario("hard_crossing", max_steps=40)
    sim = FleetSim(scenario, num_fleets=2)
    policy = baselines.make_policy(name, scenario)
    obs = sim.reset(seeds=[0, 1])
    declared = policy.message_entries
    assert 1 <= declared <= scenario.message_size
    written = np.zeros(scenario.message_size, dtype=bool)
    for _ in range(40):
        actions = policy.act_batch(obs)
        written |= (actions[..., 4:] != 0.0).any(axis=(0, 1))
        obs = sim.step(actions)
    assert not written[declared:].any() and written[0]


def test_a_trained_agent_and_the_zero_policy_meet_it() -> None:
    from agents import load_policy

    agent = ROOT / "tests" / "fixtures" / "agents" / "residual_ppo_lossy_links"
    assert isinstance(load_policy(agent, "bench_lossy_links"), FleetPolicy)
    assert isinstance(ZeroPolicy(4), FleetPolicy)


def test_the_resolver_accepts_a_plain_object_with_the_contract_and_refuses_others() -> None:
    class Minimal:
        """act_batch(obs), reset(seed), diagnostics: what the commands need."""

        def __init__(self) -> None:
            self.diagnostics: dict = {}

        def act_batch(self, obs, fleets=None):
            return np.zeros((*np.shape(obs)[:2], 4))

        def reset(self, seed=None):
            del seed

    minimal = Minimal()
    assert resolve_policy(minimal, "wang2014") is minimal
    with pytest.raises(ValueError, match="cannot use int as a policy"):
        resolve_policy(3, "wang2014")  # type: ignore[arg-type]
