"""Readable views of a benchmark run: the markdown summary and one figure per headline metric.

Both read the rows of ``bench_report.summarize``; the figures are drawn on
fresh matplotlib ``Figure`` objects (Agg, no window) with no time stamp, so
the same rows give the same bytes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from cpf_commands.bench.report import HEADLINE, CellResult
from cpf_commands.bench.verdict import RELATIVE_TOLERANCE, Verdict, verdicts

__all__ = ["figure", "markdown", "markdown_table", "terminal_table", "verdict_rows"]

VERDICT_HEADER = ("policy", "scenario", "N", "cost difference [95 %]", "P(beats) [95 %]", "verdict")


def verdict_rows(found: Sequence[Verdict]) -> list[list[str]]:
    """One row of cell texts per verdict (``VERDICT_HEADER``)."""
    rows = []
    for v in found:
        diff, low, high = v.cost_difference
        p, p_low, p_high = v.p_beats
        rows.append(
            [
                v.policy,
                v.scenario,
                str(v.episodes),
                f"{diff:+.3g} [{low:+.3g}, {high:+.3g}]",
                f"{p:.2f} [{p_low:.2f}, {p_high:.2f}]",
                v.label,
            ]
        )
    return rows


def terminal_table(cells: Sequence[CellResult], reference: str) -> str:
    """The verdicts as a plain-text table for the terminal ('' without the reference)."""
    body = verdict_rows(verdicts(cells, reference))
    if not body:
        return ""
    table = [list(VERDICT_HEADER), *body]
    widths = [max(len(row[k]) for row in table) for k in range(len(VERDICT_HEADER))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)) for row in table]
    return f"against {reference}:\n" + "\n".join(line.rstrip() for line in lines)


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


def markdown(
    rows: list[dict[str, object]],
    cells: Sequence[CellResult],
    command: str,
    reference: str,
    skipped: Mapping[tuple[str, str], str],
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
    judged = verdicts(cells, reference)
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
            "See docs/benchmark.md.",
            "",
        ]
        lines += markdown_table(VERDICT_HEADER, verdict_rows(judged))
    if skipped:
        lines += ["", "Not run (the policy does not fit the scenario):", ""]
        lines += [f"- {policy} on {name}: {why}" for (policy, name), why in skipped.items()]
    if any(r["scenario"] == "all" for r in rows):
        body = []
        for policy in policies:
            found = [index.get((policy, "all", f"{m}_normalized")) for m, _ in HEADLINE]
            failures = next((str(r["failures"]) for r in found if r), "")
            body.append([policy, *(_interval(r) for r in found), failures])
        lines += ["", f"## All scenarios, each episode divided by {reference}'s mean", ""]
        lines += markdown_table(["policy", *headings, "failures"], body)
    for metric, heading in HEADLINE[:2]:
        body = []
        for policy in policies:
            found = [index.get((policy, name, metric)) for name in names]
            body.append([policy] + [_mean_and_failures(r) for r in found])
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
            body.append([policy, text[0], _interval(cost, "iqm"), *text[1:], failures, ratio, p])
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


def figure(
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
        deterministic = any(c.deterministic for c in cells if c.scenario == name)
        ax.set_title(f"{name} (deterministic)" if deterministic else name, fontsize=9)
        ax.set_xticks(range(len(policies)), policies, rotation=45, ha="right", fontsize=7)
        ax.tick_params(axis="y", labelsize=7)
        ax.grid(axis="y", alpha=0.3)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    fig.suptitle(f"{title}: mean and 95 % bootstrap interval")
    return fig
