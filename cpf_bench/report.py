"""Statistics tables of a benchmark run: summary rows and the CSV files.

``summarize`` turns per-episode results into one row per policy x scenario x
metric (mean and IQM with 95 % bootstrap intervals, failures, the ratio to
the reference policy's mean, the mean paired difference to it with its
bootstrap interval, and the probability of beating it on a paired episode
with Wilson's interval; for the cost, the share of the gap between the
reference and the headroom reference that the policy closes), plus, when the
reference ran, rows over all scenarios together
(scenario ``"all"``, metric ``<metric>_normalized``): every episode divided
by the reference's mean on its scenario, resampled by a bootstrap stratified
by scenario. Numbers are written with ``repr`` (shortest round-trip form) and
the files carry no time stamps or paths, so the same arguments give the same
bytes.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from baselines import HEADROOM_REFERENCE
from cpf_bench import stats
from cpf_bench.episodes import METRICS
from cpf_env.evaluation.fleet_metrics import COURSE_UNMEASURED, UNSEPARATED
from cpf_env.scenarios import splits

__all__ = [
    "GAP_METRICS",
    "HEADLINE",
    "SUMMARY_COLUMNS",
    "CellResult",
    "episodes_csv",
    "normalized_score",
    "read_episodes_csv",
    "summarize",
    "summary_csv",
]

#: Metrics shown in summary.md and drawn as figures: (metric, heading), cost first.
HEADLINE: tuple[tuple[str, str], ...] = (
    ("cost", "cost"),
    ("cost_window", "cost, final window"),
    ("cross_track_error_rms_window", "cross-track error RMS, final window (m)"),
    ("along_track_error_rms_window", "along-track error RMS, final window (m)"),
    ("heading_error_rms_window", "heading error RMS, final window (rad)"),
    ("formation_error_rms_window", "formation error RMS, final window (m)"),
    ("theta_spread_end", "path-variable spread at the end"),
    ("progress", "progress (distance made good / v0 T)"),
    ("control_energy", "control energy (s)"),
    ("saturated_fraction", "saturated fraction"),
)
#: Metrics where higher is better (for all others lower is).
HIGHER_IS_BETTER = frozenset(
    {"return", "return_window", "steps", "progress", "progress_window"}
    | {"speed_along_path", "speed_along_path_window"}
)

SUMMARY_COLUMNS = (
    "policy",
    "scenario",
    "metric",
    "mean",
    "ci_low",
    "ci_high",
    "iqm",
    "iqm_ci_low",
    "iqm_ci_high",
    "n_episodes",
    "failures",
    "deterministic",
    "normalized",
    "diff_reference",
    "diff_ci_low",
    "diff_ci_high",
    "p_beats_reference",
    "p_ci_low",
    "p_ci_high",
    "gap_closed",
    "gap_ci_low",
    "gap_ci_high",
    "suite_version",
)
#: Metrics with a share of the gap closed (lower is better for both).
GAP_METRICS = ("cost", "cost_window")


@dataclass(frozen=True)
class CellResult:
    """The episodes of one policy on one scenario.

    Attributes:
        policy: Policy label.
        scenario: Scenario name.
        seeds: Reset seeds, one per episode (S,).
        deterministic: Whether the scenario gives the same episode for every seed
            (then S = 1).
        metrics: Metric name -> values per episode, shape (S,).
    """

    policy: str
    scenario: str
    seeds: tuple[int, ...]
    deterministic: bool
    metrics: dict[str, NDArray[np.float64]]


def _signed(metric: str, values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Values oriented so that lower is better."""
    return -values if metric in HIGHER_IS_BETTER else values


def _row(
    policy: str,
    scenario: str,
    metric: str,
    strata: list[NDArray[np.float64]],
    failures: int,
    deterministic: bool,
    intervals: tuple[float, float, float, float] | None = None,
) -> dict[str, object]:
    """A summary row; ``intervals`` (mean low, high, IQM low, high) if already bootstrapped."""
    values = np.concatenate(strata)
    if intervals is None:
        low, high = stats.bootstrap_interval(strata)
        iqm_low, iqm_high = stats.bootstrap_interval(strata, stats.iqm)
    else:
        low, high, iqm_low, iqm_high = intervals
    return {
        "policy": policy,
        "scenario": scenario,
        "metric": metric,
        "mean": float(values.mean()),
        "ci_low": low,
        "ci_high": high,
        "iqm": float(stats.iqm(values)),
        "iqm_ci_low": iqm_low,
        "iqm_ci_high": iqm_high,
        "n_episodes": int(values.size),
        "failures": failures,
        "deterministic": deterministic,
        "normalized": None,
        "diff_reference": None,
        "diff_ci_low": None,
        "diff_ci_high": None,
        "p_beats_reference": None,
        "p_ci_low": None,
        "p_ci_high": None,
        "gap_closed": None,
        "gap_ci_low": None,
        "gap_ci_high": None,
    }


