"""The bench's answer: ranked tables per scenario and over the suite, and the best policy named.

``ranked_tables`` reads the summary rows (``report.summarize``) and the
verdicts (``verdict.verdicts``) and builds one ``RankedTable`` per scenario
and one over all scenarios, each policy a row, lowest mean cost first:

* mean cost with its 95 % bootstrap interval (over all episodes for the
  suite-wide table);
* the ratio to the reference's mean cost with its paired 95 % interval (the
  suite-wide ratio: each episode divided by the reference's mean on its
  scenario, stratified bootstrap);
* the normalized score (J_reference - J) / (J_reference - J_headroom) with
  its interval, read from the summary rows (``report.normalized_score``):
  "n/a" where the headroom reference did not run, "no gap" where it is not
  better than the reference;
* the verdict against the reference (suite-wide: the count of each per-scenario
  verdict);

and a sentence naming the best deployable policy (privileged references,
which read the simulator, are ranked but never named best). ``text`` renders
a table for the terminal; ``html_report`` renders the same tables as
``report.html``: the bench's answer and figures in one self-contained page
(the regressed guarded metrics, every figure inline as a base64 PNG), which
opens in any browser with nothing beside it. No time stamp or path: the same
run gives the same bytes.
"""

from __future__ import annotations

import base64
import html
import textwrap
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from baselines import HEADROOM_REFERENCE, PRIVILEGED
from cpf_bench.report import CellResult, normalized_score
from cpf_bench.verdict import COST_MARGIN, Verdict, verdicts
from cpf_commands.bench.views import regression_lines

__all__ = ["RankedTable", "html_report", "legend", "ranked_tables", "terminal_report", "text"]

#: The metric the tables rank by.
METRIC = "cost"


@dataclass(frozen=True)
class RankedTable:
    """One ranked table of the bench's answer.

    Attributes:
        title: What the table covers (a scenario, or all of them).
        header: Column headings.
        rows: Cell texts, one list per policy, best first.
        best: A sentence naming the best deployable policy ('' if none ran).
        suite: Whether the table covers every scenario.
    """

    title: str
    header: tuple[str, ...]
    rows: list[list[str]]
    best: str
    suite: bool = False


def _deployable(policy: str) -> bool:
    """Whether a policy may be named best: neither a privileged nor the headroom reference."""
    return policy not in PRIVILEGED and policy != HEADROOM_REFERENCE


def _name(policy: str, reference: str) -> str:
    if policy == reference:
        return f"{policy} (reference)"
    if policy in PRIVILEGED:
        return f"{policy} (privileged)"
    return policy if _deployable(policy) else f"{policy} (not deployable)"


def _triple(row: Mapping[str, object], keys: tuple[str, str, str]) -> tuple[float, float, float]:
    """Three float columns of a summary row."""
    first, second, third = (float(row[key]) for key in keys)  # type: ignore[arg-type]
    return first, second, third


def _number(value: float, digits: int) -> str:
    """``digits`` significant digits, or (``digits=0``, ratios and scores) 3 decimals.

    With 3 decimals, a value that rounds to zero is "0.000" whatever its sign,
    and one of 1000 or more keeps 4 significant digits.
    """
    if digits:
        return f"{value:.{digits}g}"
    if abs(value) >= 1e3:
        return f"{value:.4g}"
    return f"{value:.3f}" if round(value, 3) else "0.000"


def _interval(value: float, low: float, high: float, single: bool, digits: int = 4) -> str:
    """A value with its interval in brackets (alone when one episode leaves no interval)."""
    if single:
        return _number(value, digits)
    return f"{_number(value, digits)} [{_number(low, digits)}, {_number(high, digits)}]"


def _scores(
    found: Sequence[tuple[str, Mapping[str, object]]], reference: str, headroom_ran: bool
) -> list[str]:
    """The score column of a table's rows (``found``: policy, summary row).

    The reference 0; the headroom reference 1 where it is better than the
    reference (some row has a score), else "no gap"; every other policy its
    score, or "no gap"; "n/a" everywhere but the reference's row if the
    headroom reference did not run.
    """
    scores = [normalized_score(row) for _, row in found]
    gap = any(score is not None for score in scores)
    texts = []
    for (policy, row), score in zip(found, scores, strict=True):
        if policy == reference:
            texts.append("0")
        elif not headroom_ran:
            texts.append("n/a")
        elif policy == HEADROOM_REFERENCE:
            texts.append("1" if gap else "no gap")
        elif score is None:
            texts.append("no gap")
        else:
            texts.append(_interval(*score, single=row["n_episodes"] == 1, digits=0))
    return texts


def _ratio(row: Mapping[str, object], base: Mapping[str, object]) -> tuple[float, float, float]:
    """Policy mean / reference mean; the paired difference's interval mapped the same way."""
    scale = float(base["mean"])  # type: ignore[arg-type]
    mean = float(row["mean"]) / scale  # type: ignore[arg-type]
    if row["diff_reference"] is None:
        return mean, mean, mean
    _, low, high = _triple(row, ("diff_reference", "diff_ci_low", "diff_ci_high"))
    return mean, 1.0 + low / scale, 1.0 + high / scale


