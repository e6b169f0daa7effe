"""Statistics of the benchmark: interquartile means and bootstrap intervals.

The estimators follow Agarwal et al., "Deep RL at the edge of the statistical
precipice" (NeurIPS 2021) and its library rliable, written out here in a few
lines (rliable 1.2 does not import with pandas 3) and tested against scipy:

* ``iqm``: the interquartile mean, the mean of the middle 50 % of the
  values (``scipy.stats.trim_mean(x, 0.25)``); robust to a few outlying
  episodes, yet less noisy than the median.
* ``bootstrap_interval``: a percentile interval from a stratified bootstrap:
  every stratum (a scenario) is resampled with replacement on its own, so
  each scenario keeps its number of episodes in every replicate. The
  generator is seeded, so an interval is the same on every run.
* ``probability_of_beating``: the probability that a policy's episode is
  better (lower) than the reference's on the same seed, ties counting one
  half; paired, since every policy runs the same seeds. Its interval is
  Wilson's score interval (``wilson_interval``), which stays honest at 0/N
  and N/N, where a percentile bootstrap collapses to a point.
* ``paired_difference``: the mean over seeds of (policy - reference) with a
  percentile bootstrap interval that resamples the pairs together.
* ``paired_headroom``: 1 - mean(bound) / mean(best), the room a bound leaves
  below the best deployable design, with a paired bootstrap interval.
* ``gap_closed``: the share of the gap between the reference and a
  headroom reference that a policy closes, (ref - policy) / (ref - headroom)
  of the means, with a paired bootstrap interval (the seeds resampled
  together for all three).

Example:
    >>> import numpy as np
    >>> float(iqm(np.array([0.0, 1.0, 2.0, 3.0, 100.0, 4.0, 5.0, 6.0])))
    3.5
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from statistics import NormalDist

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BOOTSTRAP_SEED",
    "bootstrap_interval",
    "bootstrap_rows",
    "gap_closed",
    "iqm",
    "paired_difference",
    "paired_headroom",
    "probability_of_beating",
    "wilson_interval",
]

#: Seed of every bootstrap (a fixed seed keeps tables reproducible byte for byte).
BOOTSTRAP_SEED = 20140721
#: Bootstrap replicates.
REPLICATES = 2000

Statistic = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def iqm(values: ArrayLike, axis: int = -1) -> NDArray[np.float64]:
    """Interquartile mean along ``axis``: drop the lowest and highest quarter, average the rest.

    Drops ``floor(N / 4)`` values at each end, as ``scipy.stats.trim_mean(x, 0.25)``.

    Args:
        values: Samples, N along ``axis`` (N >= 1).
        axis: The sample axis.

    Returns:
        The IQM, ``values`` with ``axis`` removed.
    """
    array = np.sort(np.asarray(values, dtype=np.float64), axis=axis)
    count = array.shape[axis]
    if count < 1:
        raise ValueError("iqm needs at least one value.")
    cut = count // 4
    return np.take(array, np.arange(cut, count - cut), axis=axis).mean(axis=axis)


def _mean(values: NDArray[np.float64]) -> NDArray[np.float64]:
    return values.mean(axis=-1)


def bootstrap_interval(
    strata: Sequence[ArrayLike],
    statistic: Statistic = _mean,
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile interval of ``statistic`` by stratified bootstrap.

    Args:
        strata: One 1-D array of samples per stratum (e.g. per scenario); each
            is resampled with replacement to its own size, then all are joined.
        statistic: Maps resamples (R, N) to (R,), e.g. ``iqm`` or the mean (default).
        confidence: Coverage of the interval, in (0, 1).
        replicates: Number of bootstrap replicates R.
        seed: Seed of the resampling generator.

    Returns:
        (low, high). A sample without spread gives a zero-width interval.

    Raises:
        ValueError: No strata, an empty stratum, or a confidence outside (0, 1).
    """
    arrays = [np.asarray(stratum, dtype=np.float64).reshape(-1) for stratum in strata]
    if not arrays or any(array.size == 0 for array in arrays):
        raise ValueError("bootstrap_interval needs at least one stratum, none of them empty.")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}.")
    draws = _resample_indices(tuple(array.size for array in arrays), replicates, seed)
    resampled = np.concatenate(
        [array[index] for array, index in zip(arrays, draws, strict=True)], axis=1
    )
    estimates = statistic(resampled)
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(estimates, [tail, 100.0 - tail])
    return float(low), float(high)


