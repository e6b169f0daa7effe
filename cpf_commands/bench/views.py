"""Readable views of a benchmark run: the markdown summary and one figure per headline metric.

Both read the rows of ``bench_report.summarize``; the figures are drawn on
fresh matplotlib ``Figure`` objects (Agg, no window) with no time stamp, so
the same rows give the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from baselines import HEADROOM_REFERENCE, PRIVILEGED
from cpf_bench.headroom import headroom_table, room_table
from cpf_bench.report import GAP_METRICS, HEADLINE, CellResult
from cpf_bench.verdict import (
    COST_MARGIN,
    GUARDED,
    RELATIVE_TOLERANCE,
    Verdict,
    verdicts,
    worst_episode,
    worst_episode_regressed,
)
from cpf_env.scenarios import suite

__all__ = [
    "display_name",
    "figure",
    "figure_label",
    "gap_table",
    "markdown",
    "markdown_table",
    "regression_lines",
    "verdict_rows",
]

VERDICT_HEADER = ("policy", "scenario", "N", "cost difference [95 %]", "P(beats) [95 %]", "verdict")


def display_name(policy: str) -> str:
    """A policy's name in tables: a privileged reference says that it is one."""
    return f"{policy} (privileged, not deployable)" if policy in PRIVILEGED else policy


def figure_label(policy: str) -> str:
    """A policy's label in figures: a folder's last part; a privileged reference says so."""
    short = policy.rstrip("/").split("/")[-1]
    return f"{short} (privileged)" if policy in PRIVILEGED else short


def verdict_rows(found: Sequence[Verdict]) -> list[list[str]]:
    """One row of cell texts per verdict (``VERDICT_HEADER``)."""
    rows = []
    for v in found:
        diff, low, high = v.cost_difference
        p, p_low, p_high = v.p_beats
        rows.append(
            [
                display_name(v.policy),
                v.scenario,
                str(v.episodes),
                f"{diff:+.3g} [{low:+.3g}, {high:+.3g}]",
                f"{p:.2f} [{p_low:.2f}, {p_high:.2f}]",
                v.label,
            ]
        )
    return rows


#: Units of the guarded metrics' short labels, as printed.
_UNITS = {"cross-track": " m", "heading": " rad", "formation": " m"}


def regression_lines(cells: Sequence[CellResult], reference: str, margin: float) -> list[str]:
    """One line per verdict with a regressed guarded metric: the means, policy vs reference.

    Final-window means in SI units (m, rad; progress as a fraction of v0 T,
    failures as a fraction of the episodes). Then one line per verdict whose
    worst episode regressed on a metric its mean did not
    (``verdict.worst_episode_regressed``): the worst episodes' values.
    """
    by_key = {(cell.policy, cell.scenario): cell for cell in cells}
    lines, tails = [], []
    for result in verdicts(cells, reference, margin):
        cell, base = by_key[result.policy, result.scenario], by_key[reference, result.scenario]
        if result.regressed:
            values = _values(cell, base, result.regressed, lambda _, v: float(np.mean(v)))
            lines.append(
                f"  {result.policy} on {result.scenario}, worse than {reference}: {values}"
            )
        tail = [m for m in worst_episode_regressed(cell, base) if m not in result.regressed]
        if tail:
            values = _values(cell, base, tail, worst_episode)
            tails.append(
                f"  {result.policy} on {result.scenario}, worst episode worse than "
                f"{reference}'s worst: {values}"
            )
    return lines + tails


def _values(
    cell: CellResult,
    base: CellResult,
    labels: Sequence[str],
    statistic: Callable[[str, np.ndarray], float],
) -> str:
    """``label value vs value`` of guarded metrics (short labels), policy then reference.

    ``statistic(metric, episode values)`` gives each value; units as printed (``_UNITS``).
    """
    metric_of = {label: name for name, (label, _, _) in GUARDED.items()}
    return ", ".join(
        f"{label} {statistic(metric_of[label], cell.metrics[metric_of[label]]):.3g}"
        f"{_UNITS.get(label, '')} vs "
        f"{statistic(metric_of[label], base.metrics[metric_of[label]]):.3g}{_UNITS.get(label, '')}"
        for label in labels
    )


def _interval(row: dict[str, object] | None, estimate: str = "mean") -> str:
    """An estimate ("mean" or "iqm") with its interval in brackets (alone for one episode)."""
    if row is None:
        return ""
    prefix = "" if estimate == "mean" else f"{estimate}_"
    keys = (estimate, f"{prefix}ci_low", f"{prefix}ci_high")
    mean, low, high = (float(row[k]) for k in keys)  # type: ignore[arg-type]
    if row["n_episodes"] == 1:
        return f"{mean:.3g}"
    return f"{mean:.3g} [{low:.3g}, {high:.3g}]"


