"""The multi-metric verdict: did a policy beat the reference on a scenario?

A lower cost alone can hide a controller that buys its reward with a
physical regression (a steady heading offset, a larger cross-track error, a
slower fleet). The verdict therefore reads the paired cost difference and a
declared set of physical metrics (``GUARDED``), all on the same seeds:

* ``equivalent``: the 95 % interval of the mean paired cost difference
  (policy - reference) lies inside the practical-equivalence margin
  +-``COST_MARGIN`` x the reference's mean cost (default 1 %): whatever its
  sign, the difference is too small to matter (``equivalent (worse: ...)``
  if a guarded metric regressed);
* ``beats``: otherwise, the cost interval lies below zero and no guarded
  metric regressed;
* ``mixed (worse: ...)``: the cost interval lies below zero but a guarded
  metric regressed (named);
* ``loses``: the cost interval lies above zero;
* ``no difference``: the cost interval contains zero and reaches beyond the
  margin: not resolved by these seeds (``no difference (worse: ...)`` if a
  guarded metric regressed).

Where no hull of the fleet has a sway actuator (the scenarios whose course
is measured, ``cpf_env.evaluation.fleet_metrics``) no direction is guarded:
such a hull steers its position with its heading, holding the path in a
cross current only with its bow turned into the drift and converging to it
only on a course off the tangent, so neither offset is a regression in
itself; what it buys is judged by the cross-track, formation and progress
guards.

A guarded metric is read as its distance from a target where it has one
(progress from 1: a fleet ahead of its schedule is as far off it as one
behind), else as is (lower is better). It regressed when the mean paired
difference of that distance exceeds ``max(RELATIVE_TOLERANCE x |reference
mean|, floor)`` and the lower end of its 95 % bootstrap interval is above
zero (a real, not a noisy, regression). The floors ignore differences
below what matters physically on a 1.255 m model ship (1 mm, 1 mrad, 1 %
of the distance v0 T, any extra failure).

A mean can hide one bad episode among many good ones (a vessel that ends
one episode in ten a metre off its place). ``worst_episode_regressed``
reads the worst episode of each guarded metric instead, with the same
tolerance and floor against the reference's worst episode; it does not
change the label, and ``cpf-bench`` prints it next to the regressions
(``views.regression_lines``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpf_bench import stats
from cpf_bench.report import CellResult

__all__ = [
    "COST_MARGIN",
    "GUARDED",
    "RELATIVE_TOLERANCE",
    "Verdict",
    "check_margin",
    "guarded",
    "off_target",
    "suite_cost_difference",
    "verdict",
    "verdicts",
    "worst_episode",
    "worst_episode_regressed",
]

#: Relative tolerance of a guarded metric, as a fraction of the reference's mean.
RELATIVE_TOLERANCE = 0.10
#: Practical-equivalence margin of the cost, a fraction of the reference's mean cost.
COST_MARGIN = 0.01
#: Guarded physical metrics: name -> (short label, absolute floor, target). A metric with a
#: target is read as its distance from it; one without (None) is read as is, lower better.
GUARDED: dict[str, tuple[str, float, float | None]] = {
    "cross_track_error_rms_window": ("cross-track", 1e-3, None),
    "heading_error_rms_window": ("heading", 1e-3, None),
    "formation_error_rms_window": ("formation", 1e-3, None),
    "progress_window": ("progress", 0.01, 1.0),
    "terminated": ("failures", 0.0, None),
}


@dataclass(frozen=True)
class Verdict:
    """One policy against the reference on one scenario.

    Attributes:
        policy: The policy's label.
        scenario: Scenario name.
        reference: The reference policy's label.
        episodes: Paired episodes N.
        cost_difference: (mean, low, high) of the paired cost difference.
        p_beats: (probability, low, high) of a lower cost on a seed (Wilson interval).
        regressed: Short labels of the guarded metrics that regressed.
        margin: The cost's practical-equivalence margin, in cost units (>= 0).
        label: ``equivalent``, ``beats``, ``mixed (worse: ...)``, ``loses`` or
            ``no difference`` (the last two and ``equivalent`` with ``(worse: ...)``
            when a guarded metric regressed).
    """

    policy: str
    scenario: str
    reference: str
    episodes: int
    cost_difference: tuple[float, float, float]
    p_beats: tuple[float, float, float]
    regressed: tuple[str, ...]
    margin: float
    label: str


def off_target(metric: str, values: np.ndarray) -> np.ndarray:
    """How bad each value of a guarded metric is: its distance from the target, if any.

    Example:
        >>> off_target("progress_window", np.array([0.9, 1.0, 1.2])).round(2).tolist()
        [0.1, 0.0, 0.2]
    """
    target = GUARDED[metric][2]
    return values if target is None else np.abs(values - target)


def guarded(base: CellResult) -> list[str]:
    """The ``GUARDED`` metrics that apply on the reference cell's scenario (module docstring).

    All of them, but the heading where no hull has a sway actuator (where the
    course is measured).
    """
    swayless = not np.isnan(base.metrics["course_error_rms_window"]).all()
    return [m for m in GUARDED if not (swayless and m == "heading_error_rms_window")]


def _regressed(cell: CellResult, base: CellResult) -> tuple[str, ...]:
    """The guarded metrics on which ``cell`` is worse than ``base`` beyond tolerance."""
    worse = []
    for metric in guarded(base):
        label, floor, _ = GUARDED[metric]
        mean, low, _ = stats.paired_difference(
            off_target(metric, cell.metrics[metric]), off_target(metric, base.metrics[metric])
        )
        tolerance = max(RELATIVE_TOLERANCE * abs(float(base.metrics[metric].mean())), floor)
        if mean > tolerance and low > 0.0:
            worse.append(label)
    return tuple(worse)


def worst_episode(metric: str, values: np.ndarray) -> float:
    """A guarded metric's worst episode value: the one furthest off target (``off_target``)."""
    return float(values[np.argmax(off_target(metric, values))])


