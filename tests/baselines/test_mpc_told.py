"""``mpc`` told one thing: each member knows exactly its one piece of truth and mpc's rest."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from baselines.mpc import MPCPolicy, MPCPrivileged
from baselines.mpc_told import MPCToldDynamics, MPCToldLinks, MPCToldV0
from cpf_bench.rollout import rollout
from cpf_env import FleetSim, scenarios
from cpf_env.evaluation.privileged import ideal_link_observations

#: Small plans for short tests: one knot of 5 steps, no tail, 4 samples.
SHORT = {"horizon": 0.25, "tail": 0.0, "knot": 5, "samples": 4}
TOLD = {"mpc_told_dynamics": MPCToldDynamics, "mpc_told_links": MPCToldLinks,
        "mpc_told_v0": MPCToldV0}  # fmt: skip


def test_they_are_privileged_references_that_read_the_simulator():
    for name, cls in TOLD.items():
        assert baselines.PRIVILEGED[name] is cls and name not in baselines.POLICIES
        policy = baselines.make_policy(name, "bench_mild", **SHORT)
        assert policy.privileged
        sim = FleetSim(scenarios.get("bench_mild"), num_fleets=1)
        with pytest.raises(RuntimeError, match="bind_simulator"):
            policy.act_batch(sim.reset(seeds=[0]))


#: Per member, whose each piece of knowledge is: "told" (mpc_privileged's, the truth),
#: "mpc" (mpc's on the observations as received) or "mpc_ideal" (mpc's on ideal links).
SOURCES = {
    "mpc_told_dynamics": {"links": "received", "model": "told", "speed": "mpc"},
    "mpc_told_links": {"links": "ideal", "model": "mpc", "speed": "mpc_ideal"},
    "mpc_told_v0": {"links": "received", "model": "mpc", "speed": "told"},
}


@pytest.mark.parametrize("name", sorted(TOLD))
def test_each_member_is_told_exactly_its_one_thing(name):
    """On lossy, delayed links with model error and disturbances (so that every piece
    differs between mpc and the truth), each member's observations, model, residual force
    and v0 estimate are bit for bit the truth's for its one piece and mpc's for the rest,
    with shadows fed the same observations of the same run."""
    scenario = scenarios.get("bench_lossy_links")
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[10000, 10001])
    member = TOLD[name](sim, **SHORT)
    shadows = {"told": MPCPrivileged(sim, **SHORT), "mpc": MPCPolicy(scenario, **SHORT),
               "mpc_ideal": MPCPolicy(scenario, **SHORT)}  # fmt: skip
    source = SOURCES[name]
    differs = {"links": 0, "model": 0, "speed": 0}
    for _ in range(40):
        ideal = ideal_link_observations(sim).astype(np.float64)
        actions = member.act_batch(obs)
        shadows["told"].act_batch(obs)
        shadows["mpc"].act_batch(obs)
        shadows["mpc_ideal"].act_batch(ideal)
        given = np.asarray(obs, dtype=np.float64)
        expected_links = ideal if source["links"] == "ideal" else given
        np.testing.assert_array_equal(member._local(given), expected_links)
        model = shadows[source["model"]]
        np.testing.assert_array_equal(member._params, model._params)
        np.testing.assert_array_equal(member._residual, model._residual)
        speed = shadows[source["speed"]]._speed
        np.testing.assert_array_equal(member.diagnostics["speed_estimate"], speed)
        differs["links"] += int(not np.array_equal(ideal, given))
        differs["model"] += int(
            not np.array_equal(shadows["told"]._residual, shadows["mpc"]._residual)
        )
        differs["speed"] += int(not np.array_equal(shadows["told"]._speed, shadows["mpc"]._speed))
        obs = sim.step(actions)
    # the one told piece differed from mpc's on this run, so the checks are not vacuous
    told = {"mpc_told_dynamics": "model", "mpc_told_links": "links", "mpc_told_v0": "speed"}
    assert differs[told[name]] > 0 and differs["model"] > 0, differs


def test_told_v0_knows_each_fleets_own_time():
    """Fleets of one simulator at different times of a v0 schedule get each their own v0."""
    scenario = scenarios.get("bench_switching")
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    policy = MPCToldV0(sim, **SHORT)
    step_up = round(scenario.v0_schedule.times[1] / scenario.dt)
    sim.arrays.step[1] = step_up  # fleet 1 is past the schedule's first step
    policy.act_batch(obs)
    speed = policy.diagnostics["speed_estimate"]
    assert np.all(speed[0] == scenario.v0_schedule.values[0])
    assert np.all(speed[1] == scenario.v0_schedule.values[1])


def test_told_links_is_mpc_on_links_that_are_already_ideal():
    """Without loss and delay the ideal-link observations are the observations: mpc_told_links
    then acts as mpc bit for bit (it is told nothing more)."""
    scenario = scenarios.get("bench_mild")
    told = rollout(MPCToldLinks(scenario, **SHORT), scenario, [10000, 10001], max_steps=40)
    plain = rollout(MPCPolicy(scenario, **SHORT), scenario, [10000, 10001], max_steps=40)
    np.testing.assert_array_equal(told["cost"], plain["cost"])