def markdown_table(header: Sequence[str], body: Sequence[Sequence[str]]) -> list[str]:
    """The lines of a markdown table: the header, its rule, one line per row of cell texts."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(row) + " |" for row in body]


def gap_table(
    rows: list[dict[str, object]], cells: Sequence[CellResult], metric: str, reference: str
) -> list[str]:
    """Markdown lines: each policy's share of the gap closed on ``metric``, per scenario.

    "n/a" where the headroom reference is not better than the reference (no
    gap to close); empty where the policy did not run.
    """
    index = {(r["policy"], r["scenario"]): r for r in rows if r["metric"] == metric}
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    policies = [
        p
        for p in dict.fromkeys(cell.policy for cell in cells)
        if p not in (reference, HEADROOM_REFERENCE)
    ]
    body = []
    for policy in policies:
        texts = []
        for name in names:
            row = index.get((policy, name))
            if row is None or (reference, name) not in index:
                texts.append("")
            elif row["gap_closed"] is None:
                texts.append("n/a")
            else:
                keys = ("gap_closed", "gap_ci_low", "gap_ci_high")
                share, low, high = (float(row[k]) for k in keys)  # type: ignore[arg-type]
                flag = " (above 1: beats the bound)" if share > 1.0 else ""
                texts.append(f"{share:.2f} [{low:.2f}, {high:.2f}]{flag}")
        body.append([display_name(policy), *texts])
    return markdown_table(["policy", *names], body)


def markdown(
    rows: list[dict[str, object]],
    cells: Sequence[CellResult],
    command: str,
    reference: str,
    skipped: Mapping[tuple[str, str], str],
    margin: float = COST_MARGIN,
) -> str:
    """``summary.md``: the command, how to read it, and the headline metrics' tables."""
    index = {(r["policy"], r["scenario"], r["metric"]): r for r in rows}
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    headings = [heading for _, heading in HEADLINE]
    lines = [
        "# cpf-bench summary",
        "",
        f"Regenerate with `{command}`.",
        "",
        "Mean over episodes with its 95 % bootstrap interval in brackets (2000 replicates, "
        "fixed seed); every policy runs the same seeds. Failures are episodes that left the "
        "path: counted, never dropped; a failed episode's metrics cover its steps up to the "
        f"failure. IQM: interquartile mean. `/ {reference}`: the mean cost over {reference}'s; "
        f"`P(beats)`: probability of a lower cost than {reference} on the same seed. "
        "All numbers: `summary.csv`.",
    ]
    tracks = {suite.track_of(str(r["scenario"])) for r in rows}
    versions = sorted(
        {str(r["suite_version"]) for r in rows if suite.track_of(str(r["scenario"])) == "core"}
    )
    if "hard" in tracks:
        lines += [
            "",
            f"Hard-track scenarios: hard track version {suite.HARD_VERSION} "
            "(`cpf_env.scenarios.suite.HARD_VERSION`; sensing, hulls without sway, thruster "
            "dynamics and crossing traffic, `cpf_env.scenarios.hard`); results of another "
            "version do not compare.",
        ]
    if versions:
        lines += [
            "",
            f"Suite scenarios: benchmark suite version {', '.join(map(str, versions))} "
            "(`cpf_env.scenarios.suite.SUITE_VERSION`); results of another version do not "
            "compare.",
        ]
    judged = verdicts(cells, reference, margin)
    if judged:
        lines += [
            "",
            f"## Verdict against {reference}",
            "",
            f"Cost difference: mean over seeds of (policy - {reference}) cost, with its 95 % "
            "bootstrap interval; P(beats) with Wilson's 95 % interval. `beats` needs the "
            "whole cost interval below zero and no guarded physical metric (final-window "
            "cross-track, heading and formation error, progress, failures) worse by more "
            f"than {RELATIVE_TOLERANCE:.0%} of {reference}'s mean (and a physical floor) with "
            "its interval above zero; else `mixed` names the metric that regressed. "
            f"`equivalent`: the whole cost interval lies within +-{margin:.1%} of {reference}'s "
            "mean cost (the practical-equivalence margin, `--cost-margin`), too small a "
            "difference to matter either way. See docs/benchmark.md.",
            "",
        ]
        lines += markdown_table(VERDICT_HEADER, verdict_rows(judged))
    privileged = [p for p in policies if p in PRIVILEGED]
    if privileged:
        lines += [
            "",
            f"Privileged references ({', '.join(privileged)}): told the true lumped model error "
            "and disturbances and given lossless, undelayed neighbour values; not deployable. "
            f"{HEADROOM_REFERENCE} plans on copies of the simulator (the true model and the "
            "future disturbances) over the whole fleet: the headroom bound.",
        ]
    room = headroom_table(cells, reference)
    if room:
        lines += [
            "",
            "## Headroom",
            "",
            f"Mean costs; best deployable analytic: the cheapest of baselines.DEPLOYABLE that ran; "
            f"headroom = 1 - J {HEADROOM_REFERENCE} / J best (docs/benchmark.md).",
            "",
            *room,
        ]
    closed = room_table(cells)
    if closed:
        lines += [
            "",
            "## Room closed",
            "",
            "Each policy outside baselines against its scenario's room: (J best - J) / (J best - "
            f"J {HEADROOM_REFERENCE}), 0 at the best deployable analytic design and 1 at the "
            "bound; IQM of the per-episode scores over the scenarios with a 95 % bootstrap "
            "interval stratified by scenario (docs/benchmark.md).",
            "",
            *closed,
        ]
    if HEADROOM_REFERENCE in policies and len(policies) > 2:
        for metric in GAP_METRICS:
            lines += [
                "",
                f"## Normalized score against {HEADROOM_REFERENCE}, {metric}",
                "",
                f"({reference} - policy) / ({reference} - {HEADROOM_REFERENCE}) of the mean "
                f"{metric}, with its paired 95 % bootstrap interval: 0 = {reference}'s level, 1 = "
                f"the bound's, < 0 worse than {reference}; above 1 (flagged) the policy beat the "
                "bound, which a finite-horizon sampled plan can allow (docs/benchmark.md). n/a: "
                f"{HEADROOM_REFERENCE} is not better than {reference} there (no gap to close).",
                "",
            ]
            lines += gap_table(rows, cells, metric, reference)
    if skipped:
        lines += ["", "Not run (the policy does not fit the scenario):", ""]
        lines += [f"- {policy} on {name}: {why}" for (policy, name), why in skipped.items()]
    if any(r["scenario"] == "all" for r in rows):
        body = []
        for policy in policies:
            found = [index.get((policy, "all", f"{m}_normalized")) for m, _ in HEADLINE]
            failures = next((str(r["failures"]) for r in found if r), "")
            body.append([display_name(policy), *(_interval(r) for r in found), failures])
        lines += ["", f"## All scenarios, each episode divided by {reference}'s mean", ""]
        lines += markdown_table(["policy", *headings, "failures"], body)
    for metric, heading in HEADLINE[:2]:
        body = []
        for policy in policies:
            found = [index.get((policy, name, metric)) for name in names]
            body.append([display_name(policy)] + [_mean_and_failures(r) for r in found])
        lines += ["", f"## {heading.capitalize()} by scenario (mean; failed episodes)", ""]
        lines += markdown_table(["policy", *names], body)
    for name in names:
        first = next(cell for cell in cells if cell.scenario == name)
        count = (
            "deterministic: every seed gives the same episode, so one episode"
            if first.deterministic
            else f"{len(first.seeds)} episodes, seeds {first.seeds[0]}..{first.seeds[-1]}"
        )
        body = []
        for policy in policies:
            cost = index.get((policy, name, "cost"))
            if cost is None:
                continue
            ratio = "" if cost["normalized"] is None else f"{cost['normalized']:.3g}"
            p = "" if cost["p_beats_reference"] is None else f"{cost['p_beats_reference']:.2f}"
            failures = f"{cost['failures']}/{cost['n_episodes']}"
            found = [index.get((policy, name, m)) for m, _ in HEADLINE]
            text = [_interval(r) for r in found]
            body.append(
                [
                    display_name(policy),
                    text[0],
                    _interval(cost, "iqm"),
                    *text[1:],
                    failures,
                    ratio,
                    p,
                ]
            )
        lines += ["", f"## {name} ({count})", ""]
        header = ["policy", headings[0], "cost IQM", *headings[1:]]
        lines += markdown_table([*header, "failures", f"/ {reference}", "P(beats)"], body)
    return "\n".join(lines) + "\n"