def worst_episode_regressed(cell: CellResult, base: CellResult) -> tuple[str, ...]:
    """The guarded metrics whose worst episode in ``cell`` is worse than ``base``'s worst.

    Further off target (``worst_episode``, ``off_target``) by more than
    ``max(RELATIVE_TOLERANCE x |base's worst|, floor)``. Not part of the verdict's label.
    """
    worse = []
    for metric in guarded(base):
        label, floor, _ = GUARDED[metric]
        own, reference = (worst_episode(metric, c.metrics[metric]) for c in (cell, base))
        excess = float(off_target(metric, np.array(own)) - off_target(metric, np.array(reference)))
        if excess > max(RELATIVE_TOLERANCE * abs(reference), floor):
            worse.append(label)
    return tuple(worse)


def verdict(cell: CellResult, base: CellResult, margin: float = COST_MARGIN) -> Verdict:
    """The verdict of ``cell`` against the reference's ``base`` (same scenario and seeds).

    Args:
        cell: The policy's episodes.
        base: The reference's episodes on the same scenario and seeds.
        margin: Practical-equivalence margin of the cost, a fraction (>= 0) of
            the reference's mean cost; 0 turns it off.

    Raises:
        ValueError: The cells ran different scenarios or seeds, or a negative margin.
    """
    if cell.scenario != base.scenario or cell.seeds != base.seeds:
        raise ValueError(
            f"{cell.policy} and {base.policy} must run the same scenario and seeds to be compared."
        )
    check_margin(margin)
    cost = stats.paired_difference(cell.metrics["cost"], base.metrics["cost"])
    p_beats = stats.probability_of_beating(cell.metrics["cost"], base.metrics["cost"])
    regressed = _regressed(cell, base)
    worse = f" (worse: {', '.join(regressed)})" if regressed else ""
    band = margin * abs(float(base.metrics["cost"].mean()))
    if -band < cost[1] and cost[2] < band:
        label = "equivalent" + worse
    elif cost[2] < 0.0:
        label = "mixed" + worse if regressed else "beats"
    elif cost[1] > 0.0:
        label = "loses"
    else:
        label = "no difference" + worse
    return Verdict(
        cell.policy,
        cell.scenario,
        base.policy,
        len(cell.seeds),
        cost,
        p_beats,
        regressed,
        band,
        label,
    )


def check_margin(margin: float) -> None:
    """Raise ValueError unless ``margin`` is a finite fraction >= 0."""
    if not (np.isfinite(margin) and margin >= 0.0):
        raise ValueError(
            "the cost margin (--cost-margin) must be a fraction >= 0 of the reference's mean "
            f"cost (0.01 = 1 %), got {margin}."
        )


def verdicts(
    cells: Sequence[CellResult], reference: str, margin: float = COST_MARGIN
) -> list[Verdict]:
    """Every non-reference cell's verdict where the reference ran the same scenario."""
    bases = {cell.scenario: cell for cell in cells if cell.policy == reference}
    return [
        verdict(cell, bases[cell.scenario], margin)
        for cell in cells
        if cell.policy != reference and cell.scenario in bases
    ]


def suite_cost_difference(
    cells: Sequence[CellResult], policy: str, reference: str
) -> tuple[float, float, float] | None:
    """Suite-wide relative cost difference (policy / reference - 1), stratified by scenario.

    Every episode's cost is divided by the reference's mean cost on its
    scenario; the mean of (normalized - 1) over all episodes has a bootstrap
    interval that resamples each scenario on its own. None if the policy or
    the reference misses a scenario.
    """
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    by_key = {(cell.policy, cell.scenario): cell for cell in cells}
    if any((p, n) not in by_key for p in (policy, reference) for n in names):
        return None
    strata = []
    for name in names:
        scale = float(by_key[(reference, name)].metrics["cost"].mean())
        strata.append(by_key[(policy, name)].metrics["cost"] / scale - 1.0)
    low, high = stats.bootstrap_interval(strata)
    return float(np.concatenate(strata).mean()), low, high
