"""How the ``oracle`` became a bound where vessels cross: its view, its sampling and its barrier.

Runs the ``oracle`` on the crossing scenarios (those with a separation) with
the 10 s view of the core suite (``tail`` 8 s after its 2 s plan) or the
whole episode (its setting there), its path-rate samples partly per vessel
(``vessel_rate_share`` 0.1, the core suite's) or common to the fleet (0, its
setting there), and its feedback's barrier 0.2 m or 1 cm outside the
collision distance (``barrier_margin``; 1 cm is its setting), on the same
``test`` seeds, and prints the mean whole-episode cost with the separation,
position and sync parts, the progress and the closest approach. Usage::

    python studies/hard_track/crossing_bound.py --num-seeds 3
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from baselines import OraclePolicy
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.scenarios.suite import list_suite

#: label -> the options that differ from the oracle's settings where vessels cross.
VARIANTS: dict[str, dict[str, Any]] = {
    "10 s view": {"tail": 8.0},
    "per-vessel rates": {"vessel_rate_share": 0.1},
    "barrier 0.2 m": {"barrier_margin": 0.2},
    "the oracle": {},
}


def _oracle(options: dict[str, Any]) -> Callable[[object], OraclePolicy]:
    return lambda task: OraclePolicy(task, **options)


def main(argv: Sequence[str] | None = None) -> dict[tuple[str, str], float]:
    """Print and return (variant, scenario) -> mean cost."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=None)
    crossing = [n for n in list_suite("hard") if scenarios.get(n).separation is not None]
    parser.add_argument("--scenarios", nargs="+", default=crossing)
    args = parser.parse_args(argv)
    costs = {}
    print("| oracle | scenario | cost | separation | position | sync | progress | closest (m) |")
    print("|---|---|---|---|---|---|---|---|")
    for label, options in VARIANTS.items():
        cells = run_bench({label: _oracle(options)}, args.scenarios,
                          num_seeds=args.num_seeds, max_steps=args.max_steps,
                          figures=False)  # fmt: skip
        for cell in cells:
            m = cell.metrics
            costs[(label, cell.scenario)] = float(np.mean(m["cost"]))
            print(
                f"| {label} | {cell.scenario} | {np.mean(m['cost']):.1f} | "
                f"{np.mean(m['cost_separation']):.1f} | {np.mean(m['cost_position']):.1f} | "
                f"{np.mean(m['cost_sync']):.1f} | {np.mean(m['progress']):.2f} | "
                f"{np.min(m['separation_min']):.2f} |"
            )
    return costs


if __name__ == "__main__":
    main()
