"""The procedural scenario distribution: determinism, validity, coverage, held-out refusal."""

from __future__ import annotations

import re

import numpy as np
import pytest

from cpf_env.scenarios import splits
from cpf_env.scenarios.sampler import (
    GRAPH_FAMILIES,
    NOMINAL_TAU_MAX,
    PATH_FAMILIES,
    ScenarioDistribution,
    check_not_held_out,
)
from cpf_env.sim.fleet import FleetSim

DRAWS = range(200)


@pytest.fixture(scope="module")
def draws() -> list:
    fleets = ScenarioDistribution()
    return [fleets.sample(seed) for seed in DRAWS]


def test_same_seed_same_scenario_and_seeds_differ(draws: list) -> None:
    again = ScenarioDistribution().sample(17)
    assert again == draws[17]
    assert again.paths == draws[17].paths and again.initial == draws[17].initial
    assert len({d.paths for d in draws}) == len(draws)


def test_every_draw_is_valid(draws: list) -> None:
    fleets = ScenarioDistribution()
    for scenario in draws:
        lo, hi = fleets.sizes
        assert lo <= scenario.n <= hi
        for graph in scenario.switching.graphs:
            graph.validate_for_consensus()
        # every vessel starts on its path's point at theta = 0, along its tangent
        for path, eta in zip(scenario.paths, scenario.initial.eta, strict=True):
            np.testing.assert_allclose(path.evaluate(0.0)[0], eta, atol=1e-12)
        assert fleets.v0[0] <= scenario.v0_schedule.values[0] <= fleets.v0[1]
        assert fleets.loss[0] <= scenario.links.loss_probability <= fleets.loss[1]
        assert fleets.delay[0] <= scenario.links.delay_steps <= fleets.delay[1]
        assert fleets.model_spread[0] <= scenario.model_spread <= fleets.model_spread[1]


def test_draws_run_in_the_simulator(draws: list) -> None:
    for scenario in draws[:5]:
        sim = FleetSim(scenario, num_fleets=2)
        sim.reset(seeds=[3, 4])
        for _ in range(20):
            obs = sim.step(np.zeros((2, scenario.n, 4 + scenario.message_size)))
        assert np.all(np.isfinite(obs))


def test_every_family_is_drawn(draws: list) -> None:
    graphs, paths = set(), set()
    for scenario in draws:
        match = re.search(r"(\w+) graph, (\w+) paths", scenario.description)
        assert match is not None
        graphs.add(match.group(1))
        paths.add(match.group(2))
    assert graphs == set(GRAPH_FAMILIES)
    assert paths == set(PATH_FAMILIES)
    mixed = [d for d in draws if "mixed paths" in d.description]
    assert any(len({type(p) for p in d.paths}) > 1 for d in mixed)
    stars = [d for d in draws if "star graph" in d.description]
    for scenario in stars:
        degree = scenario.switching.graphs[0].degree
        assert degree.max() == scenario.n - 1 and np.sum(degree == 1) == scenario.n - 1


def test_max_degree_caps_every_graph() -> None:
    fleets = ScenarioDistribution(sizes=(6, 10), max_degree=3)
    for seed in range(60):
        scenario = fleets.sample(seed)
        assert scenario.switching.graphs[0].degree.max() <= 3
        assert "star graph" not in scenario.description
    with pytest.raises(ValueError, match="no graph family"):
        ScenarioDistribution(sizes=(6, 6), graph_families=("star",), max_degree=3).sample(0)


def test_training_and_evaluation_seeds_are_disjoint() -> None:
    fleets = ScenarioDistribution()
    with pytest.raises(ValueError, match="evaluation=True"):
        fleets.sample(splits.EVALUATION_SEED)
    with pytest.raises(ValueError, match="evaluation draws use seeds at or above"):
        fleets.sample(5, evaluation=True)
    held = fleets.sample(splits.EVALUATION_SEED + 3, evaluation=True)
    assert "evaluation fleet" in held.description


@pytest.mark.parametrize("name", sorted(splits.SHIFTS))
@pytest.mark.parametrize("split", splits.SPLITS)
def test_evaluation_splits_are_refused(name: str, split: str) -> None:
    held = splits.split_scenario(name, split)
    with pytest.raises(ValueError, match="evaluation split"):
        check_not_held_out(held)
    with pytest.raises(ValueError, match="evaluation split"):  # renamed, still the same fleet
        check_not_held_out(held.replace(name="procedural_1", description=""))


def test_force_scale_scales_the_limits_and_leaves_every_other_draw() -> None:
    nominal, weak = ScenarioDistribution(), ScenarioDistribution(force_scale=(0.4, 1.0))
    scales = []
    for seed in range(30):
        plain, drawn = nominal.sample(seed), weak.sample(seed)
        np.testing.assert_array_equal(plain.tau_limits[1], np.tile(NOMINAL_TAU_MAX, (plain.n, 1)))
        scale = drawn.tau_limits[1] / plain.tau_limits[1]
        assert np.allclose(scale, scale[0, 0]) and 0.4 <= scale[0, 0] <= 1.0
        np.testing.assert_array_equal(drawn.tau_limits[0], -drawn.tau_limits[1])
        assert drawn.replace(tau_max=NOMINAL_TAU_MAX) == plain  # the scale is drawn last
        scales.append(scale[0, 0])
    assert np.ptp(scales) > 0.3
    assert nominal.describe(plain)["tau_max"] == list(NOMINAL_TAU_MAX)


def test_bad_distributions_are_refused() -> None:
    with pytest.raises(ValueError, match="sizes"):
        ScenarioDistribution(sizes=(1, 4))
    with pytest.raises(ValueError, match="path_families"):
        ScenarioDistribution(path_families=("spiral",))
    with pytest.raises(ValueError, match="loss"):
        ScenarioDistribution(loss=(0.5, 0.2))
    with pytest.raises(ValueError, match=r"force_scale = \(0.0, 1.0\) must be a range"):
        ScenarioDistribution(force_scale=(0.0, 1.0))
    with pytest.raises(ValueError, match="of two numbers"):
        ScenarioDistribution(v0=(0.1,))  # type: ignore[arg-type]
