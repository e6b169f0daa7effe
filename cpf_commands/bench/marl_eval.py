"""Export a benchmark run in marl-eval's JSON format (``cpf-bench --marl-eval FILE``).

marl-eval (InstaDeep) and BenchMARL read a nested dictionary

    {env_name: {task_name: {algorithm: {"seed_<k>": {"absolute_metrics": {metric: [value]}}}}}}

here with env ``cpf_env``, one task per scenario, one algorithm per policy
label and one ``seed_<k>`` per evaluation seed; every metric of
``episodes.csv`` goes into ``absolute_metrics`` as a one-element list (one
evaluation episode per seed). marl-eval's convention is higher is better,
so the cost is also given as ``return`` (its negation), which the episode
records already carry.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

from cpf_bench.report import CellResult
from cpf_env.infra import atomic

__all__ = ["ENV_NAME", "marl_eval_dict", "write_marl_eval"]

ENV_NAME = "cpf_env"


def marl_eval_dict(cells: Sequence[CellResult]) -> dict[str, object]:
    """The nested marl-eval dictionary of ``cells`` (NaN metrics left out)."""
    tasks: dict[str, dict[str, dict[str, object]]] = {}
    for cell in cells:
        runs: dict[str, object] = {}
        for k, seed in enumerate(cell.seeds):
            metrics = {
                name: [float(values[k])]
                for name, values in cell.metrics.items()
                if not math.isnan(float(values[k]))
            }
            runs[f"seed_{seed}"] = {"absolute_metrics": metrics}
        tasks.setdefault(cell.scenario, {})[cell.policy] = runs
    return {ENV_NAME: tasks}


def write_marl_eval(cells: Sequence[CellResult], path: str | Path) -> None:
    """Write ``marl_eval_dict(cells)`` as JSON to ``path`` atomically (``cpf_env.infra.atomic``)."""
    atomic.write_text(path, json.dumps(marl_eval_dict(cells), indent=1, sort_keys=True) + "\n")
