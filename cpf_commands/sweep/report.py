"""What a sweep's trials left on disk, and the sweep's summary (``summary.md``, ``summary.csv``).

A trial is finished when its folder holds ``evaluation.json`` (written last,
atomically) and its ``config.json`` records the configuration the sweep
would train it with now. A trial folder trained with another configuration
is never mixed into the summary: it is reported as stale, and the next run
of the sweep trains it again.

The summary has one row per trial and, over seeds, one row per scenario and
setting: the mean cost relative to the base policy and the number of trials
in which the agent beat it.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.training.config import TrainConfig
from cpf_commands.bench.views import markdown_table
from cpf_commands.sweep.spec import SweepSpec, trial_name
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import VALIDATION_SEED

__all__ = [
    "EVALUATION_FILE",
    "summary_csv",
    "summary_markdown",
    "summary_rows",
    "trial_state",
    "write_evaluation",
]

#: Written last in a trial's folder: the trial is finished when it exists.
EVALUATION_FILE = "evaluation.json"


def _read_json(path: Path) -> dict[str, Any] | None:
    """The JSON object in ``path``; None if it is missing or unreadable (a cut-off write)."""
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def write_evaluation(folder: Path, record: dict[str, Any]) -> None:
    """Write a trial's ``evaluation.json`` atomically (a reader sees all of it or nothing)."""
    atomic.write_text(folder / EVALUATION_FILE, json.dumps(record, indent=2) + "\n")


def trial_state(folder: Path, config: TrainConfig) -> tuple[str, dict[str, Any]]:
    """A trial folder's state and its evaluation record.

    Returns:
        ("done", record) if the trial finished with ``config`` and was evaluated on
        the validation seeds; ("stale", record) if it finished with another
        configuration or was evaluated on other seeds (a record without ``seed``:
        the test seeds, before the validation seeds); ("missing", {}) if it has
        not finished.
    """
    record = _read_json(folder / EVALUATION_FILE)
    if record is None:
        return "missing", {}
    saved = _read_json(folder / "config.json") or {}
    wanted = json.loads(json.dumps(config.to_json()))  # as config.json holds it: lists
    evaluated = "cost" in record  # a trial of a sweep without evaluation has no seed
    current = saved.get("config") == wanted and (
        not evaluated or record.get("seed") == VALIDATION_SEED
    )
    return ("done" if current else "stale"), record


def summary_rows(spec: SweepSpec, out: Path, errors: dict[str, str]) -> list[dict[str, Any]]:
    """One row per trial, from the trials' folders; ``errors`` maps trial -> error text."""
    rows = []
    for params in spec.trials():
        name = trial_name(params, spec)
        state, record = trial_state(out / "trials" / name, spec.config(params))
        row: dict[str, Any] = {**params, "trial": name}
        if state == "done":
            row |= record | {"status": "done"}
        elif state == "stale":
            row["status"] = (
                "stale: trained with another configuration or evaluated on other seeds; the "
                "next run of the sweep trains it again"
            )
        else:
            row["status"] = f"error: {errors[name]}" if name in errors else "not finished"
        rows.append(row)
    return rows


_TRIAL_COLUMNS = (
    "trial",
    "status",
    "train_seconds",
    "vessel_steps_per_second",
    "reference",
    "episodes",
    "cost_ratio",
    "p_beats_reference",
    "failures",
    "path_error_rms_window",
)

#: Number formats of the summary's columns (others: general, 4 significant digits).
_FORMATS = {"train_seconds": ".1f", "p_beats_reference": ".2f", "vessel_steps_per_second": ".0f"}


def _number(value: Any, column: str) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return format(value, ".4f" if "cost_ratio" in column else _FORMATS.get(column, ".4g"))
    return str(value)


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """A markdown table of values, each formatted for its column."""
    body = [
        [_number(value, column) for value, column in zip(row, header, strict=True)] for row in rows
    ]
    return markdown_table(header, body)


def _setting(value: Any) -> Any:
    """A grid value as the summary shows it (None, a valid setting, as 'none')."""
    return "none" if value is None else value


def summary_markdown(spec: SweepSpec, rows: Sequence[dict[str, Any]], command: str) -> str:
    """The sweep's summary: trials, then each scenario x setting over seeds."""
    lines = ["# Sweep summary", "", f"Command: `{command}`", ""]
    references = sorted({row["reference"] for row in rows if "reference" in row})
    if spec.eval_num_seeds:
        lines.append(
            f"Evaluation: {spec.eval_num_seeds} paired episodes per trial (validation seeds "
            f"from {VALIDATION_SEED}) against the trial's base policy, or nn_dsc for an agent "
            "trained from scratch "
            f"(here: {', '.join(references) or 'no trial finished yet'}); a scenario in which "
            "nothing is random runs one episode (`episodes`). cost_ratio < 1: the agent's "
            "cost is lower."
        )
    else:
        lines.append("Evaluation: none (--eval-num-seeds 0).")
    lines.append("")
    lines += _table(_TRIAL_COLUMNS, [[row.get(c) for c in _TRIAL_COLUMNS] for row in rows])
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        key = (row["scenario"], *(_setting(row[name]) for name in spec.grid))
        groups.setdefault(key, []).append(row)
    header = [
        "scenario",
        *spec.grid,
        "trials done",
        "cost_ratio mean",
        "cost_ratio min",
        "cost_ratio max",
        "beat ref",
    ]
    table = []
    for key, members in groups.items():
        ratios = [m["cost_ratio"] for m in members if m.get("cost_ratio") is not None]
        beat = sum(1 for ratio in ratios if ratio < 1.0)
        stats = [float(np.mean(ratios)), min(ratios), max(ratios)] if ratios else [None] * 3
        done = sum(1 for m in members if m["status"] == "done")
        table.append([*key, f"{done}/{len(members)}", *stats, f"{beat}/{len(ratios)}"])
    lines += ["", "Over seeds:", "", *_table(header, table), ""]
    return "\n".join(lines)


def summary_csv(rows: Sequence[dict[str, Any]]) -> str:
    """``summary.csv``: one row per trial, every key any row has as a column."""
    columns: list[str] = []
    for row in rows:
        columns += [key for key in row if key not in columns]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()
