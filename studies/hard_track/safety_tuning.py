"""How far the safety filter should keep the hulls apart: its barrier distance and gains swept.

Runs ``mpc_tuned_safe`` (``baselines.safety``) with each barrier distance d_b
and gain k = k1 = k2 on training seeds of ``hard_crossing`` (below the
evaluation seeds, so the choice does not see the test split) and prints the
mean whole-episode cost, its separation and position parts, the closest
approach and the collisions. The defaults (``baselines.barrier``'s
``BARRIER_MARGIN`` and ``BARRIER_GAINS``) were chosen from this table. Usage::

    python studies/hard_track/safety_tuning.py --num-seeds 6
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence

import numpy as np

from baselines.safety import MPCTunedSafe
from cpf_commands.bench.run import run_bench


def _policy(distance: float, gain: float) -> Callable[[object], MPCTunedSafe]:
    return lambda task: MPCTunedSafe(task, barrier_distance=distance, barrier_gains=(gain, gain))


def main(argv: Sequence[str] | None = None) -> list[tuple[float, float, float]]:
    """Print and return (d_b, k, mean cost) per setting."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0, help="first training seed")
    parser.add_argument("--distances", type=float, nargs="+", default=[0.6, 0.7, 0.8, 0.9])
    parser.add_argument("--gains", type=float, nargs="+", default=[0.25, 0.5, 1.0])
    parser.add_argument("--max-steps", type=int, default=None)
    args = parser.parse_args(argv)
    rows = []
    print("| d_b (m) | k (1/s) | cost | separation | position | closest (m) | collisions |")
    print("|---|---|---|---|---|---|---|")
    for distance in args.distances:
        for gain in args.gains:
            (cell,) = run_bench(
                {f"mpc_tuned_safe_d{distance}_k{gain}": _policy(distance, gain)},
                ["hard_crossing"],
                num_seeds=args.num_seeds,
                seed=args.seed,
                max_steps=args.max_steps,
                figures=False,
            )
            m = cell.metrics
            rows.append((distance, gain, float(np.mean(m["cost"]))))
            print(
                f"| {distance} | {gain} | {np.mean(m['cost']):.1f} | "
                f"{np.mean(m['cost_separation']):.1f} | {np.mean(m['cost_position']):.1f} | "
                f"{np.min(m['separation_min']):.2f} | {int(np.sum(m['terminated']))} |"
            )
    return rows


if __name__ == "__main__":
    main()
