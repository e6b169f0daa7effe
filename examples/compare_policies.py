"""Compare the analytic policies (the paper's controller, its ablations, backstepping).

Runs every policy on every named scenario (or the ones given) for one seed
and prints a markdown table of steady-state metrics over the last quarter of
each episode: what each contribution of the paper is worth, scenario by
scenario.

Usage::

    python examples/compare_policies.py [--scenarios wang2014 saturation_heavy] [--steps N]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from baselines import POLICIES
from cpf_commands.experiment import run_episode
from cpf_env import scenarios
from cpf_env.metrics import episode_metrics

COLUMNS = (
    "scenario",
    "policy",
    "path err max (m)",
    "path err rms (m)",
    "max abs(theta_i - theta_j)",
    "max abs(vhat - v0) (m/s)",
    "saturated steps",
    "return",
)


def compare(
    scenario_names: Sequence[str] | None = None,
    policies: Sequence[str] | None = None,
    seed: int = 0,
    steps: int | None = None,
) -> list[tuple[object, ...]]:
    """One row per (scenario, policy): the metrics of ``COLUMNS``."""
    rows = []
    for name in scenario_names or scenarios.list_scenarios():
        for policy in policies or list(POLICIES):
            metrics = episode_metrics(run_episode(name, policy, seed=seed, steps=steps))
            speed = metrics.get("speed_estimate_error_max", [float("nan")])
            rows.append((
                name,
                policy,
                max(metrics["path_error_max"]),
                max(metrics["path_error_rms"]),
                metrics["coordination_error_max"],
                max(speed),
                float(np.mean(metrics["saturated_fraction"])),
                metrics["return_mean"],
            ))  # fmt: skip
    return rows


def main(argv: Sequence[str] | None = None) -> list[tuple[object, ...]]:
    """Parse arguments, run the comparison, print the table, and return its rows."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=None, choices=scenarios.list_scenarios())
    parser.add_argument("--policies", nargs="+", default=None, choices=sorted(POLICIES))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None)
    args = parser.parse_args(argv)
    rows = compare(args.scenarios, args.policies, args.seed, args.steps)
    print("| " + " | ".join(COLUMNS) + " |")
    print("|" + "---|" * len(COLUMNS))
    for row in rows:
        cells = [f"{x:.3g}" if isinstance(x, float) else str(x) for x in row]
        print("| " + " | ".join(cells) + " |")
    return rows


if __name__ == "__main__":
    main()