def _compare(
    row: dict[str, object],
    values: NDArray,
    reference: NDArray,
    metric: str,
    difference: tuple[float, float] | None,
) -> None:
    """Fill the reference columns of ``row``.

    With ``difference``, the bootstrap interval (low, high) of the paired
    difference, also the paired difference and P(beats).
    """
    reference_mean = float(reference.mean())
    if reference_mean != 0.0:
        row["normalized"] = float(values.mean()) / reference_mean
    if difference is None:
        return
    diff = float((values - reference).mean())
    row.update(diff_reference=diff, diff_ci_low=difference[0], diff_ci_high=difference[1])
    p, low, high = stats.probability_of_beating(_signed(metric, values), _signed(metric, reference))
    row.update(p_beats_reference=p, p_ci_low=low, p_ci_high=high)


def _wins(values: NDArray, reference: NDArray, metric: str) -> NDArray[np.float64]:
    """1 where ``values`` beats ``reference`` on the same seed, 1/2 on a tie, else 0."""
    x, y = _signed(metric, values), _signed(metric, reference)
    return (x < y) + 0.5 * (x == y)


def _scaled(group: Sequence[CellResult], metric: str, means: Sequence[float]) -> NDArray:
    """One policy's episodes on every scenario, each divided by the reference's mean there."""
    return np.concatenate([c.metrics[metric] / m for c, m in zip(group, means, strict=True)])


def _suite_rows(
    cells: Sequence[CellResult],
    reference: str,
    headroom: str,
    by_key: dict[tuple[str, str], CellResult],
) -> list[dict[str, object]]:
    """Rows over all scenarios: episodes normalized by the reference's mean on their scenario.

    The gap columns of a ``GAP_METRICS`` row hold the suite-wide normalized
    score: ``stats.gap_closed`` of the normalized episodes of the reference,
    the policy and the ``headroom`` reference, i.e. (1 - r) / (1 - r_headroom)
    with r the policy's suite-wide mean ratio to the reference.
    """
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    if any((reference, name) not in by_key for name in names):
        return []
    references = [by_key[(reference, name)] for name in names]
    tops = [by_key[(headroom, name)] for name in names if (headroom, name) in by_key]
    rows = []
    for policy in dict.fromkeys(cell.policy for cell in cells):
        if any((policy, name) not in by_key for name in names):
            continue  # not run on every scenario: no suite-wide row
        own = [by_key[(policy, name)] for name in names]
        failures = sum(int(cell.metrics["terminated"].sum()) for cell in own)
        for metric, _ in HEADLINE:
            means = [float(base.metrics[metric].mean()) for base in references]
            if 0.0 in means:
                continue
            strata = [c.metrics[metric] / m for c, m in zip(own, means, strict=True)]
            row = _row(policy, "all", f"{metric}_normalized", strata, failures, False)
            row["normalized"] = row["mean"]
            if policy != reference:
                wins = [
                    _wins(c.metrics[metric], base.metrics[metric], metric)
                    for c, base in zip(own, references, strict=True)
                ]
                pooled = np.concatenate(wins)
                low, high = stats.wilson_interval(float(pooled.sum()), int(pooled.size))
                p = float(pooled.mean())
                row.update(p_beats_reference=p, p_ci_low=low, p_ci_high=high)
            scored = policy not in (reference, headroom) and len(tops) == len(names)
            if metric in GAP_METRICS and scored:
                found = stats.gap_closed(
                    _scaled(references, metric, means),
                    _scaled(own, metric, means),
                    _scaled(tops, metric, means),
                )
                if found is not None:
                    row.update(zip(("gap_closed", "gap_ci_low", "gap_ci_high"), found, strict=True))
            rows.append(row)
    return rows


def summarize(
    cells: Sequence[CellResult], reference: str = "nn_dsc", headroom: str = HEADROOM_REFERENCE
) -> list[dict[str, object]]:
    """Summary rows (``SUMMARY_COLUMNS``) of every cell and metric, then the suite-wide rows.

    Metrics a policy does not have (NaN in every episode, e.g. a speed-estimate
    error without an estimator) get no row. The suite-wide rows need the
    reference on every scenario. The gap columns (``GAP_METRICS``) need the
    reference and the ``headroom`` reference on the scenario (on every
    scenario for the suite-wide rows), and stay empty where the headroom
    reference is not better than the reference. They are the normalized score
    (``normalized_score``).
    """
    by_key = {(cell.policy, cell.scenario): cell for cell in cells}
    rows: list[dict[str, object]] = []
    for cell in cells:
        failures = int(cell.metrics["terminated"].sum())
        base = by_key.get((reference, cell.scenario))
        matrix = np.stack([cell.metrics[metric] for metric in METRICS])  # (M, N)
        mean_ci, iqm_ci = stats.bootstrap_rows(matrix), stats.bootstrap_rows(matrix, stats.iqm)
        paired = base is not None and cell.policy != reference
        if base is not None and paired:
            differences = matrix - np.stack([base.metrics[metric] for metric in METRICS])
            diff_ci = stats.bootstrap_rows(differences)
        for k, metric in enumerate(METRICS):
            values = cell.metrics[metric]
            if np.all(np.isnan(values)):
                continue
            intervals = (mean_ci[0][k], mean_ci[1][k], iqm_ci[0][k], iqm_ci[1][k])
            row = _row(
                cell.policy,
                cell.scenario,
                metric,
                [values],
                failures,
                cell.deterministic,
                tuple(float(x) for x in intervals),  # type: ignore[arg-type]
            )
            if base is not None and not np.all(np.isnan(base.metrics[metric])):
                interval = (float(diff_ci[0][k]), float(diff_ci[1][k])) if paired else None
                _compare(row, values, base.metrics[metric], metric, interval)
            top = by_key.get((headroom, cell.scenario))
            if metric in GAP_METRICS and base is not None and top is not None:
                if cell.policy not in (reference, headroom):
                    found = stats.gap_closed(base.metrics[metric], values, top.metrics[metric])
                    if found is not None:
                        row.update(
                            zip(("gap_closed", "gap_ci_low", "gap_ci_high"), found, strict=True)
                        )
            rows.append(row)
    rows += _suite_rows(cells, reference, headroom, by_key)
    versions = {splits.suite_version(cell.scenario) for cell in cells}
    suite_wide = versions.pop() if len(versions) == 1 else None  # one version on every scenario
    for row in rows:
        scenario = str(row["scenario"])
        row["suite_version"] = suite_wide if scenario == "all" else splits.suite_version(scenario)
    return rows


