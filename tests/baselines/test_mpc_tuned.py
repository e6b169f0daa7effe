"""``mpc_tuned``: ``mpc`` with a fast, rate-limited v0 estimator and nothing else changed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import baselines
from baselines.mpc import MPCPolicy
from baselines.mpc_tuned import K5, K6, MPCTuned
from cpf_bench.rollout import rollout
from cpf_env import FleetSim, scenarios
from cpf_env.model.graph import Graph
from cpf_env.model.paths import Sinusoid
from cpf_env.scenarios import splits

#: Small plans for short tests: one knot of 5 steps, no tail, 4 samples.
SHORT = {"horizon": 0.25, "tail": 0.0, "knot": 5, "samples": 4}


def test_it_is_deployable_and_defaults_to_the_tuned_gains():
    assert baselines.POLICIES["mpc_tuned"] is MPCTuned
    assert "mpc_tuned" not in baselines.PRIVILEGED
    policy = baselines.make_policy("mpc_tuned", "bench_mild", **SHORT)
    assert not policy.privileged
    assert (policy.gains.k5, policy.gains.k6) == (K5, K6)
    assert baselines.make_policy("mpc_tuned", "bench_mild", k5=2.0).gains.k5 == 2.0


def test_without_the_rate_limit_at_mpcs_gains_it_is_mpc_bit_for_bit():
    scenario = scenarios.get("bench_lossy_links")
    seeds = [10000, 10001]
    unlimited = MPCTuned(scenario, speed_rate=np.inf, k5=1.0, k6=1.0, **SHORT)
    tuned = rollout(unlimited, scenario, seeds, max_steps=60)
    plain = rollout(MPCPolicy(scenario, **SHORT), scenario, seeds, max_steps=60)
    for metric in ("cost", "cross_track_error_rms", "formation_error_rms"):
        np.testing.assert_array_equal(tuned[metric], plain[metric])


def test_the_speed_estimate_moves_at_most_its_rate_limit_per_step():
    """Over 300 steps of the tight force limits, the estimate climbs toward v0 at the
    limit (tau_max_u / (m - X_udot) x speed_rate x dt per step) and never faster."""
    scenario = scenarios.get("bench_saturation")
    sim = FleetSim(scenario, num_fleets=2)
    obs = sim.reset(seeds=[0, 1])
    policy = MPCTuned(sim, **SHORT)
    vessel = scenario.vessel_models[0]
    expected = 0.25 * scenario.dt * scenario.tau_max[0][0] / (vessel.mass - vessel.X_udot)
    np.testing.assert_allclose(policy.speed_step[0], expected, rtol=1e-12)
    speed = np.zeros((2, scenario.n))
    steps_at_limit = 0
    for _ in range(300):
        obs = sim.step(policy.act_batch(obs))
        estimate = policy.diagnostics["speed_estimate"]
        change = np.abs(estimate - speed)
        assert np.all(change <= policy.speed_step * (1 + 1e-12))
        steps_at_limit += int(np.any(np.isclose(change, policy.speed_step, rtol=1e-9)))
        speed = estimate
    assert steps_at_limit > 10  # the limit binds: the check above is not vacuous
    v0 = scenario.v0_schedule.values[0]
    np.testing.assert_allclose(speed, v0, atol=0.02)  # and the estimate still reaches v0


@pytest.mark.parametrize("rate", [0.0, -1.0, float("nan")])
def test_a_rate_limit_that_is_not_positive_is_refused(rate):
    with pytest.raises(ValueError, match="speed_rate must be > 0"):
        MPCTuned("bench_mild", speed_rate=rate)


def _star(n: int) -> scenarios.Scenario:
    """``bench_large_fleet_shift``'s star with n vessels, the hub in the middle."""
    base = splits.split_scenario("bench_large_fleet", "shift")
    offsets = [4.0 * (k - n // 2) for k in range(n)]
    eta = tuple((0.0, y + 1.0, 0.0) for y in offsets)
    initial = dataclasses.replace(base.initial, eta=eta, nu=None, theta=None)
    return base.replace(
        paths=tuple(Sinusoid(y0=y, amplitude=2.0, wavenumber=0.2) for y in offsets),
        topology=Graph.star(n, center=n // 2, leaders=(n // 2,)),
        initial=initial,
        tau_max=(base.tau_max[0],) * n,
        tau_min=(base.tau_min[0],) * n,
        vessels=(base.vessels[0],) * n,
    )


def test_on_a_large_star_the_estimators_step_stays_bounded_at_the_fast_gains():
    """An 11-vessel star (hub degree 10): at 5 /s, dt (k5 d + k6 l) = 2.75 for the hub, so an
    uncapped step would give the hub's old estimate the weight -1.75 and swing ever wider
    (removing the cap in ``MPCPolicy._update_knowledge`` fails this test); the capped step
    keeps every estimate a convex combination of the values it combines, so it stays
    within [0, v0] on the way up from 0 (no rate limit here, to see the step alone)."""
    scenario = _star(11)
    v0 = scenario.v0_schedule.values[0]
    policy = MPCTuned(scenario, speed_rate=np.inf, **SHORT)
    hub = scenario.n // 2
    assert scenario.dt * (K5 * (scenario.n - 1) + K6) > 2.0  # an uncapped step diverges
    sim = FleetSim(scenario, num_fleets=1)
    obs = sim.reset(seeds=[0])
    low, high = 0.0, 0.0
    for _ in range(300):
        obs = sim.step(policy.act_batch(obs))
        estimate = policy.diagnostics["speed_estimate"]
        low, high = min(low, float(estimate.min())), max(high, float(estimate.max()))
    assert low >= 0.0 and high <= v0 * (1 + 1e-9), (low, high)
    assert policy.diagnostics["speed_estimate"][0, hub] > 0.9 * v0  # and the hub got there