HEADER = ("#", "policy", "mean cost [95 %]", "/ {ref} [95 %]", "score [95 %]", "verdict")


def _scenario_table(
    name: str,
    index: Mapping[tuple[str, str, str], dict[str, object]],
    policies: Sequence[str],
    reference: str,
    judged: Mapping[tuple[str, str], Verdict],
) -> RankedTable | None:
    """The ranked table of one scenario (None without the reference's row there)."""
    base = index.get((reference, name, METRIC))
    if base is None or float(base["mean"]) == 0.0:  # type: ignore[arg-type]
        return None
    found = [(p, index[(p, name, METRIC)]) for p in policies if (p, name, METRIC) in index]
    found.sort(key=lambda item: float(item[1]["mean"]))  # type: ignore[arg-type]
    scores = _scores(found, reference, (HEADROOM_REFERENCE, name, METRIC) in index)
    rows, best = [], ""
    for rank, (policy, row) in enumerate(found, start=1):
        single = row["n_episodes"] == 1
        mean = _interval(*_triple(row, ("mean", "ci_low", "ci_high")), single=single)
        ratio = _ratio(row, base)
        verdict = judged[(policy, name)].label if (policy, name) in judged else "reference"
        failures = int(row["failures"])  # type: ignore[call-overload]
        if failures:
            verdict += f", {failures}/{row['n_episodes']} failed"
        rows.append(
            [
                str(rank),
                _name(policy, reference),
                mean,
                _interval(*ratio, single=single or policy == reference, digits=0),
                scores[rank - 1],
                verdict,
            ]
        )
        if not best and _deployable(policy):
            best = _best_sentence(policy, reference, ratio, verdict, single)
    episodes = int(base["n_episodes"])  # type: ignore[call-overload]
    count = "1 episode" if episodes == 1 else f"{episodes} episodes"
    return RankedTable(f"{name} ({count})", _header(reference), rows, best)


def _header(reference: str) -> tuple[str, ...]:
    return tuple(text.format(ref=reference) for text in HEADER)


def _best_sentence(
    policy: str, reference: str, ratio: tuple[float, float, float], verdict: str, single: bool
) -> str:
    """'best deployable: X, mean cost 0.930 [0.900, 0.950] x ref's (the lowest); verdict: beats'."""
    if policy == reference:
        return f"best deployable: {reference} (the reference): no policy has a lower mean cost"
    how = _interval(*ratio, single=single, digits=0)
    return (
        f"best deployable: {policy}, mean cost {how} x {reference}'s (the lowest); "
        f"verdict: {verdict}"
    )


def _suite_table(
    index: Mapping[tuple[str, str, str], dict[str, object]],
    cells: Sequence[CellResult],
    policies: Sequence[str],
    reference: str,
    found_verdicts: Sequence[Verdict],
) -> RankedTable | None:
    """The ranked table over every scenario (None without suite-wide rows)."""
    names = list(dict.fromkeys(cell.scenario for cell in cells))
    found = [
        (p, index[(p, "all", f"{METRIC}_normalized")])
        for p in policies
        if (p, "all", f"{METRIC}_normalized") in index
    ]
    if len(names) < 2 or not found:
        return None
    found.sort(key=lambda item: float(item[1]["mean"]))  # type: ignore[arg-type]
    by_key = {(cell.policy, cell.scenario): cell for cell in cells}
    scores = _scores(found, reference, all((HEADROOM_REFERENCE, name) in by_key for name in names))
    rows, best = [], ""
    for rank, (policy, row) in enumerate(found, start=1):
        episodes = [by_key[(policy, name)].metrics[METRIC] for name in names]
        total = sum(float(values.sum()) for values in episodes)
        count = sum(values.size for values in episodes)
        ratio = _triple(row, ("mean", "ci_low", "ci_high"))
        tally = Counter(v.label.split(" (")[0] for v in found_verdicts if v.policy == policy)
        verdict = ", ".join(f"{label} {k}" for label, k in tally.most_common()) or "reference"
        failures = int(row["failures"])  # type: ignore[call-overload]
        if failures:
            verdict += f"; {failures}/{count} failed"
        rows.append(
            [
                str(rank),
                _name(policy, reference),
                f"{total / count:.4g}",
                _interval(*ratio, single=policy == reference, digits=0),
                scores[rank - 1],
                verdict,
            ]
        )
        if not best and _deployable(policy):
            best = _best_sentence(policy, reference, ratio, verdict, policy == reference)
    header = list(_header(reference))
    header[2] = "mean cost (all episodes)"
    header[-1] = f"verdicts on {len(names)} scenarios"
    return RankedTable(f"all {len(names)} scenarios", tuple(header), rows, best, suite=True)


