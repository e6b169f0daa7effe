"""Separation (``cpf_env.model.separation``): the keep-out cost, the collision and the layout."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpf_env import scenarios
from cpf_env.evaluation.fleet_metrics import FleetMetrics
from cpf_env.model.graph import Graph
from cpf_env.model.paths import StraightLine
from cpf_env.model.separation import Separation
from cpf_env.scenarios import hard
from cpf_env.scenarios.crossing import crossing_fleet
from cpf_env.scenarios.reward_weights import REWARD_TERMS
from cpf_env.scenarios.scenario import InitialState, Scenario
from cpf_env.sim.fleet import FleetSim

SEPARATION = REWARD_TERMS.index("separation")


def _pair(gap: float, separation: Separation | None, **changes: object) -> Scenario:
    """Two vessels at rest on parallel eastbound lines ``gap`` metres apart."""
    return Scenario(
        name="pair",
        paths=(StraightLine(y0=0.0), StraightLine(y0=gap)),
        topology=Graph.path(2, leaders=(0,)),
        initial=InitialState(eta=((0.0, 0.0, 0.0), (0.0, gap, 0.0))),
        separation=separation,
        **changes,  # type: ignore[arg-type]
    )


def _step(task: Scenario, sway: float = 0.0, steps: int = 1) -> FleetSim:
    """``steps`` steps, vessel 1 pushed towards vessel 0 by a sway force ``sway`` (N)."""
    sim = FleetSim(task, num_fleets=1)
    sim.reset(seeds=[0])
    action = np.zeros((1, task.n, 4 + task.message_size))
    action[0, 1, 1] = -sway
    for _ in range(steps):
        sim.step(action)
    return sim


def test_the_term_is_the_squared_intrusion_over_the_margin_times_weight_and_dt() -> None:
    """Vessel 1 starts 1.6 m off and is pushed inside the 1.5 m keep-out distance."""
    sep = Separation(safe_distance=1.5, hard_distance=0.5, weight=10.0)
    sim = _step(_pair(1.6, sep), sway=3.0, steps=60)
    a = sim.arrays
    gap = float(np.hypot(*(a.eta[0, 0, :2] - a.eta[0, 1, :2])))
    assert 0.5 < gap < 1.4
    expected = -sim.scenario.dt * 10.0 * ((1.5 - gap) / 1.0) ** 2
    np.testing.assert_allclose(a.reward_terms[0, :, SEPARATION], [expected, expected], rtol=1e-12)
    np.testing.assert_allclose(a.reward[0], a.reward_terms[0].sum(axis=1), rtol=1e-12)
    assert not a.terminated[0]


def test_outside_the_safe_distance_or_without_a_constraint_the_term_is_zero() -> None:
    far = _step(_pair(1.6, Separation()), steps=5)
    none = _step(_pair(0.6, None), sway=3.0, steps=60)
    assert np.all(far.arrays.reward_terms[..., SEPARATION] == 0.0)
    assert np.all(none.arrays.reward_terms[..., SEPARATION] == 0.0)
    assert not none.arrays.terminated[0]


def test_closer_than_the_hard_distance_the_fleet_collides_and_pays_the_failure_term() -> None:
    """Vessel 1 starts 0.8 m from vessel 0 and is pushed sideways into it until they collide."""
    task = _pair(0.8, Separation(safe_distance=0.7, hard_distance=0.5))
    sim = FleetSim(task, num_fleets=1)
    sim.reset(seeds=[0])
    action = np.zeros((1, 2, 4 + task.message_size))
    action[0, 1, 1] = -4.0
    for step in range(200):  # noqa: B007  (read after the loop)
        sim.step(action)
        gap = float(np.hypot(*(sim.arrays.eta[0, 0, :2] - sim.arrays.eta[0, 1, :2])))
        if sim.arrays.terminated[0]:
            break
    assert sim.arrays.terminated[0] and gap < 0.5
    assert np.all(sim.arrays.reward_terms[0, :, REWARD_TERMS.index("failure")] < 0.0)
    assert step > 0  # it took the hull some steps to close 0.3 m


def test_bad_settings_are_refused_with_what_to_change() -> None:
    with pytest.raises(ValueError, match="0 <= hard_distance < safe_distance"):
        Separation(safe_distance=0.5, hard_distance=0.5)
    with pytest.raises(ValueError, match="weight must be finite and >= 0"):
        Separation(weight=-1.0)
    with pytest.raises(ValueError, match="must be a number"):
        Separation(safe_distance=True)
    with pytest.raises(ValueError, match=r"vessels 0 and 1 start 1 m apart .* keep-out zone"):
        _pair(1.0, Separation(safe_distance=1.5))
    with pytest.raises(ValueError, match=r"must be a cpf_env\.model\.separation\.Separation"):
        _pair(2.0, 1.5)  # type: ignore[arg-type]


def test_the_closest_approach_metric_is_the_smallest_gap_where_separation_is_constrained() -> None:
    def closest(task: Scenario) -> tuple[float, float]:
        sim = FleetSim(task, num_fleets=1)
        sim.reset(seeds=[0])
        metrics = FleetMetrics(sim, horizon=60)
        metrics.start(sim.arrays)
        action = np.zeros((1, 2, 4 + task.message_size))
        action[0, 1, 1] = -3.0
        gaps = []
        for t in range(60):
            sim.step(action)
            metrics.record(t, sim.arrays, 0.1, None)
            gaps.append(float(np.hypot(*(sim.arrays.eta[0, 0, :2] - sim.arrays.eta[0, 1, :2]))))
        result = metrics.reduce(np.array([60]), np.array([False]))
        return float(result["separation_min"][0]), min(gaps)

    measured, smallest = closest(_pair(3.0, Separation()))
    assert measured == pytest.approx(smallest, rel=1e-12) and smallest < 3.0 - 0.05
    unconstrained, _ = closest(_pair(3.0, None))
    assert math.isnan(unconstrained)


def test_crossing_partners_meet_at_offset_over_root_two_and_others_stay_apart() -> None:
    """The synchronized formation (every theta equal) over the first 20 m of path."""
    for pairs in (2, 5):
        paths, initial, topology = crossing_fleet(pairs, offset=0.3)
        theta = np.linspace(0.0, 20.0, 8001)
        position = np.stack([path.evaluate(theta)[:, 0, :2] for path in paths], axis=1)
        for i in range(2 * pairs):
            for j in range(i + 1, 2 * pairs):
                closest = np.linalg.norm(position[:, i] - position[:, j], axis=1).min()
                if i // 2 == j // 2:
                    assert closest == pytest.approx(0.3 / math.sqrt(2.0), abs=1e-3)
                    assert topology.adjacency[i, j] > 0  # partners hear each other
                else:
                    assert closest > 4.5
        assert np.allclose(np.array(initial.eta)[:, :2], position[0])


def test_without_a_separation_every_core_cost_is_untouched() -> None:
    """The term is exactly zero without a constraint: the reward is the five terms' sum."""
    task = scenarios.get("bench_mild")
    sim = FleetSim(task, num_fleets=2)
    sim.reset(seeds=[0, 1])
    action = np.zeros((2, task.n, 4 + task.message_size))
    action[..., 0], action[..., 3] = 2.0, 0.1
    for _ in range(30):
        sim.step(action)
    terms = sim.arrays.reward_terms
    assert np.all(terms[..., SEPARATION] == 0.0)
    assert np.array_equal(sim.arrays.reward, terms[..., :5].sum(axis=2) + terms[..., 5])


def test_the_crossing_scenarios_refuse_a_layout_that_would_start_inside_the_keep_out() -> None:
    with pytest.raises(ValueError, match="keep-out zone"):
        hard.hard_crossing().replace(separation=Separation(safe_distance=6.0, hard_distance=0.5))