def bootstrap_rows(
    samples: ArrayLike,
    statistic: Statistic = _mean,
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``bootstrap_interval([row])`` of every row of ``samples`` (M, N) at once.

    Every row is resampled with the same draws a single stratum of N samples
    gets, so row m's interval is ``bootstrap_interval([samples[m]], ...)``
    bit for bit; one call instead of M (the bench's many metrics of a cell).

    Returns:
        (low, high), each (M,).
    """
    matrix = np.asarray(samples, dtype=np.float64)
    if matrix.ndim != 2 or matrix.shape[1] == 0:
        raise ValueError(f"samples must be (M, N) with N >= 1, got shape {matrix.shape}.")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}.")
    (draw,) = _resample_indices((matrix.shape[1],), replicates, seed)
    rows, size = matrix.shape
    # (M R, N): the layout a single stratum's (R, N) resample has, so numpy reduces
    # every replicate in the same order (a 3-D array may be reduced in another)
    resampled = matrix[:, draw].reshape(rows * replicates, size)
    estimates = statistic(resampled).reshape(rows, replicates)
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(estimates, [tail, 100.0 - tail], axis=1)
    return low, high


@functools.lru_cache(maxsize=64)
def _resample_indices(
    sizes: tuple[int, ...], replicates: int, seed: int
) -> tuple[NDArray[np.int64], ...]:
    """The bootstrap's draws: per stratum of N_s samples, (replicates, N_s) indices.

    One seeded generator draws the strata in order; the draws depend only on
    the sizes, so they are made once and shared by every metric and cell of a
    run (read-only arrays), the same numbers as drawing them each time.
    """
    rng = np.random.default_rng(seed)
    draws = tuple(rng.integers(0, size, size=(replicates, size)) for size in sizes)
    for draw in draws:
        draw.flags.writeable = False
    return draws


def wilson_interval(successes: float, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson's score interval for a binomial proportion.

    With p = successes / N and z the standard normal quantile of (1 + confidence) / 2,

        centre = (p + z^2 / 2N) / (1 + z^2 / N)
        half   = z / (1 + z^2 / N) * sqrt(p (1 - p) / N + z^2 / 4N^2)

    At 10 successes of 10 the 95 % interval is [0.722, 1].

    Args:
        successes: Number of successes, 0 <= successes <= trials (a tie may count 1/2).
        trials: N >= 1.
        confidence: Coverage, in (0, 1).

    Returns:
        (low, high), within [0, 1].

    Raises:
        ValueError: No trials, successes outside [0, N], or a confidence outside (0, 1).
    """
    if trials < 1 or not 0.0 <= successes <= trials:
        raise ValueError(f"need 0 <= successes <= trials, trials >= 1; got {successes}/{trials}.")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}.")
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    p, n = successes / trials, float(trials)
    scale = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / scale
    half = z / scale * np.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n))
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def _paired(values: ArrayLike, reference: ArrayLike) -> tuple[NDArray, NDArray]:
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    y = np.asarray(reference, dtype=np.float64).reshape(-1)
    if x.shape != y.shape or x.size == 0:
        raise ValueError(f"paired values need the same number of seeds, got {x.size} and {y.size}.")
    return x, y


def paired_difference(
    values: ArrayLike,
    reference: ArrayLike,
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float, float]:
    """Mean of the per-seed differences ``values - reference``, with a bootstrap interval.

    Args:
        values: One value per seed, shape (N,).
        reference: The reference policy's values on the same N seeds.
        confidence: Coverage of the interval.
        replicates: Bootstrap replicates (the differences are resampled).
        seed: Seed of the resampling generator.

    Returns:
        (mean difference, low, high); one seed gives a zero-width interval.

    Raises:
        ValueError: Arrays of different shapes or empty.
    """
    x, y = _paired(values, reference)
    difference = x - y
    low, high = bootstrap_interval(
        [difference], confidence=confidence, replicates=replicates, seed=seed
    )
    return float(difference.mean()), low, high


