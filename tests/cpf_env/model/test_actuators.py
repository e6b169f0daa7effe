"""Thruster dynamics (``cpf_env.model.actuators``): the lag's time constant and the slew limit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.model.actuators import Thrusters
from cpf_env.sim.fleet import FleetSim

BASE = scenarios.get("bench_mild")


def _applied(thrusters: Thrusters, command: tuple[float, float, float], steps: int) -> np.ndarray:
    """The applied force of vessel 0 (steps, 3) under a constant command from rest."""
    sim = FleetSim(BASE.replace(thrusters=thrusters), num_fleets=1)
    sim.reset(seeds=[0])
    action = np.zeros((1, BASE.n, 4 + BASE.message_size))
    action[0, :, :3] = command
    out = np.empty((steps, 3))
    for k in range(steps):
        sim.step(action)
        out[k] = sim.arrays.tau_applied[0, 0]
    return out


def test_a_first_order_lag_reaches_63_percent_after_one_time_constant() -> None:
    """x_k = F (1 - exp(-k dt / T)): the exact step response of x' = (F - x) / T."""
    T, dt = 0.5, BASE.dt
    applied = _applied(Thrusters(time_constant=T), (4.0, -2.0, 1.0), 40)
    k = np.arange(1, 41)[:, None]
    expected = np.array([4.0, -2.0, 1.0]) * (1.0 - np.exp(-k * dt / T))
    np.testing.assert_allclose(applied, expected, rtol=1e-12, atol=1e-12)
    one = round(T / dt) - 1  # after T seconds (row k - 1 is after k steps)
    np.testing.assert_allclose(applied[one] / [4.0, -2.0, 1.0], 1.0 - math.exp(-1.0), rtol=1e-12)


def test_the_slew_limit_ramps_the_force_and_saturation_still_bounds_it() -> None:
    """R = 2 N/s at dt = 0.05 s: 0.1 N per step, up to the 9.2 N limit (a 100 N command)."""
    applied = _applied(Thrusters(rate_limit=(2.0, 2.0, 1.0)), (100.0, -1.0, 0.3), 120)
    np.testing.assert_allclose(applied[:10, 0], 0.1 * np.arange(1, 11), rtol=1e-12)
    assert np.all(np.diff(applied[:, 0]) <= 0.1 + 1e-12)
    assert applied[-1, 0] == BASE.tau_max[0][0]  # saturated, never beyond
    np.testing.assert_allclose(applied[9:, 1], -1.0)  # reached after 10 steps
    np.testing.assert_allclose(applied[5:, 2], 0.3)


def test_the_lag_and_the_limit_compose_and_start_from_rest_at_every_reset() -> None:
    both = Thrusters(time_constant=1.0, rate_limit=(1.0, 1.0, 1.0))
    applied = _applied(both, (9.0, 0.0, 0.0), 200)
    assert np.all(np.diff(applied[:, 0]) <= 0.05 + 1e-12) and np.all(np.diff(applied[:, 0]) >= 0)
    sim = FleetSim(BASE.replace(thrusters=both), num_fleets=1)
    sim.reset(seeds=[0])
    sim.step(np.full((1, BASE.n, 5), 5.0))
    assert np.all(sim.arrays.tau_applied != 0.0)
    obs = sim.reset(seeds=[0])
    assert np.all(sim.arrays.tau_applied == 0.0) and np.all(obs[..., 13:16] == 0.0)


def test_instant_thrusters_are_the_saturated_command_bit_for_bit() -> None:
    """The default: the applied force is the saturation of the command, as before."""
    assert Thrusters().instant and BASE.thrusters == Thrusters()
    applied = _applied(Thrusters(), (100.0, -2.0, 0.5), 3)
    assert np.array_equal(applied, np.tile([9.2, -2.0, 0.5], (3, 1)))


def test_the_observation_reports_the_lagged_applied_force() -> None:
    sim = FleetSim(BASE.replace(thrusters=Thrusters(time_constant=0.3)), num_fleets=1)
    sim.reset(seeds=[0])
    obs = sim.step(np.full((1, BASE.n, 5), 1.0))
    np.testing.assert_array_equal(obs[0, :, 13:16], sim.arrays.tau_applied[0].astype(np.float32))
    assert np.all(obs[0, :, 13:16] < 1.0)


@pytest.mark.parametrize(
    ("options", "message"),
    [({"time_constant": -0.1}, "negative lag"), ({"time_constant": math.inf}, ">= 0"),
     ({"rate_limit": (1.0, 0.0, 1.0)}, "three slew rates > 0"),
     ({"rate_limit": (1.0, 1.0)}, "three slew rates")],
)  # fmt: skip
def test_bad_thruster_settings_are_refused_saying_what_to_change(options, message) -> None:
    with pytest.raises(ValueError, match=message):
        Thrusters(**options)
