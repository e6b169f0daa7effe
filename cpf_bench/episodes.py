"""Batched evaluation episodes of ``cpf-bench`` and their per-episode metrics.

``run_episodes`` runs one policy on one scenario for S paired seeds through
the commands' one rollout (``cpf_bench.rollout``) and returns the
metrics of ``cpf_env.evaluation.fleet_metrics`` (``METRICS``), the same numbers
``cpf-run`` reports. ``docs/benchmark.md`` defines every metric.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from cpf_bench.rollout import rollout
from cpf_env.envs.policy import FleetPolicy
from cpf_env.evaluation.fleet_metrics import METRICS, WINDOW_FRACTION
from cpf_env.scenarios import Scenario

__all__ = ["METRICS", "WINDOW_FRACTION", "run_episodes"]


def run_episodes(
    policy: FleetPolicy,
    scenario: Scenario,
    seeds: Sequence[int],
    max_steps: int | None = None,
    progress: tqdm | None = None,
) -> dict[str, NDArray[np.float64]]:
    """Run S episodes of ``policy`` on ``scenario`` in one batch and measure each.

    Args:
        policy: A policy built for ``scenario`` (reset here).
        scenario: The task.
        seeds: Reset seed of each fleet, length S.
        max_steps: Horizon in control steps (default: the scenario's ``max_steps``).
        progress: A progress bar advanced by one per step, or None.

    Returns:
        Metric name (``METRICS``) -> values, shape (S,).
    """
    return rollout(policy, scenario, seeds, max_steps=max_steps, progress=progress)