def _mean_and_failures(row: dict[str, object] | None) -> str:
    """The mean, followed by the number of failed episodes if any."""
    if row is None:
        return ""
    failures = int(row["failures"])  # type: ignore[call-overload]
    return f"{float(row['mean']):.3g}" + (f" ({failures} failed)" if failures else "")  # type: ignore[arg-type]


def _ratio(row: dict[str, object], base: dict[str, object]) -> tuple[float, float, float] | None:
    """Policy mean over the reference mean; the paired interval mapped the same way."""
    scale = float(base["mean"])  # type: ignore[arg-type]
    if scale <= 0.0 or row["diff_reference"] is None:
        return None
    low, high = (float(row[k]) for k in ("diff_ci_low", "diff_ci_high"))  # type: ignore[arg-type]
    mean = float(row["mean"])  # type: ignore[arg-type]
    return mean / scale, 1.0 + low / scale, 1.0 + high / scale


#: Minor ticks of the log axis that get a label.
_MINOR = (0.2, 0.5, 2.0, 5.0)
#: Smallest ratio drawn on the log axis, its left edge: a mean below it is drawn there as a
#: "<" marker, and an interval reaching below it is annotated as clipped.
_FLOOR = 1e-3


def figure(
    rows: list[dict[str, object]], cells: Sequence[CellResult], metric: str, title: str
) -> Figure:
    """Each policy's mean over the reference's on every scenario, with the paired 95 % interval.

    One row per scenario, one marker per policy, on a log axis centred on 1
    (the reference); a cell that did not run is written out as "not run", a
    ratio below 0.001 is drawn at that axis edge and marked clipped, and a
    metric whose reference mean is not positive has no ratio (written out).
    The figure grows with the number of scenarios, so it stays readable.
    """
    index = {(r["policy"], r["scenario"]): r for r in rows if r["metric"] == metric}
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    reference = next(
        (
            p
            for p in policies
            if all(index.get((p, n), {}).get("diff_reference") is None for n in names)
        ),
        policies[0],
    )
    others = [p for p in policies if p != reference]
    height = 1.2 + 0.28 * max(1, len(names) * max(1, len(others)))
    fig = Figure(figsize=(8.0, height), layout="constrained")
    ax = fig.subplots()
    spacing = 1.0 / (len(others) + 1)
    clipped = False
    for k, policy in enumerate(others):
        color = f"C{k % 10}"
        label: str | None = figure_label(policy)
        for row_index, name in enumerate(names):
            y = row_index + (k + 1) * spacing - 0.5
            row, base = index.get((policy, name)), index.get((reference, name))
            if row is None or base is None:
                ax.annotate("not run", (1.0, y), fontsize=7, color="grey", va="center")
                continue
            ratio = _ratio(row, base)
            if ratio is None:
                ax.annotate(
                    f"no ratio ({reference}'s mean <= 0)",
                    (1.0, y),
                    fontsize=7,
                    color="grey",
                    va="center",
                )
                continue
            mean, low, high = (max(value, _FLOOR) for value in ratio)
            ax.errorbar(
                mean,
                y,
                xerr=[[mean - low], [high - mean]],
                fmt="<" if ratio[0] < _FLOOR else "o",
                color=color,
                markersize=4,
                capsize=2,
                label=label,
            )
            label = None
            if ratio[1] < _FLOOR:  # pinned to the axis edge: say so
                ax.annotate(
                    f"< {_FLOOR:g}: clipped",
                    (_FLOOR, y),
                    xytext=(3, 4),
                    textcoords="offset points",
                    fontsize=7,
                    color=color,
                )
                clipped = True
            failures = int(row["failures"])  # type: ignore[call-overload]
            if failures:
                ax.annotate(f"{failures} failed", (high, y), fontsize=7, color="red", va="center")
    ax.axvline(1.0, color="black", linewidth=0.8)
    ax.set_xscale("log")
    if clipped:  # the floor is the axis edge, where clipped markers and bars end
        ax.set_xlim(left=_FLOOR)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_ylim(len(names) - 0.5, -0.5)
    ax.grid(axis="x", which="both", alpha=0.3)
    ax.set_xlabel(f"mean / {reference}'s mean (log; < 1 is better for errors and cost)", fontsize=8)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"x{x:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(lambda x, _: f"{x:g}" if x in _MINOR else ""))
    ax.tick_params(axis="x", which="both", labelsize=7)
    if ax.get_legend_handles_labels()[0]:  # none when no ratio was drawn
        fig.legend(fontsize=7, loc="outside lower center", ncols=min(3, len(others)))
    fig.suptitle(f"{title}\nrelative to {reference}, paired 95 % bootstrap interval", fontsize=10)
    return fig
