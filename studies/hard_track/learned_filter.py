"""The learned filter's learning curve: validation cost against the data it was fitted on.

Gathers ``--num-seeds`` training episodes of the base (``cpf-fit-filter``'s
``agents.estimation.fit.gather``, one episode at a time, timed), fits the
correction on the first k of them for k = 1, 2, 4, ... and runs each fitted
filter, with the base and ``nn_dsc``, on ``--eval-num-seeds`` validation seeds
(paired), and prints per k the vessel-steps, the wall time of gathering and
fitting them, the mean cost and its paired difference from the base, so the
data (and time) it takes to beat ``nn_dsc`` and the base can be read off. Usage::

    python studies/hard_track/learned_filter.py --scenario hard_sensing --num-seeds 16
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np

from agents.estimation.correction import fit
from agents.estimation.fit import RIDGE, gather
from agents.estimation.policy import WINDOW, LearnedFilter
from baselines import make_policy
from cpf_bench.rollout import rollout_group
from cpf_bench.stats import paired_difference
from cpf_env.scenarios import make_scenario
from cpf_env.scenarios.splits import VALIDATION_SEED


def main(argv: Sequence[str] | None = None) -> list[tuple[int, float]]:
    """Print and return (episodes, mean validation cost) per fit."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="hard_sensing")
    parser.add_argument("--num-seeds", type=int, default=16, help="training episodes, at most")
    parser.add_argument("--eval-num-seeds", type=int, default=10)
    parser.add_argument("--base", default="mpc_tuned_mmae")
    parser.add_argument("--max-steps", type=int, default=None, help="default: the scenario's")
    args = parser.parse_args(argv)
    task = make_scenario(args.scenario)
    if args.max_steps is not None:
        task = task.replace(max_steps=args.max_steps)
    parts, seconds = [], []
    start = time.perf_counter()
    for seed in range(args.num_seeds):
        parts.append(gather(task, [seed], args.base, WINDOW))
        seconds.append(time.perf_counter() - start)
    sizes = [k for k in (1, 2, 4, 8, 16, 32, 64) if k <= args.num_seeds]
    filters = []
    for k in sizes:
        inputs = np.concatenate([p[0] for p in parts[:k]])
        errors = np.concatenate([p[1] for p in parts[:k]])
        filters.append(LearnedFilter(task, fit(inputs, errors, WINDOW, RIDGE), base=args.base))
    seeds = [VALIDATION_SEED + k for k in range(args.eval_num_seeds)]
    reference, base, *fitted = rollout_group(
        [make_policy("nn_dsc", task), LearnedFilter(task, None, base=args.base), *filters],
        task,
        seeds,
    )
    steps = task.n * (task.max_steps - WINDOW)
    print(
        f"{args.scenario}, validation seeds {seeds[0]}-{seeds[-1]}: nn_dsc "
        f"{np.mean(reference['cost']):.1f}, {args.base} {np.mean(base['cost']):.1f}\n"
    )
    print("| episodes | vessel-steps | gathered in (s) | cost | minus the base's (95 % interval) |")
    print("|---|---|---|---|---|")
    rows = []
    for k, metrics in zip(sizes, fitted, strict=True):
        mean, low, high = paired_difference(metrics["cost"], base["cost"])
        rows.append((k, float(np.mean(metrics["cost"]))))
        print(
            f"| {k} | {k * steps:,} | {seconds[k - 1]:.0f} | {np.mean(metrics['cost']):.1f} | "
            f"{mean:+.1f} ({low:+.1f} to {high:+.1f}) |"
        )
    return rows


if __name__ == "__main__":
    main()
