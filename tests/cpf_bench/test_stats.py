from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as scipy_stats

from cpf_bench import stats


@pytest.mark.parametrize("size", [1, 2, 3, 4, 5, 7, 10, 13, 40])
def test_iqm_matches_scipy_trim_mean(size):
    values = np.random.default_rng(size).lognormal(size=size)
    assert stats.iqm(values) == pytest.approx(scipy_stats.trim_mean(values, 0.25), rel=1e-12)


def test_iqm_ignores_outliers_along_an_axis():
    values = np.array([[1.0, 2.0, 3.0, 1e9], [-1e9, 5.0, 6.0, 7.0]])
    np.testing.assert_allclose(stats.iqm(values), [2.5, 5.5])


def test_bootstrap_interval_matches_scipy_percentile_bootstrap():
    data = np.random.default_rng(1).normal(3.0, 2.0, size=25)
    low, high = stats.bootstrap_interval([data], replicates=20000)
    reference = scipy_stats.bootstrap(
        (data,),
        np.mean,
        method="percentile",
        n_resamples=20000,
        rng=np.random.default_rng(2),
    ).confidence_interval
    # Two independent 20,000-replicate runs: percentiles agree to a few % of the data's sd.
    assert low == pytest.approx(reference.low, abs=0.05 * data.std())
    assert high == pytest.approx(reference.high, abs=0.05 * data.std())


@pytest.mark.parametrize(
    ("statistic", "truth"),
    [(lambda x: x.mean(axis=-1), 2.0), (stats.iqm, 2.0)],
    ids=["mean", "iqm"],
)
def test_bootstrap_interval_covers_a_known_centre_at_about_its_nominal_rate(statistic, truth):
    """95 % intervals on 400 synthetic samples of 30 (symmetric: mean = IQM = 2)."""
    rng = np.random.default_rng(7)
    trials = 400
    covered = 0
    for trial in range(trials):
        data = rng.normal(truth, 1.0, size=30)
        low, high = stats.bootstrap_interval([data], statistic, replicates=1000, seed=trial)
        covered += low <= truth <= high
    # Percentile intervals under-cover a little at N = 30 (about 93 %); binomial sd 1.1 %.
    assert 0.90 <= covered / trials <= 0.98


def test_stratified_bootstrap_keeps_every_stratum_size():
    """Strata with no spread of their own: every replicate has the same mean."""
    low, high = stats.bootstrap_interval([np.zeros(5), np.ones(15)])
    assert low == high == 0.75
    pooled = stats.bootstrap_interval([np.r_[np.zeros(5), np.ones(15)]])
    assert pooled[0] < 0.75 < pooled[1]


def test_bootstrap_is_reproducible_and_seeded():
    data = np.random.default_rng(3).normal(size=12)
    assert stats.bootstrap_interval([data]) == stats.bootstrap_interval([data])
    assert stats.bootstrap_interval([data], seed=1) != stats.bootstrap_interval([data], seed=2)


def test_bootstrap_of_a_constant_is_a_point():
    assert stats.bootstrap_interval([np.full(4, 2.5)]) == (2.5, 2.5)


@pytest.mark.parametrize(
    ("strata", "confidence"),
    [([], 0.95), ([np.array([])], 0.95), ([np.ones(3)], 1.0), ([np.ones(3)], 0.0)],
)
def test_bootstrap_rejects_bad_input(strata, confidence):
    with pytest.raises(ValueError, match=r"stratum|confidence"):
        stats.bootstrap_interval(strata, confidence=confidence)


def test_probability_of_beating_counts_paired_wins_and_half_ties():
    p, low, high = stats.probability_of_beating([1.0, 2.0, 3.0, 0.0], [2.0, 2.0, 2.0, 1.0])
    assert p == pytest.approx((1 + 0.5 + 0 + 1) / 4)
    assert 0.0 <= low <= p <= high <= 1.0
    p, low, high = stats.probability_of_beating([1.0], [2.0])
    assert (p, high) == (1.0, 1.0) and low < 0.25  # one win of one proves little


@pytest.mark.parametrize("trials", [1, 5, 10, 20, 37])
def test_wilson_interval_matches_scipy_at_every_count(trials):
    scipy_stats = pytest.importorskip("scipy.stats")
    for wins in range(trials + 1):
        expected = scipy_stats.binomtest(wins, trials).proportion_ci(0.95, method="wilson")
        low, high = stats.wilson_interval(wins, trials)
        assert low == pytest.approx(expected.low, abs=1e-12)
        assert high == pytest.approx(expected.high, abs=1e-12)