def probability_of_beating(
    values: ArrayLike, reference: ArrayLike, confidence: float = 0.95
) -> tuple[float, float, float]:
    """Probability that ``values`` is lower than ``reference`` on a paired episode.

    Args:
        values: One value per seed, shape (N,) (lower is better).
        reference: The reference policy's values on the same N seeds.
        confidence: Coverage of the Wilson interval.

    Returns:
        (probability, low, high); a tie counts one half.

    Raises:
        ValueError: Arrays of different shapes or empty.
    """
    x, y = _paired(values, reference)
    wins = (x < y) + 0.5 * (x == y)
    low, high = wilson_interval(float(wins.sum()), int(wins.size), confidence)
    return float(wins.mean()), low, high


def gap_closed(
    reference: ArrayLike,
    values: ArrayLike,
    headroom: ArrayLike,
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float, float] | None:
    """Share of the reference-to-headroom gap a policy closes, with a paired bootstrap interval.

    share = (mean(reference) - mean(values)) / (mean(reference) - mean(headroom)),
    lower is better: 0 = the reference's level, 1 = the headroom reference's,
    below 0 worse than the reference, above 1 better than the headroom. Each
    bootstrap replicate resamples the N seeds once and applies the draw to
    all three arrays (they ran the same seeds).

    Args:
        reference: The reference policy's values per seed (N,).
        values: The policy's values on the same seeds (N,).
        headroom: The headroom reference's values on the same seeds (N,).
        confidence: Coverage of the interval.
        replicates: Bootstrap replicates.
        seed: Seed of the resampling generator.

    Returns:
        (share, low, high), or None when the headroom reference is not better
        than the reference with this confidence (the lower end of the paired
        interval of reference - headroom is not above zero): then there is no
        gap to close and the ratio would only measure noise.

    Raises:
        ValueError: Arrays of different shapes or empty.
    """
    x, y = _paired(values, reference)
    h, _ = _paired(headroom, reference)
    gap, gap_low, _ = paired_difference(y, h, confidence, replicates, seed)
    if not gap_low > 0.0:
        return None
    low, high = _paired_interval(
        lambda ref, value, top: (ref - value) / (ref - top), (y, x, h), confidence, replicates, seed
    )
    return float((y.mean() - x.mean()) / gap), low, high


def paired_headroom(
    best: ArrayLike,
    bound: ArrayLike,
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float, float]:
    """The room 1 - mean(bound) / mean(best), with a paired bootstrap interval.

    Each replicate resamples the N seeds once for both arrays (they ran the
    same seeds), so the interval carries the seed-to-seed correlation of the
    two costs.

    Args:
        best: The best deployable design's cost per seed (N,).
        bound: The headroom bound's cost on the same seeds (N,).
        confidence: Coverage of the interval.
        replicates: Bootstrap replicates.
        seed: Seed of the resampling generator.

    Returns:
        (room, low, high); one seed gives a zero-width interval.

    Raises:
        ValueError: Arrays of different shapes or empty.

    Example:
        >>> paired_headroom([10.0, 20.0], [5.0, 10.0])
        (0.5, 0.5, 0.5)
    """
    x, y = _paired(bound, best)
    low, high = _paired_interval(
        lambda top, ref: 1.0 - top / ref, (x, y), confidence, replicates, seed
    )
    return float(1.0 - x.mean() / y.mean()), low, high


def _paired_interval(
    statistic: Callable[..., NDArray[np.float64]],
    arrays: Sequence[NDArray[np.float64]],
    confidence: float,
    replicates: int,
    seed: int,
) -> tuple[float, float]:
    """Percentile interval of ``statistic`` of the arrays' means, the seeds resampled together.

    Each replicate draws the N seeds once and applies the draw to every array
    (they ran the same seeds); ``statistic`` maps their (R,) means to (R,).
    """
    (draw,) = _resample_indices((arrays[0].size,), replicates, seed)
    estimates = statistic(*(array[draw].mean(axis=1) for array in arrays))
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(estimates, [tail, 100.0 - tail])
    return float(low), float(high)