def normalized_score(row: Mapping[str, object]) -> tuple[float, float, float] | None:
    """The normalized score of a summary row, with its 95 % interval: (score, low, high).

    score = (J_reference - J) / (J_reference - J_headroom) of the mean costs,
    computed by ``summarize`` against the headroom reference it is given by
    name (``stats.gap_closed``): 0 = the reference's level, 1 = the headroom
    reference's, below 0 worse than the reference. On a suite-wide row the
    costs are each scenario's divided by the reference's mean there.

    Returns:
        None where the row has no score: the headroom reference did not run
        (on every scenario, for a suite-wide row), is not better than the
        reference, or the row is the reference's or the headroom reference's.
    """
    if row.get("gap_closed") is None:
        return None
    keys = ("gap_closed", "gap_ci_low", "gap_ci_high")
    score, low, high = (float(row[key]) for key in keys)  # type: ignore[arg-type]
    return score, low, high


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if np.isnan(value) else repr(value)
    return str(value)


def _table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([[_cell(value) for value in row] for row in rows])
    return buffer.getvalue()


def episodes_csv(cells: Sequence[CellResult]) -> str:
    """``episodes.csv``: one row per episode, the metrics in ``METRICS`` order."""
    rows = [
        [cell.policy, cell.scenario, seed, cell.deterministic]
        + [float(cell.metrics[metric][k]) for metric in METRICS]
        for cell in cells
        for k, seed in enumerate(cell.seeds)
    ]
    return _table(("policy", "scenario", "seed", "deterministic", *METRICS), rows)


def _column(
    rows: Sequence[dict[str, str]], metric: str, absent: Mapping[str, float]
) -> NDArray[np.float64]:
    """One metric of a cell's rows; an empty field is NaN, an absent column its fixed value."""
    if metric in absent:
        return np.full(len(rows), absent[metric])
    return np.array([float(row[metric] or "nan") for row in rows])


def read_episodes_csv(text: str) -> list[CellResult]:
    """The cells of an ``episodes.csv`` (``episodes_csv``'s inverse), in their first-row order.

    A table written before the separation metrics existed (every scenario of its
    time without a separation) reads with their values by construction
    (``UNSEPARATED``: a zero term, an unmeasured closest approach); one written
    before the course metrics existed (every hull of its time with a sway
    actuator) reads them as not measured (``COURSE_UNMEASURED``).

    Raises:
        ValueError: A column of ``METRICS`` or of the row key is missing (the file is
            not a ``cpf-bench`` episodes table, or of another version of it).
    """
    reader = csv.DictReader(io.StringIO(text))
    columns = reader.fieldnames or ()
    absent: dict[str, float] = {}
    for group in (UNSEPARATED, COURSE_UNMEASURED):  # a partial group: a damaged table
        if not any(c in columns for c in group):
            absent.update(group)
    missing = [c for c in ("policy", "scenario", "seed", "deterministic", *METRICS)
               if c not in columns and c not in absent]  # fmt: skip
    if missing:
        raise ValueError(
            f"not a cpf-bench episodes.csv: missing column(s) {missing}; regenerate it "
            "with cpf-bench --out."
        )
    grouped: dict[tuple[str, str], list[dict[str, str]]] = {}
    for row in reader:
        grouped.setdefault((row["policy"], row["scenario"]), []).append(row)
    return [
        CellResult(
            policy,
            scenario,
            tuple(int(row["seed"]) for row in rows),
            rows[0]["deterministic"] == "True",
            {metric: _column(rows, metric, absent) for metric in METRICS},
        )
        for (policy, scenario), rows in grouped.items()
    ]


def summary_csv(rows: Sequence[dict[str, object]]) -> str:
    """``summary.csv``: the rows of ``summarize``, columns ``SUMMARY_COLUMNS``."""
    return _table(SUMMARY_COLUMNS, [[row[c] for c in SUMMARY_COLUMNS] for row in rows])
