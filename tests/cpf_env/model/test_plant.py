"""The simulator integrates each vessel exactly as ``plant.rk4_period`` does, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.model.disturbances import D_SCALE
from cpf_env.model.plant import rk4_period
from cpf_env.sim.fleet import FleetSim


@pytest.mark.parametrize("name", ["bench_current_waves", "bench_heterogeneous", "wang2014"])
def test_fleet_step_integrates_every_vessel_as_rk4_period(name: str) -> None:
    """The kernel goes sub-step by sub-step over a fleet's vessels (sharing the time terms);
    the result must be the single-vessel integrator's, to the last bit."""
    sim = FleetSim(scenarios.get(name), num_fleets=3)
    sim.reset(seeds=[4, 5, 6])
    a, c = sim.arrays, sim.constants
    rng = np.random.default_rng(1)
    scale = float(c.disturbances[D_SCALE])
    for _ in range(15):
        actions = np.zeros((3, sim.n, sim.act_dim))
        actions[..., :3] = rng.uniform(-1.2, 1.2, (3, sim.n, 3)) * c.tau_scale
        applied = np.clip(actions[..., :3], c.tau_min, c.tau_max)
        expected = np.empty((3, sim.n, 6))
        for b in range(3):
            t0 = float(a.step[b]) * c.dt
            for i in range(sim.n):
                force = a.waves[b, i] + a.wind[b, i]
                load = (*applied[b, i], *force, *a.current[b])
                state = (*a.eta[b, i], *a.nu[b, i])
                expected[b, i] = rk4_period(a.params[b, i], scale, t0, c.dt, c.substeps,
                                            tuple(float(x) for x in state),
                                            tuple(float(x) for x in load))  # fmt: skip
        sim.step(actions)
        assert np.array_equal(np.concatenate([a.eta, a.nu], axis=2), expected)
