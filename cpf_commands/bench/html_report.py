"""``report.html``: the bench's answer and figures in one self-contained page.

The ranked tables of ``cpf_commands.bench.ranking`` as HTML tables, the
regressed guarded metrics, and every figure inline as a base64 PNG, so the
file opens in any browser with nothing beside it. No time stamp or path: the
same run gives the same bytes.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Mapping, Sequence

from cpf_commands.bench.ranking import RankedTable

__all__ = ["html_report"]

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
        tables: The ranked tables (``ranking.ranked_tables``).
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
