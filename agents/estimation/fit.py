"""Fit a ``LearnedFilter``: closed-loop episodes, least squares, and again on its own episodes.

``gather`` runs a ``LearnedFilter`` on training seeds of a scenario and
records, every step after the first ``window``, each vessel's inputs
(``correction.assemble``) and its base filter's error against the true state
the simulator holds. ``fit_filter`` fits in rounds, as DAgger does (Ross et
al. 2011): round 0 gathers under the base alone (``Correction.zero``), each
later round under the filter fitted so far, on fresh training seeds, and
every round refits the ridge regression (``correction.fit``) and, with
hidden layers, the network on what it leaves (``network.fit_network``) on
all the data so far. The rounds matter because the correction acts in the
loop: it moves the vessels, so the forces and fix offsets its inputs read
are not those of the base's episodes (on ``hard_sensing``'s validation
seeds the network fitted on the base's episodes alone costs 91.9-93.5, and
88.0-89.7 after three more rounds on its own; docs/findings). With
validation seeds (``eval_num_seeds``), the base and each round's filter are
measured on them (``EvaluationLog``: the rows of ``evaluations.csv`` that
``cpf-curves`` reads); ``agents.estimation.folder`` writes what it fitted.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.estimation.correction import (
    CHUNK,
    TARGET_SIZE,
    Correction,
    assemble,
    body_error,
    fit,
    input_size,
)
from agents.estimation.folder import save_filter
from agents.estimation.network import EPOCHS, HIDDEN, fit_network
from agents.estimation.policy import WINDOW, LearnedFilter, bank_size
from agents.training.evaluation import ValidationEvaluator
from agents.training.schedule import EvaluationLog
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.scenarios.splits import check_training
from cpf_env.sim.fleet import FleetSim

__all__ = ["RIDGE", "ROUNDS", "Gathered", "fit_filter", "gather"]

Array = NDArray[np.float64]

#: The ridge penalty per sample on the standardized weights.
RIDGE = 1e-3
#: Rounds of gathering and fitting (the first under the base alone).
ROUNDS = 4

#: (inputs (N, D), errors (N, 6), simulated vessel-steps) of one gathering.
Gathered = tuple[Array, Array, int]


def gather(
    scenario: str | Scenario, seeds: Sequence[int], base: str, correction: Correction
) -> Gathered:
    """Inputs, errors and simulated vessel-steps of ``correction`` on ``scenario``'s ``seeds``.

    Every step from the ``window``-th on, every vessel of every fleet still running (a
    fleet whose episode failed is left out from then on).
    """
    check_training(scenario, seeds)
    task = make_scenario(scenario)
    policy = LearnedFilter(task, correction, base=base)
    sim = FleetSim(task, num_fleets=len(seeds))
    obs = sim.reset(seeds=list(seeds))
    inputs, errors, simulated = [], [], 0
    for step in range(task.max_steps):
        actions = policy.act_batch(obs)
        alive = ~sim.arrays.terminated  # a fleet that failed is not stepped on
        simulated += int(alive.sum()) * task.n
        if step >= correction.window and alive.any():
            states = policy.base.state[alive]
            seen = assemble(policy.history_inputs()[alive], states, policy.base.members[alive])
            inputs.append(seen.reshape(-1, seen.shape[-1]))
            truth = body_error(states, sim.arrays.eta[alive], sim.arrays.nu[alive])
            errors.append(truth.reshape(-1, TARGET_SIZE))
        obs = sim.step(actions)
    return np.concatenate(inputs), np.concatenate(errors), simulated


def fit_filter(
    scenarios: Sequence[str],
    num_seeds: int,
    base: str = "mpc_tuned_mmae",
    window: int = WINDOW,
    ridge: float = RIDGE,
    rounds: int = ROUNDS,
    hidden: tuple[int, ...] = HIDDEN,
    epochs: int = EPOCHS,
    eval_num_seeds: int = 10,
    seed: int = 0,
    max_steps: int | None = None,
    device: str = "cpu",
    report: Callable[[str], None] | None = None,
) -> tuple[Correction, dict[str, Any], list[dict[str, float]]]:
    """Fit in ``rounds`` of ``num_seeds`` episodes per scenario each, from training seed ``seed``.

    Round r runs training seeds ``seed + r * num_seeds`` on (module docstring); its
    network (none for ``hidden = ()``) trains ``epochs`` passes from seed ``seed + r``.
    ``max_steps`` shortens every episode, gathered and validated (None: each
    scenario's own); ``device`` trains the network (``network.fit_network``); ``report`` is
    handed a line per round (``print``: progress).

    Returns:
        The correction; the record (the settings, the validation's (``evaluation``:
        ``ValidationEvaluator.settings``, None without), the samples, the error's RMS
        before and after on all the data, each round's samples, vessel-steps and
        seconds, and per scenario the validation cost of the base and of the last
        round's filter); and the evaluations' rows (``EvaluationLog.rows``: the base at 0
        vessel-steps, then each round; empty without validation seeds).

    Raises:
        ValueError: A setting out of range, a held-out scenario or seed.
    """
    if rounds < 1 or num_seeds < 1 or window < 1 or epochs < 1:
        raise ValueError(
            f"rounds, num_seeds, window and epochs must be >= 1, got {rounds}, {num_seeds}, "
            f"{window}, {epochs}."
        )
    if any(width < 1 for width in hidden):
        raise ValueError(f"the network's hidden widths must be >= 1, got {list(hidden)}.")
    tasks = [make_scenario(s) for s in scenarios]
    if max_steps is not None:
        tasks = [task.replace(max_steps=max_steps) for task in tasks]
    for task in tasks:
        check_training(task, range(seed, seed + rounds * num_seeds))
        if task.max_steps <= window:
            raise ValueError(
                f"{task.name}'s episodes of {task.max_steps} steps end before the window of "
                f"{window} fills: give longer episodes or a shorter window."
            )
    members = bank_size(base)
    start = time.perf_counter()
    evaluator = (
        ValidationEvaluator([t.name for t in tasks], eval_num_seeds, max_steps)
        if eval_num_seeds > 0
        else None
    )
    log = None if evaluator is None else EvaluationLog(evaluator, best=None)

    def evaluate(correction: Correction, vessel_steps: int) -> None:
        """One row of the log: ``correction`` on the validation seeds, as a folder."""
        if log is None:
            return
        settings = {"base": base, "scenarios": [t.name for t in tasks], "window": window}

        def write(folder: Path) -> None:
            save_filter(folder, correction, {**settings, "members": members})

        log.run(write, vessel_steps, lambda: time.perf_counter() - start)

    correction = Correction.zero(window, members)
    evaluate(correction, 0)
    inputs = np.empty((0, input_size(window, members)))
    errors = np.empty((0, TARGET_SIZE))
    vessel_steps = 0
    history = []
    for r in range(rounds):
        seeds = list(range(seed + r * num_seeds, seed + (r + 1) * num_seeds))
        for task in tasks:  # the samples of every round so far, in one array (no second copy)
            more_inputs, more_errors, simulated = gather(task, seeds, base, correction)
            inputs = np.concatenate([inputs, more_inputs])
            errors = np.concatenate([errors, more_errors])
            vessel_steps += simulated
            del more_inputs, more_errors
        correction = fit(inputs, errors, window, members, ridge)
        if hidden:
            correction = fit_network(
                inputs, errors, correction, hidden, epochs, seed + r, device=device
            )
        history.append(
            {
                "round": r,
                "seeds": seeds,
                "samples": len(inputs),
                "vessel_steps": vessel_steps,
                "seconds": round(time.perf_counter() - start, 1),
            }
        )
        evaluate(correction, vessel_steps)
        if report is not None:
            cost = "" if log is None else f", validation cost {log.rows[-1]['mean_cost']:.1f}"
            report(
                f"round {r}: {len(inputs):,} samples from {vessel_steps:,} vessel-steps{cost} "
                f"({time.perf_counter() - start:.0f} s)"
            )
    left = errors - np.concatenate(
        [correction.apply(inputs[k : k + CHUNK]) for k in range(0, len(inputs), CHUNK)]
    )
    rows = [] if log is None else list(log.rows)
    record = {
        "base": base,
        "scenarios": [task.name for task in tasks],
        "window": window,
        "members": members,
        "ridge": ridge,
        "hidden": list(hidden),
        "epochs": epochs,
        "device": device,
        "rounds": history,
        "samples": len(inputs),
        "error_rms": np.sqrt(np.mean(errors**2, axis=0)).tolist(),
        "error_rms_fitted": np.sqrt(np.mean(left**2, axis=0)).tolist(),
        "evaluation": None if evaluator is None else evaluator.settings,
        "validation": {
            task.name: {
                "base": rows[0][f"cost_{task.name}"],
                "filter": rows[-1][f"cost_{task.name}"],
            }
            for task in (tasks if rows else [])
        },
        "seconds": round(time.perf_counter() - start, 1),
    }
    return correction, record, rows
