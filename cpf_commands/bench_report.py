"""Tables and figures of a benchmark run: summary rows, CSV, markdown and PNG.

``summarize`` turns per-episode results into one row per policy x scenario x
metric (mean and IQM with 95 % bootstrap intervals, failures, the ratio to
the reference policy's mean and the probability of beating it on a paired
episode), plus, when the reference ran, rows over all scenarios together
(scenario ``"all"``, metric ``<metric>_normalized``): every episode divided
by the reference's mean on its scenario, resampled by a bootstrap stratified
by scenario. Numbers are written with ``repr`` (shortest round-trip form) and
the files carry no time stamps or paths, so the same arguments give the same
bytes.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from cpf_commands import stats
from cpf_commands.episodes import METRICS

__all__ = ["HEADLINE", "CellResult", "summarize", "write_outputs"]

#: Metrics shown in summary.md and drawn as figures: (metric, heading in tables and figures).
HEADLINE: tuple[tuple[str, str], ...] = (
    ("cost", "cost"),
    ("cost_window", "cost, final window"),
    ("path_error_rms_window", "path error RMS, final window (m)"),
    ("coordination_error_end", "coordination error at the end"),
    ("speed_error_rms_window", "speed error RMS, final window (m/s)"),
    ("control_energy", "control energy (s)"),
    ("saturated_fraction", "saturated fraction"),
)
#: Metrics where higher is better (for all others lower is).
HIGHER_IS_BETTER = frozenset({"return", "return_window", "steps"})

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
    "p_beats_reference",
    "p_ci_low",
    "p_ci_high",
)


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
) -> dict[str, object]:
    values = np.concatenate(strata)
    low, high = stats.bootstrap_interval(strata)
    iqm_low, iqm_high = stats.bootstrap_interval(strata, stats.iqm)
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
        "p_beats_reference": None,
        "p_ci_low": None,
        "p_ci_high": None,
    }


def _compare(
    row: dict[str, object], values: NDArray, reference: NDArray, metric: str, paired: bool
) -> None:
    """Fill the reference columns of ``row`` (``paired``: also the probability of beating it)."""
    reference_mean = float(reference.mean())
    if reference_mean != 0.0:
        row["normalized"] = float(values.mean()) / reference_mean
    if not paired:
        return
    p, low, high = stats.probability_of_beating(_signed(metric, values), _signed(metric, reference))
    row.update(p_beats_reference=p, p_ci_low=low, p_ci_high=high)


def summarize(cells: Sequence[CellResult], reference: str = "nn_dsc") -> list[dict[str, object]]:
    """Summary rows (``SUMMARY_COLUMNS``) of every cell and metric, then the suite-wide rows.

    Metrics a policy does not have (NaN in every episode, e.g. a speed-estimate
    error without an estimator) get no row.
    """
    by_key = {(cell.policy, cell.scenario): cell for cell in cells}
    rows: list[dict[str, object]] = []
    for cell in cells:
        failures = int(cell.metrics["terminated"].sum())
        base = by_key.get((reference, cell.scenario))
        for metric in METRICS:
            values = cell.metrics[metric]
            if np.all(np.isnan(values)):
                continue
            row = _row(cell.policy, cell.scenario, metric, [values], failures, cell.deterministic)
            if base is not None and not np.all(np.isnan(base.metrics[metric])):
                _compare(row, values, base.metrics[metric], metric, cell.policy != reference)
            rows.append(row)
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    scenario_names = list(dict.fromkeys(cell.scenario for cell in cells))
    references = [by_key.get((reference, name)) for name in scenario_names]
    if any(base is None for base in references):
        return rows
    for policy in policies:
        own = [by_key[(policy, name)] for name in scenario_names]
        for metric, _ in HEADLINE:
            means = [float(base.metrics[metric].mean()) for base in references]  # type: ignore[union-attr]
            if any(mean == 0.0 for mean in means):
                continue
            strata = [c.metrics[metric] / mean for c, mean in zip(own, means, strict=True)]
            failures = sum(int(c.metrics["terminated"].sum()) for c in own)
            row = _row(policy, "all", f"{metric}_normalized", strata, failures, False)
            row["normalized"] = row["mean"]
            wins = [
                (c.metrics[metric] < b.metrics[metric])
                + 0.5 * (c.metrics[metric] == b.metrics[metric])  # type: ignore[union-attr]
                for c, b in zip(own, references, strict=True)
            ]
            low, high = stats.bootstrap_interval(wins)
            row.update(
                p_beats_reference=float(np.concatenate(wins).mean()), p_ci_low=low, p_ci_high=high
            )
            rows.append(row)
    return rows


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if np.isnan(value) else repr(value)
    return str(value)


def _csv(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([[_cell(value) for value in row] for row in rows])
    return buffer.getvalue()


def _interval(row: dict[str, object]) -> str:
    mean, low, high = (float(row[k]) for k in ("mean", "ci_low", "ci_high"))  # type: ignore[arg-type]
    if row["n_episodes"] == 1:
        return f"{mean:.3g}"
    return f"{mean:.3g} [{low:.3g}, {high:.3g}]"


def _markdown(
    rows: list[dict[str, object]], cells: Sequence[CellResult], command: str, reference: str
) -> str:
    index = {(r["policy"], r["scenario"], r["metric"]): r for r in rows}
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    lines = [
        "# cpf-bench summary",
        "",
        f"Regenerate with `{command}`.",
        "",
        "Mean over episodes with its 95 % bootstrap interval in brackets (2000 replicates, "
        f"fixed seed); every policy runs the same seeds. `failures`: episodes that left the "
        f"path (counted, never dropped; a failed episode's metrics cover its steps up to the "
        f"failure). `/ {reference}`: the cost's mean over {reference}'s; `P(beats)`: probability "
        f"of a lower cost than {reference} on the same seed. Full numbers: `summary.csv`.",
    ]
    if any(r["scenario"] == "all" for r in rows):
        lines += [
            "",
            f"## All scenarios, each episode divided by {reference}'s mean on its scenario",
            "",
        ]
        lines.append("| policy | " + " | ".join(h for _, h in HEADLINE) + " | failures |")
        lines.append("|---" * (len(HEADLINE) + 2) + "|")
        for policy in policies:
            cells_ = [index.get((policy, "all", f"{m}_normalized")) for m, _ in HEADLINE]
            text = [_interval(r) if r else "" for r in cells_]
            failures = next((r["failures"] for r in cells_ if r), "")
            lines.append(f"| {policy} | " + " | ".join(text) + f" | {failures} |")
    scenario_names = list(dict.fromkeys(cell.scenario for cell in cells))
    for name in scenario_names:
        first = next(cell for cell in cells if cell.scenario == name)
        count = (
            "deterministic: every seed gives the same episode, so one episode"
            if first.deterministic
            else f"{len(first.seeds)} episodes, seeds {first.seeds[0]}..{first.seeds[-1]}"
        )
        lines += ["", f"## {name} ({count})", ""]
        lines.append(
            "| policy | "
            + " | ".join(h for _, h in HEADLINE)
            + f" | failures | / {reference} | P(beats) |"
        )
        lines.append("|---" * (len(HEADLINE) + 4) + "|")
        for policy in policies:
            row_cost = index.get((policy, name, "cost"))
            if row_cost is None:
                continue
            text = [
                _interval(index[(policy, name, m)]) if (policy, name, m) in index else ""
                for m, _ in HEADLINE
            ]
            ratio = "" if row_cost["normalized"] is None else f"{row_cost['normalized']:.3g}"
            p = (
                ""
                if row_cost["p_beats_reference"] is None or policy == reference
                else f"{row_cost['p_beats_reference']:.2f}"
            )
            lines.append(
                f"| {policy} | "
                + " | ".join(text)
                + f" | {row_cost['failures']}/{row_cost['n_episodes']} | {ratio} | {p} |"
            )
    return "\n".join(lines) + "\n"


def _figure(
    rows: list[dict[str, object]], cells: Sequence[CellResult], metric: str, title: str
) -> Figure:
    """One panel per scenario, one bar per policy: mean with its 95 % interval."""
    index = {(r["policy"], r["scenario"]): r for r in rows if r["metric"] == metric}
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    columns = min(4, len(names))
    grid = (len(names) + columns - 1) // columns
    fig = Figure(figsize=(3.2 * columns, 2.8 * grid + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(grid, columns, squeeze=False)).reshape(-1)
    colors = [f"C{k % 10}" for k in range(len(policies))]
    for ax, name in zip(axes, names, strict=False):
        for k, policy in enumerate(policies):
            row = index.get((policy, name))
            if row is None:
                continue
            mean = float(row["mean"])  # type: ignore[arg-type]
            error = [[mean - float(row["ci_low"])], [float(row["ci_high"]) - mean]]  # type: ignore[arg-type]
            ax.bar(k, mean, color=colors[k], yerr=error, capsize=3)
            if int(row["failures"]):  # type: ignore[call-overload]
                ax.annotate(
                    f"{row['failures']} failed",
                    (k, mean),
                    ha="center",
                    va="bottom",
                    fontsize=7,
                    color="red",
                )
        ax.set_title(name, fontsize=9)
        ax.set_xticks(range(len(policies)), policies, rotation=45, ha="right", fontsize=7)
        ax.tick_params(axis="y", labelsize=7)
        ax.grid(axis="y", alpha=0.3)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    fig.suptitle(f"{title}: mean and 95 % bootstrap interval")
    return fig


def write_outputs(
    cells: Sequence[CellResult],
    out: str | Path,
    command: str,
    reference: str = "nn_dsc",
    figures: bool = True,
) -> list[dict[str, object]]:
    """Write episodes.csv, summary.csv, summary.md and one PNG per headline metric to ``out``.

    Returns:
        The summary rows.
    """
    directory = Path(out)
    directory.mkdir(parents=True, exist_ok=True)
    episode_rows = [
        [
            cell.policy,
            cell.scenario,
            seed,
            cell.deterministic,
            *(float(cell.metrics[m][k]) for m in METRICS),
        ]
        for cell in cells
        for k, seed in enumerate(cell.seeds)
    ]
    (directory / "episodes.csv").write_text(
        _csv(("policy", "scenario", "seed", "deterministic", *METRICS), episode_rows)
    )
    rows = summarize(cells, reference)
    (directory / "summary.csv").write_text(
        _csv(SUMMARY_COLUMNS, [[row[c] for c in SUMMARY_COLUMNS] for row in rows])
    )
    (directory / "summary.md").write_text(_markdown(rows, cells, command, reference))
    if figures:
        for metric, title in HEADLINE:
            _figure(rows, cells, metric, title).savefig(
                directory / f"{metric}.png", dpi=100, metadata={"Software": None}
            )
    return rows
