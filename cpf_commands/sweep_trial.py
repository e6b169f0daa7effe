"""One trial of a sweep, and the sweep's summary table.

A trial trains with exactly ``cpf-train``'s function (``agents.train``) into
``<out>/trials/<name>/`` (so ``agents.load_policy`` loads it), reports the
episodic cost to Ray Tune as it learns, then evaluates the agent against its
base policy on paired seeds with ``cpf-bench``'s machinery and writes
``evaluation.json``. A trial whose folder already holds ``evaluation.json`` is
finished: a resumed sweep reports it again without retraining. A trial that
was interrupted starts over (trials keep no mid-training checkpoints).

The summary has one row per trial and, over seeds, one row per scenario and
setting: the mean cost relative to the base policy and the number of trials
in which the agent beat it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from agents.training import TrainConfig, train
from cpf_commands.bench import BASE_SEED, run_bench
from cpf_commands.bench_report import summarize
from cpf_commands.sweep_spec import SweepSpec, trial_name

__all__ = ["EVALUATION_FILE", "evaluate_agent", "run_trial", "summary_markdown", "summary_rows"]

#: Written last in a trial's folder: the trial is finished when it exists.
EVALUATION_FILE = "evaluation.json"

#: Seconds between two progress reports of a trial to Ray Tune.
REPORT_PERIOD = 5.0


class _TuneReport(BaseCallback):
    """Report timesteps and the mean episodic cost to Ray Tune, at most every REPORT_PERIOD s."""

    def __init__(self) -> None:
        super().__init__()
        self._last = time.perf_counter()

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        if time.perf_counter() - self._last < REPORT_PERIOD or not self.model.ep_info_buffer:
            return
        from ray import tune

        cost = -float(np.mean([info["r"] for info in self.model.ep_info_buffer]))
        tune.report({"timesteps": int(self.model.num_timesteps), "episodic_cost": cost})
        self._last = time.perf_counter()


def evaluate_agent(
    folder: Path, config: TrainConfig, seeds: int, steps: int | None
) -> dict[str, Any]:
    """The trained agent in ``folder`` against its base policy on paired seeds.

    Args:
        folder: A trained agent's folder.
        config: Its training configuration.
        seeds: Evaluation episodes (seeds ``BASE_SEED + k``, as ``cpf-bench`` uses).
        steps: Horizon (None: the scenario's ``max_steps``).

    Returns:
        ``reference`` (the base policy; ``nn_dsc`` for an agent trained from
        scratch), ``cost`` and ``reference_cost`` (means), ``cost_ratio``,
        ``p_beats_reference`` (fraction of paired episodes with a lower cost),
        ``failures`` (episodes that left the path) and ``path_error_rms_window``.
    """
    reference = "nn_dsc" if config.base == "none" else config.base
    cells = run_bench(
        {"agent": folder, reference: reference}, [config.scenario], seeds=seeds, steps=steps
    )
    rows = summarize(cells, reference)
    by_metric = {row["metric"]: row for row in rows if row["policy"] == "agent"}
    base = {row["metric"]: row for row in rows if row["policy"] == reference}
    return {
        "reference": reference,
        "episodes": len(cells[0].seeds),
        "cost": by_metric["cost"]["mean"],
        "reference_cost": base["cost"]["mean"],
        "cost_ratio": by_metric["cost"]["normalized"],
        "p_beats_reference": by_metric["cost"]["p_beats_reference"],
        "failures": by_metric["cost"]["failures"],
        "path_error_rms_window": by_metric["path_error_rms_window"]["mean"],
        "reference_path_error_rms_window": base["path_error_rms_window"]["mean"],
    }


def run_trial(params: dict[str, Any], spec: SweepSpec, out: str) -> None:
    """Ray Tune trainable: train one trial's agent, evaluate it, report.

    Args:
        params: The trial's varying parameters (from the sweep's grid).
        spec: The sweep.
        out: The sweep's folder (absolute; shared by every node on a cluster).
    """
    from ray import tune

    folder = Path(out) / "trials" / trial_name(params, spec)
    done = folder / EVALUATION_FILE
    if done.exists():
        tune.report(json.loads(done.read_text()))
        return
    config = spec.config(params)
    if "torch_threads" not in spec.fixed and "torch_threads" not in spec.grid:
        config = spec.config({**params, "torch_threads": spec.cpus_per_trial})
    train(config, folder, progress=False, overwrite=True, callbacks=[_TuneReport()])
    record = json.loads((folder / "config.json").read_text())
    result: dict[str, Any] = {
        "trial": folder.name,
        "timesteps": record["timesteps_done"],
        "train_seconds": record["train_seconds"],
        "vessel_steps_per_second": record["vessel_steps_per_second"],
    }
    if spec.eval_seeds:
        start = time.perf_counter()
        result |= evaluate_agent(folder, config, spec.eval_seeds, spec.eval_steps)
        result["eval_seconds"] = time.perf_counter() - start
    done.write_text(json.dumps(result, indent=2) + "\n")
    tune.report(result)


_TRIAL_COLUMNS = (
    "trial",
    "status",
    "train_seconds",
    "vessel_steps_per_second",
    "episodes",
    "cost_ratio",
    "p_beats_reference",
    "failures",
    "path_error_rms_window",
)


def summary_rows(spec: SweepSpec, out: Path, errors: dict[str, str]) -> list[dict[str, Any]]:
    """One row per trial, from the trials' folders; ``errors`` maps trial -> error text."""
    rows = []
    for params in spec.trials():
        name = trial_name(params, spec)
        path = out / "trials" / name / EVALUATION_FILE
        row: dict[str, Any] = {**params, "trial": name}
        if path.exists():
            row |= json.loads(path.read_text()) | {"status": "done"}
        else:
            row["status"] = f"error: {errors[name]}" if name in errors else "not finished"
        rows.append(row)
    return rows


#: Number formats of the summary's columns (others: general, 4 significant digits).
_FORMATS = {"train_seconds": ".1f", "p_beats_reference": ".2f", "vessel_steps_per_second": ".0f"}


def _number(value: Any, column: str) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return format(value, ".4f" if "cost_ratio" in column else _FORMATS.get(column, ".4g"))
    return str(value)


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        cells = (_number(value, column) for value, column in zip(row, header, strict=True))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def summary_markdown(spec: SweepSpec, rows: Sequence[dict[str, Any]], command: str) -> str:
    """The sweep's summary: trials, then each scenario x setting over seeds."""
    lines = ["# Sweep summary", "", f"Command: `{command}`", ""]
    reference = next((row["reference"] for row in rows if "reference" in row), "the base")
    if spec.eval_seeds:
        lines.append(
            f"Evaluation: {spec.eval_seeds} paired episodes per trial against {reference} "
            f"(seeds from {BASE_SEED}; one where nothing in the scenario is random, see "
            "`episodes`); cost_ratio < 1 means the agent's cost is lower."
        )
    else:
        lines.append("Evaluation: none (--eval-seeds 0).")
    lines.append("")
    lines += _table(_TRIAL_COLUMNS, [[row.get(c) for c in _TRIAL_COLUMNS] for row in rows])
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        key = (row["scenario"], *(row[name] for name in spec.grid))
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
