"""How the ``oracle`` became a bound where vessels cross: its sampling and its barrier, varied.

Runs the ``oracle`` on the crossing scenarios (those with a separation) with
its path-rate samples partly per vessel (``vessel_rate_share`` 0.1, the
core suite's) or common to the fleet (0, its setting there), and its
feedback's barrier 0.2 m or 1 cm outside the collision distance
(``barrier_margin``; 1 cm is its setting), on the same ``test`` seeds, and
prints the mean whole-episode cost with the separation, position and sync
parts and the closest approach. Usage::

    python studies/hard_track/crossing_bound.py --num-seeds 3
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence

import numpy as np

from baselines import OraclePolicy
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.scenarios.suite import list_suite

#: label -> (vessel_rate_share, barrier_margin (m)).
VARIANTS = {
    "per-vessel rates, 0.2 m": (0.1, 0.2),
    "common rates, 0.2 m": (0.0, 0.2),
    "common rates, 1 cm (the oracle)": (0.0, 0.01),
}


def _oracle(share: float, margin: float) -> Callable[[object], OraclePolicy]:
    return lambda task: OraclePolicy(task, vessel_rate_share=share, barrier_margin=margin)


def main(argv: Sequence[str] | None = None) -> dict[tuple[str, str], float]:
    """Print and return (variant, scenario) -> mean cost."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=None)
    crossing = [n for n in list_suite("hard") if scenarios.get(n).separation is not None]
    parser.add_argument("--scenarios", nargs="+", default=crossing)
    args = parser.parse_args(argv)
    costs = {}
    print("| oracle | scenario | cost | separation | position | sync | closest (m) |")
    print("|---|---|---|---|---|---|---|")
    for label, (share, margin) in VARIANTS.items():
        cells = run_bench({label: _oracle(share, margin)}, args.scenarios,
                          num_seeds=args.num_seeds, max_steps=args.max_steps,
                          figures=False)  # fmt: skip
        for cell in cells:
            m = cell.metrics
            costs[(label, cell.scenario)] = float(np.mean(m["cost"]))
            print(
                f"| {label} | {cell.scenario} | {np.mean(m['cost']):.1f} | "
                f"{np.mean(m['cost_separation']):.1f} | {np.mean(m['cost_position']):.1f} | "
                f"{np.mean(m['cost_sync']):.1f} | {np.min(m['separation_min']):.2f} |"
            )
    return costs


if __name__ == "__main__":
    main()
