"""One trial of a sweep: the Ray Tune trainable.

A trial trains with exactly ``cpf-train``'s function (``agents.train``) into
``<out>/trials/<name>/`` (so ``agents.load_policy`` loads it), reports the
episodic cost to Ray Tune as it learns, then evaluates the agent against its
base policy on paired validation seeds (``cpf_env.scenarios.splits.VALIDATION_SEED``
and up: a sweep chooses among its trials, and the benchmark's seeds play no
part in that choice) with ``cpf-bench``'s machinery and writes
``evaluation.json`` (``sweep_report``). A trial whose folder shows it
finished with the same configuration is reported again without retraining.
A trial that was interrupted starts over (trials keep no mid-training
checkpoints).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from agents.training.config import TrainConfig
from agents.training.trainer import train
from cpf_bench.report import summarize
from cpf_commands.bench.run import run_bench
from cpf_commands.sweep.report import trial_state, write_evaluation
from cpf_commands.sweep.spec import SweepSpec, trial_name
from cpf_env.scenarios.splits import VALIDATION_SEED

__all__ = ["evaluate_agent", "run_trial"]

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
    folder: Path, config: TrainConfig, num_seeds: int, max_steps: int | None
) -> dict[str, Any]:
    """The trained agent in ``folder`` against its base policy on paired seeds.

    Args:
        folder: A trained agent's folder.
        config: Its training configuration.
        num_seeds: Evaluation episodes (seeds ``VALIDATION_SEED + k``).
        max_steps: Horizon (None: the scenario's ``max_steps``).

    Returns:
        ``reference`` (the base policy; ``nn_dsc`` for an agent trained from
        scratch), ``seed`` (the first of the paired seeds), ``episodes`` (run per
        policy: 1 on a scenario in which nothing is random), ``cost`` and
        ``reference_cost`` (mean episodic costs: minus the sum over steps of the
        fleet-mean reward),
        ``cost_ratio`` (agent / reference),
        ``p_beats_reference`` (fraction of paired episodes with a lower cost),
        ``failures`` (agent episodes that left the path), and
        ``path_error_rms_window`` / ``reference_path_error_rms_window`` (mean
        RMS path error over the final quarter of the horizon, m).
    """
    reference = "nn_dsc" if config.base_policy == "none" else config.base_policy
    policies: dict[str, str | Path] = {"agent": folder, reference: reference}
    cells = run_bench(policies, list(config.scenarios), num_seeds, VALIDATION_SEED, max_steps)
    rows = summarize(cells, reference)
    by_metric = {row["metric"]: row for row in rows if row["policy"] == "agent"}
    base = {row["metric"]: row for row in rows if row["policy"] == reference}
    return {
        "reference": reference,
        "seed": VALIDATION_SEED,
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
    config = spec.config(params)
    state, record = trial_state(folder, config)
    if state == "done":
        tune.report(record)
        return
    # A new folder replaces the old one whole once the agent is written (nothing of an
    # earlier agent is left to mix in); killed before, the old folder stays, unfinished.
    train(config, folder, progress=False, overwrite=True, callbacks=[_TuneReport()])
    record = json.loads((folder / "config.json").read_text())
    result: dict[str, Any] = {
        "trial": folder.name,
        "timesteps": record["timesteps_done"],
        "train_seconds": record["train_seconds"],
        "vessel_steps_per_second": record["vessel_steps_per_second"],
    }
    if spec.eval_num_seeds:
        start = time.perf_counter()
        result |= evaluate_agent(folder, config, spec.eval_num_seeds, spec.eval_max_steps)
        result["eval_seconds"] = time.perf_counter() - start
    write_evaluation(folder, result)
    tune.report(result)
