"""Suite-wide views in the style of rliable: performance profiles and probability of improvement.

Agarwal et al., "Deep RL at the edge of the statistical precipice" (NeurIPS
2021), section 4, on the benchmark's episodes. The score of an episode is
its scenario's normalized cost, higher is better:

    score = (the reference's mean cost on the scenario) / (the episode's cost),

1 at the reference's level, 2 at half its cost. Every estimator weighs the
scenarios equally and its 95 % interval comes from a stratified percentile
bootstrap (each scenario's episodes resampled on their own, 2,000
replicates, fixed seed: ``stats``).

* ``performance_profile``: for each threshold tau, the fraction of
  episodes with a score above tau (the mean over scenarios of each
  scenario's fraction); a curve above another is better at every level.
* ``probability_of_improvement``: P(X > Y), the probability that an episode
  of policy X scores higher than an episode of policy Y on the same
  scenario, ties one half (the Mann-Whitney U statistic over m n, averaged
  over scenarios); the bootstrap resamples both policies' episodes. Unlike
  ``P(beats)`` in the tables it does not pair the seeds.

rliable itself (1.2) imports only with pandas < 3; these few lines are
tested against scipy and, where it is installed (the ``rliable`` extra),
against rliable (``tests/cpf_commands/bench/test_profiles.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from numpy.typing import ArrayLike, NDArray

from cpf_bench.report import CellResult
from cpf_bench.stats import BOOTSTRAP_SEED, REPLICATES
from cpf_commands.bench.views import figure_label

__all__ = [
    "improvement_figure",
    "normalized_scores",
    "performance_profile",
    "probability_of_improvement",
    "profile_figure",
]

Array = NDArray[np.float64]


def normalized_scores(
    cells: Sequence[CellResult], reference: str, metric: str = "cost"
) -> dict[str, list[Array]]:
    """Per policy that ran every scenario, one score array per scenario (higher is better).

    Scores are the reference's mean ``metric`` on the scenario over each
    episode's value. Empty if the reference misses a scenario.
    """
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    by_key = {(cell.policy, cell.scenario): cell for cell in cells}
    if any((reference, name) not in by_key for name in names):
        return {}
    scales = {name: float(by_key[(reference, name)].metrics[metric].mean()) for name in names}
    scores: dict[str, list[Array]] = {}
    for policy in dict.fromkeys(cell.policy for cell in cells):
        if all((policy, name) in by_key for name in names):
            scores[policy] = [scales[n] / by_key[(policy, n)].metrics[metric] for n in names]
    return scores


def _strata(values: Sequence[ArrayLike]) -> list[Array]:
    arrays = [np.asarray(v, dtype=np.float64).reshape(-1) for v in values]
    if not arrays or any(a.size == 0 for a in arrays):
        raise ValueError("need at least one scenario, each with at least one episode.")
    return arrays


def _interval(estimates: Array, confidence: float) -> tuple[Array, Array]:
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(estimates, [tail, 100.0 - tail], axis=0)
    return low, high


def performance_profile(
    scores: Sequence[ArrayLike],
    taus: ArrayLike,
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[Array, Array, Array]:
    """Fraction of episodes with a score above each tau, and its stratified-bootstrap interval.

    Args:
        scores: One array of episode scores per scenario.
        taus: Thresholds, shape (T,).
        confidence: Coverage of the interval.
        replicates: Bootstrap replicates.
        seed: Seed of the resampling generator.

    Returns:
        (fraction, low, high), each (T,): the mean over scenarios of the
        fraction of that scenario's episodes scoring above tau.
    """
    strata, thresholds = _strata(scores), np.asarray(taus, dtype=np.float64)

    def profile(samples: list[Array]) -> Array:  # samples: (R, N_s) per scenario
        return np.mean([(s[..., None] > thresholds).mean(axis=-2) for s in samples], axis=0)

    rng = np.random.default_rng(seed)
    resampled = [s[rng.integers(0, s.size, size=(replicates, s.size))] for s in strata]
    low, high = _interval(profile(resampled), confidence)
    return profile([s[None, :] for s in strata])[0], low, high


def _improvement(x: list[Array], y: list[Array]) -> Array:
    """P(X > Y) averaged over scenarios; x, y: (R, m) and (R, n) per scenario."""
    per_task = [
        ((a[..., :, None] > b[..., None, :]) + 0.5 * (a[..., :, None] == b[..., None, :])).mean(
            axis=(-2, -1)
        )
        for a, b in zip(x, y, strict=True)
    ]
    return np.mean(per_task, axis=0)


def probability_of_improvement(
    x: Sequence[ArrayLike],
    y: Sequence[ArrayLike],
    confidence: float = 0.95,
    replicates: int = REPLICATES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float, float]:
    """P(X > Y) over scenarios with a stratified-bootstrap interval (both samples resampled).

    Args:
        x: Policy X's episode scores, one array per scenario (higher is better).
        y: Policy Y's, the same scenarios in the same order.
        confidence: Coverage of the interval.
        replicates: Bootstrap replicates.
        seed: Seed of the resampling generator.

    Returns:
        (probability, low, high).

    Raises:
        ValueError: Different numbers of scenarios, or an empty one.
    """
    xs, ys = _strata(x), _strata(y)
    if len(xs) != len(ys):
        raise ValueError(f"x and y need the same scenarios, got {len(xs)} and {len(ys)}.")
    rng = np.random.default_rng(seed)
    bx, by = [], []
    for a, b in zip(xs, ys, strict=True):
        bx.append(a[rng.integers(0, a.size, size=(replicates, a.size))])
        by.append(b[rng.integers(0, b.size, size=(replicates, b.size))])
    low, high = _interval(_improvement(bx, by), confidence)
    return float(_improvement(xs, ys)), float(low), float(high)


#: Minor ticks of the log axis that get a label.
_MINOR = (0.5, 2.0, 3.0, 5.0)


def profile_figure(scores: dict[str, list[Array]], reference: str) -> Figure:
    """Performance profiles of the normalized cost score, one curve per policy with its band."""
    everything = np.concatenate([np.concatenate(v) for v in scores.values()])
    low, high = max(float(everything.min()), 1e-3), float(everything.max())
    taus = np.geomspace(low * 0.9, high * 1.1, 400)
    fig = Figure(figsize=(8.0, 4.8), layout="constrained")
    ax = fig.subplots()
    for k, (policy, values) in enumerate(scores.items()):
        fraction, band_low, band_high = performance_profile(values, taus)
        style = "--" if policy == reference else "-"
        color = f"C{k % 10}"
        ax.plot(taus, fraction, style, color=color, label=figure_label(policy))
        ax.fill_between(taus, band_low, band_high, color=color, alpha=0.15, linewidth=0)
    ax.axvline(1.0, color="black", linewidth=0.8)
    wide = high / low > 10.0  # a log axis only where the scores span a decade
    if wide:
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda x, _: f"{x:g}" if x in _MINOR else ""))
    ax.set_ylim(-0.02, 1.02)
    ax.grid(which="both", alpha=0.3)
    ax.set_xlabel(
        f"normalized score tau = {reference}'s mean cost / episode cost"
        f"{' (log)' if wide else ''}; > 1 is better",
        fontsize=8,
    )
    ax.set_ylabel("fraction of episodes with score > tau", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="upper right")  # the curves fall to 0 on the right
    fig.suptitle(
        "Performance profiles over the scenarios (each weighted equally),\n"
        "95 % stratified bootstrap bands",
        fontsize=10,
    )
    return fig


def improvement_figure(scores: dict[str, list[Array]], reference: str) -> Figure:
    """P(policy > reference) per policy, with its 95 % stratified-bootstrap interval."""
    others = [p for p in scores if p != reference]
    fig = Figure(figsize=(8.0, 1.4 + 0.35 * max(1, len(others))), layout="constrained")
    ax = fig.subplots()
    for row, policy in enumerate(others):
        p, low, high = probability_of_improvement(scores[policy], scores[reference])
        ax.errorbar(p, row, xerr=[[p - low], [high - p]], fmt="o", color="C0", capsize=3)
        ax.annotate(f"{p:.2f}", (high, row), xytext=(4, 0), textcoords="offset points",
                    fontsize=7, va="center")  # fmt: skip
    ax.axvline(0.5, color="black", linewidth=0.8)
    ax.set_xlim(0.0, 1.05)
    ax.set_yticks(range(len(others)), [figure_label(p) for p in others], fontsize=8)
    ax.set_ylim(len(others) - 0.5, -0.5)
    ax.grid(axis="x", alpha=0.3)
    ax.set_xlabel(
        f"P(an episode of the policy has a lower cost than one of {reference}), "
        "averaged over scenarios",
        fontsize=8,
    )
    ax.tick_params(axis="x", labelsize=7)
    fig.suptitle(
        f"Probability of improvement over {reference}, 95 % stratified bootstrap interval",
        fontsize=10,
    )
    return fig
