"""Integral LOS guidance (``baselines.ilos``): its known property in a current, and its contract."""

from __future__ import annotations

import numpy as np
import pytest

import baselines
from cpf_env import scenarios
from cpf_env.model.disturbances import Disturbances, OceanCurrent
from cpf_env.model.graph import Graph
from cpf_env.model.paths import StraightLine
from cpf_env.scenarios import InitialState, Scenario
from cpf_env.sim.fleet import FleetSim

#: Control steps of the straight-line runs: 6,000 s at dt = 0.05 s (the integral settles
#: over thousands of seconds at v0 = 0.2 m/s: studies/ilos/line_in_current.py).
STEPS = 120_000
#: The last 100 s, over which the steady state is judged.
TAIL = 2_000


def _line_in_a_current(current: tuple[float, float]) -> Scenario:
    """Two vessels on parallel straight lines 3 m apart, 0.5 m off them, in a steady current."""
    paths = tuple(StraightLine(x0=0.0, y0=3.0 * i, heading=0.0) for i in range(2))
    return Scenario(
        name="line_in_a_current",
        paths=paths,
        topology=Graph.from_edges(2, [(0, 1)], leaders=(0,)),
        initial=InitialState(eta=((0.0, 0.5, 0.0), (0.0, 3.5, 0.0))),
        v0=0.2,
        disturbances=Disturbances(unmodeled_scale=0.0, current=OceanCurrent(velocity=current)),
        max_steps=STEPS + 1,
        max_path_error=50.0,
    )


def _cross_track(scenario: Scenario, **gains: float) -> tuple[np.ndarray, np.ndarray]:
    """The cross-track error y_e (m) of every step, (STEPS, n), and every force command."""
    sim = FleetSim(scenario, num_fleets=1)
    policy = baselines.make_policy("ilos", scenario, **gains)
    obs = sim.reset(seeds=[0])
    errors, forces = np.empty((STEPS, scenario.n)), np.empty((STEPS, scenario.n, 3))
    for k in range(STEPS):
        actions = policy.act_batch(obs)
        errors[k] = policy.diagnostics["aux_state"][0, :, 1]
        forces[k] = actions[0, :, :3]
        obs = sim.step(actions)
    return errors, forces


@pytest.fixture(scope="module")
def current_runs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    scenario = _line_in_a_current((0.0, 0.05))  # 5 cm/s across the path: a quarter of v0
    return {"ilos": _cross_track(scenario), "los": _cross_track(scenario, sigma=0.0)}


def test_ilos_reaches_zero_cross_track_error_in_a_constant_current(current_runs) -> None:
    """Børhaug, Pavlov & Pettersen (2008): the integral absorbs the sideslip, y_e -> 0."""
    errors, _ = current_runs["ilos"]
    assert np.abs(errors[:100]).max() > 0.4  # it starts 0.5 m off
    assert np.abs(errors[-TAIL:]).max() < 1e-3  # within 1 mm over the last 100 s


def test_plain_los_keeps_a_steady_offset_in_the_same_current(current_runs) -> None:
    """sigma = 0: the hull crabs into the current, and only a cross-track error turns it."""
    errors, _ = current_runs["los"]
    tail = errors[-TAIL:]
    assert np.all(np.abs(tail) > 0.5)  # metres off, on the downstream side
    assert np.ptp(tail, axis=0).max() < 1e-2  # steady, not oscillating
    assert np.all(np.sign(tail) == np.sign(tail[0, 0]))


def test_ilos_commands_no_sway_force(current_runs) -> None:
    for errors, forces in current_runs.values():
        assert np.all(forces[..., 1] == 0.0)
        assert np.all(np.isfinite(errors))


def test_without_a_current_both_converge_to_the_path() -> None:
    """No sideslip to absorb: plain LOS reaches the path as well (the offset is the current's)."""
    scenario = _line_in_a_current((0.0, 0.0))
    errors, _ = _cross_track(scenario, sigma=0.0)
    assert np.abs(errors[-TAIL:]).max() < 1e-3


def test_ilos_is_deterministic_and_batch_independent() -> None:
    """Same seed, same trajectory bit for bit; a fleet's actions do not depend on its batch."""

    def actions(seeds: list[int], steps: int = 400) -> np.ndarray:
        sim = FleetSim(scenarios.get("bench_current_waves"), num_fleets=len(seeds))
        policy = baselines.make_policy("ilos", sim)
        obs, out = sim.reset(seeds=seeds), []
        for _ in range(steps):
            out.append(policy.act_batch(obs))
            obs = sim.step(out[-1])
        return np.stack(out)

    three = actions([5, 6, 7])
    np.testing.assert_array_equal(three, actions([5, 6, 7]))
    np.testing.assert_array_equal(three[:, 1], actions([6])[:, 0])


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [("lookahead", 0.0, "lookahead must be a finite number > 0"),
     ("sigma", -1.0, "sigma must be a finite number >= 0"),
     ("k_surge", -1.0, "k_surge must be a finite number > 0"),
     ("k_yaw", 0.0, "k_yaw must be a finite number > 0"), ("gain", 1.0, "unknown option")],
)  # fmt: skip
def test_bad_gains_are_refused_naming_the_gain(option: str, value: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        baselines.make_policy("ilos", "bench_mild", **{option: value})