def ranked_tables(
    rows: Sequence[dict[str, object]],
    cells: Sequence[CellResult],
    reference: str,
    margin: float = COST_MARGIN,
) -> list[RankedTable]:
    """One ranked table per scenario where the reference ran, then the suite-wide one.

    Args:
        rows: The summary rows of ``cells`` (``report.summarize`` with ``reference``).
        cells: The results.
        reference: The policy the ratios, scores and verdicts are relative to.
        margin: The verdict's practical-equivalence margin (``verdict.COST_MARGIN``).

    Returns:
        The tables, scenarios in run order, the suite-wide table last (when
        more than one scenario ran and the reference ran on every one).
    """
    index = {(str(r["policy"]), str(r["scenario"]), str(r["metric"])): r for r in rows}
    policies = list(dict.fromkeys(cell.policy for cell in cells))
    found_verdicts = verdicts(cells, reference, margin)
    judged = {(v.policy, v.scenario): v for v in found_verdicts}
    tables = []
    for name in dict.fromkeys(cell.scenario for cell in cells):
        table = _scenario_table(name, index, policies, reference, judged)
        if table is not None:
            tables.append(table)
    suite = _suite_table(index, cells, policies, reference, found_verdicts)
    return tables if suite is None else [*tables, suite]


def text(table: RankedTable) -> str:
    """A table as aligned plain text: its title, the columns, the best deployable policy."""
    body = [list(table.header), *table.rows]
    widths = [max(len(row[k]) for row in body) for k in range(len(table.header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in body]
    lines = [f"{table.title}:", *("  " + line.rstrip() for line in lines)]
    return "\n".join([*lines, f"  {table.best}"] if table.best else lines)


def legend(reference: str, margin: float = COST_MARGIN) -> str:
    """How to read the ranked tables' columns, one paragraph."""
    return (
        f"Ranked by mean cost (lower is better). / {reference}: mean cost over {reference}'s, "
        f"with the paired 95 % interval. score: ({reference} - policy) / ({reference} - "
        f"{HEADROOM_REFERENCE}) of the mean cost: 0 = {reference}, 1 = the headroom reference "
        f"{HEADROOM_REFERENCE} (privileged, not deployable); n/a: it did not run; no gap: it is "
        f"not better than {reference} there. verdict: against {reference}; 'equivalent': the "
        f"cost interval lies within +-{margin:.1%} of its mean (docs/benchmark.md)."
    )


def terminal_report(
    rows: Sequence[dict[str, object]],
    cells: Sequence[CellResult],
    reference: str,
    margin: float = COST_MARGIN,
) -> str:
    """Every ranked table as text, after a legend of the columns ('' without the reference)."""
    tables = ranked_tables(rows, cells, reference, margin)
    if not tables:
        return ""
    parts = [textwrap.fill(legend(reference, margin), width=100)]
    parts += [text(table) for table in tables]
    notes = regression_lines(cells, reference, margin)
    if notes:
        parts.append("\n".join(notes))
    return "\n\n".join(parts)


_STYLE = (
    "body{font-family:sans-serif;max-width:70em;margin:2em auto;padding:0 1em}"
    "table{border-collapse:collapse;margin:0.5em 0}"
    "th,td{border:1px solid #ccc;padding:0.2em 0.6em;text-align:left}"
    "th{background:#f0f0f0}img{max-width:100%}"
    "code{background:#f4f4f4}"
)


def _table(table: RankedTable) -> list[str]:
    lines = [f"<h3>{html.escape(table.title)}</h3>", "<table>"]
    lines.append("<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in table.header) + "</tr>")
    for row in table.rows:
        lines.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>")
    lines.append("</table>")
    if table.best:
        lines.append(f"<p><strong>{html.escape(table.best)}</strong></p>")
    return lines


def html_report(
    tables: Sequence[RankedTable],
    legend: str,
    command: str,
    notes: Sequence[str],
    figures: Mapping[str, bytes],
) -> str:
    """The page: command, legend, ranked tables (the suite-wide one first), notes, figures.

    Args:
        tables: The ranked tables (``ranked_tables``).
        legend: How to read the columns.
        command: The command line that regenerates the run.
        notes: Lines naming regressed guarded metrics.
        figures: File name -> PNG bytes, drawn in this order.

    Returns:
        The HTML text.
    """
    ordered = [t for t in tables if t.suite] + [t for t in tables if not t.suite]
    lines = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8"><title>cpf-bench report</title>',
        f"<style>{_STYLE}</style></head><body>",
        "<h1>cpf-bench report</h1>",
        f"<p>Regenerate with <code>{html.escape(command)}</code>. All numbers: "
        "summary.csv and episodes.csv beside this file.</p>",
        f"<p>{html.escape(legend)}</p>",
        "<h2>Ranked policies</h2>",
    ]
    for table in ordered:
        lines += _table(table)
    if notes:
        lines += ["<h2>Regressed guarded metrics</h2>", "<ul>"]
        lines += [f"<li>{html.escape(note.strip())}</li>" for note in notes]
        lines.append("</ul>")
    if figures:
        lines.append("<h2>Figures</h2>")
    for name, data in figures.items():
        encoded = base64.b64encode(data).decode("ascii")
        lines.append(f"<h3>{html.escape(name)}</h3>")
        lines.append(f'<img alt="{html.escape(name)}" src="data:image/png;base64,{encoded}">')
    lines.append("</body></html>")
    return "\n".join(lines) + "\n"
