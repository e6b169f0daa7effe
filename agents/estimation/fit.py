"""Fit a ``LearnedFilter``: closed-loop episodes of its base, then least squares.

``gather`` runs the base design (a ``LearnedFilter`` without a correction,
so the history is kept exactly as the fitted filter will keep it) on
training seeds of each scenario and records, every step after the first
``window``, each vessel's inputs and its filter's error against the true
state the simulator holds. ``fit_filter`` gathers, fits the ridge
regression (``correction.fit``) and measures the base and the fitted
filter on the validation seeds (``cpf_env.scenarios.splits``), paired by
seed; ``agents.estimation.folder`` writes what it fitted.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.estimation.correction import TARGET_SIZE, Correction, assemble, body_error, fit
from agents.estimation.policy import WINDOW, LearnedFilter
from cpf_bench.rollout import rollout_group
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.scenarios.splits import VALIDATION_SEED, check_training
from cpf_env.sim.fleet import FleetSim

__all__ = ["RIDGE", "fit_filter", "gather"]

Array = NDArray[np.float64]

#: The ridge penalty per sample on the standardized weights.
RIDGE = 1e-3


def gather(
    scenario: str | Scenario, seeds: Sequence[int], base: str, window: int
) -> tuple[Array, Array]:
    """Inputs (N, D) and errors (N, 6) of the base's filter on ``scenario``'s ``seeds``.

    Every step from the ``window``-th on, every vessel of every fleet still running (a
    fleet whose episode failed is left out from then on).
    """
    check_training(scenario, seeds)
    task = make_scenario(scenario)
    policy = LearnedFilter(task, None, base=base, window=window)
    sim = FleetSim(task, num_fleets=len(seeds))
    obs = sim.reset(seeds=list(seeds))
    inputs, errors = [], []
    for step in range(task.max_steps):
        actions = policy.act_batch(obs)
        alive = ~sim.arrays.terminated  # a fleet that failed is not stepped on
        if step >= window and alive.any():
            states = policy.base.state[alive]
            history = policy.history_inputs()[alive]
            seen = assemble(history, states)
            inputs.append(seen.reshape(-1, seen.shape[-1]))
            truth = body_error(states, sim.arrays.eta[alive], sim.arrays.nu[alive])
            errors.append(truth.reshape(-1, TARGET_SIZE))
        obs = sim.step(actions)
    return np.concatenate(inputs), np.concatenate(errors)


def fit_filter(
    scenarios: Sequence[str | Scenario],
    num_seeds: int,
    base: str = "mpc_tuned_mmae",
    window: int = WINDOW,
    ridge: float = RIDGE,
    eval_num_seeds: int = 10,
    seed: int = 0,
) -> tuple[Correction, dict[str, Any]]:
    """Gather ``num_seeds`` episodes per scenario from training seed ``seed``, fit, validate.

    Returns:
        The correction and the record: the settings, the samples, the error's RMS
        before and after on the training data, and per scenario the validation
        seeds' mean cost of the base and of the fitted filter.
    """
    start = time.perf_counter()
    seeds = list(range(seed, seed + num_seeds))
    tasks = [make_scenario(s) for s in scenarios]
    parts = [gather(task, seeds, base, window) for task in tasks]
    inputs = np.concatenate([p[0] for p in parts])
    errors = np.concatenate([p[1] for p in parts])
    correction = fit(inputs, errors, window, ridge)
    left = errors - correction.apply(inputs)
    validation: dict[str, dict[str, float]] = {}
    checks = [VALIDATION_SEED + k for k in range(eval_num_seeds)]
    for task in tasks if eval_num_seeds > 0 else []:
        alone, fitted = rollout_group(
            [LearnedFilter(task, None, base=base), LearnedFilter(task, correction, base=base)],
            task,
            checks,
        )
        validation[task.name] = {
            "base": float(np.mean(alone["cost"])),
            "filter": float(np.mean(fitted["cost"])),
        }
    record = {
        "base": base,
        "scenarios": [task.name for task in tasks],
        "seeds": seeds,
        "window": window,
        "ridge": ridge,
        "samples": len(inputs),
        "error_rms": np.sqrt(np.mean(errors**2, axis=0)).tolist(),
        "error_rms_fitted": np.sqrt(np.mean(left**2, axis=0)).tolist(),
        "validation_seeds": checks,
        "validation": validation,
        "seconds": time.perf_counter() - start,
    }
    return correction, record
