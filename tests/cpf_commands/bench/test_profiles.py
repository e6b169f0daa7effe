"""Performance profiles and probability of improvement: by hand, against scipy and rliable."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as scipy_stats

from cpf_bench.report import CellResult
from cpf_commands.bench.profiles import (
    normalized_scores,
    performance_profile,
    probability_of_improvement,
)


def _scores(seed: int, tasks: int = 3, runs: int = 8, shift: float = 0.0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.lognormal(shift + 0.1 * k, 0.3, size=runs) for k in range(tasks)]


def test_performance_profile_by_hand_weighs_every_scenario_equally():
    scores = [np.array([0.5, 1.5]), np.array([2.0, 3.0, 4.0, 0.1])]
    fraction, low, high = performance_profile(scores, [0.0, 1.0, 2.5, 10.0])
    np.testing.assert_allclose(fraction, [1.0, (0.5 + 0.75) / 2, (0.0 + 0.5) / 2, 0.0])
    assert np.all(low <= fraction + 1e-12) and np.all(fraction <= high + 1e-12)
    assert low[0] == high[0] == 1.0 and low[-1] == high[-1] == 0.0


def test_probability_of_improvement_matches_scipy_mann_whitney_per_scenario():
    x, y = _scores(1, shift=0.2), _scores(2)
    x[0][:3] = y[0][:3]  # ties count one half
    expected = np.mean(
        [
            scipy_stats.mannwhitneyu(a, b).statistic / (a.size * b.size)
            for a, b in zip(x, y, strict=True)
        ]
    )
    p, low, high = probability_of_improvement(x, y)
    assert p == pytest.approx(expected, rel=1e-12)
    assert low < p < high


def test_probability_of_improvement_is_certain_only_when_every_pair_says_so():
    low_scores, high_scores = _scores(3), [s + 100.0 for s in _scores(4)]
    assert probability_of_improvement(high_scores, low_scores) == (1.0, 1.0, 1.0)
    assert probability_of_improvement(low_scores, high_scores) == (0.0, 0.0, 0.0)
    same = _scores(5)
    assert probability_of_improvement(same, same)[0] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="same scenarios"):
        probability_of_improvement(same, same[:2])


def test_normalized_scores_divide_the_reference_mean_by_each_episode():
    def cell(policy, scenario, cost):
        return CellResult(policy, scenario, (0, 1), False, {"cost": np.array(cost)})

    cells = [
        cell("ref", "a", [10.0, 30.0]),
        cell("p", "a", [10.0, 40.0]),
        cell("ref", "b", [4.0, 4.0]),
        cell("p", "b", [2.0, 8.0]),
        cell("q", "a", [1.0, 1.0]),  # missing scenario b: left out
    ]
    scores = normalized_scores(cells, "ref")
    assert list(scores) == ["ref", "p"]
    np.testing.assert_allclose(scores["p"][0], [2.0, 0.5])
    np.testing.assert_allclose(scores["p"][1], [2.0, 0.5])


def test_the_estimators_agree_with_rliable():
    rliable_metrics = pytest.importorskip("rliable.metrics")
    library = pytest.importorskip("rliable.library")
    x, y = _scores(6, shift=0.1), _scores(7)
    x_matrix, y_matrix = np.stack(x, axis=1), np.stack(y, axis=1)  # (runs, tasks)
    expected = rliable_metrics.probability_of_improvement(x_matrix, y_matrix)
    assert probability_of_improvement(x, y)[0] == pytest.approx(expected, rel=1e-12)
    taus = np.linspace(0.5, 2.5, 9)
    profiles, _ = library.create_performance_profile({"x": x_matrix}, taus, reps=50)
    np.testing.assert_allclose(performance_profile(x, taus)[0], profiles["x"], rtol=1e-12)