def test_wilson_interval_at_none_and_all_of_the_seeds():
    # 0/N: (0, z^2 / (N + z^2)); N/N: (N / (N + z^2), 1), written out for z = 1.959964
    z2 = 1.959963984540054**2
    for n in (10, 20):
        assert stats.wilson_interval(0, n) == pytest.approx((0.0, z2 / (n + z2)))
        assert stats.wilson_interval(n, n) == pytest.approx((n / (n + z2), 1.0))
    assert stats.wilson_interval(10, 10)[0] < 0.75  # 10 wins of 10 is not certainty
    p, low, high = stats.probability_of_beating(np.zeros(10), np.ones(10))
    assert p == 1.0 and low == pytest.approx(10 / (10 + z2)) and high == 1.0


def test_wilson_interval_refuses_impossible_counts():
    with pytest.raises(ValueError, match="successes <= trials"):
        stats.wilson_interval(11, 10)
    with pytest.raises(ValueError, match="successes <= trials"):
        stats.wilson_interval(0, 0)


def test_paired_difference_is_the_mean_of_per_seed_differences():
    values, reference = np.array([1.0, 2.0, 4.0, 3.0]), np.array([2.0, 2.5, 3.0, 5.0])
    mean, low, high = stats.paired_difference(values, reference)
    assert mean == pytest.approx((-1.0 - 0.5 + 1.0 - 2.0) / 4)
    assert -2.0 <= low <= mean <= high <= 1.0
    # a constant shift is known exactly: a zero-width interval at the shift
    assert stats.paired_difference(reference - 0.25, reference) == pytest.approx((-0.25,) * 3)


def test_probability_of_beating_needs_pairs():
    with pytest.raises(ValueError, match="same number of seeds"):
        stats.probability_of_beating([1.0, 2.0], [1.0])


# --- share of the gap closed --------------------------------------------------------------


def test_gap_closed_is_the_share_of_the_mean_gap_by_hand():
    reference = np.array([10.0, 12.0, 14.0, 16.0])
    headroom = reference - 4.0
    half_way = reference - 2.0  # closes half of the gap on every seed
    share, low, high = stats.gap_closed(reference, half_way, headroom)
    assert (share, low, high) == pytest.approx((0.5, 0.5, 0.5))
    assert stats.gap_closed(reference, reference + 4.0, headroom)[0] == pytest.approx(-1.0)
    assert stats.gap_closed(reference, headroom, headroom)[0] == pytest.approx(1.0)


def test_gap_closed_interval_matches_a_paired_bootstrap_written_out():
    rng = np.random.default_rng(3)
    reference = rng.normal(100.0, 5.0, size=12)
    headroom = reference - rng.normal(20.0, 2.0, size=12)
    policy = reference - rng.normal(8.0, 4.0, size=12)
    share, low, high = stats.gap_closed(reference, policy, headroom, replicates=4000, seed=9)
    draws = np.random.default_rng(9).integers(0, 12, size=(4000, 12))
    shares = [
        (reference[d].mean() - policy[d].mean()) / (reference[d].mean() - headroom[d].mean())
        for d in draws
    ]
    assert share == pytest.approx(
        (reference.mean() - policy.mean()) / (reference - headroom).mean()
    )
    assert (low, high) == pytest.approx(tuple(np.percentile(shares, [2.5, 97.5])), rel=1e-12)
    assert low < share < high


def test_no_gap_is_reported_when_the_headroom_reference_is_not_better():
    reference = np.array([10.0, 12.0, 14.0, 16.0])
    noisy = reference + np.array([1.0, -1.0, 1.0, -1.0])  # mean gap 0: nothing to close
    assert stats.gap_closed(reference, reference - 1.0, noisy) is None
    assert stats.gap_closed(reference, reference - 1.0, reference + 2.0) is None


@pytest.mark.parametrize("size", [1, 2, 3, 7, 10, 13, 20, 40])
def test_bootstrap_rows_is_each_rows_bootstrap_interval_bit_for_bit(size):
    matrix = np.random.default_rng(size).normal(size=(6, size))
    for statistic in (None, stats.iqm):
        extra = {} if statistic is None else {"statistic": statistic}
        low, high = stats.bootstrap_rows(matrix, **extra)
        for k in range(matrix.shape[0]):
            assert (low[k], high[k]) == stats.bootstrap_interval([matrix[k]], **extra)
