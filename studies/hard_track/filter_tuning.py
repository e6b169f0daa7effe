"""How much process noise the navigation filter should assume: one filter per factor, and the bank.

Runs ``mpc_tuned`` on the navigation filter (``baselines.estimator``) with
the velocity and bias process noise of ``FILTER_NOISE`` times each factor,
and on the likelihood-weighted bank of ``ADAPTIVE_SCALES`` (``mpc_tuned_mmae``),
on training seeds of the hard track's sensing scenarios (below the
evaluation seeds, so the choice does not see the test split), and prints the
mean whole-episode cost of each. With ``--safe`` it runs the same filters
under the safety filter (``mpc_tuned_ekf_safe``'s design) on
``hard_large_fleet`` and counts the episodes that end early. The bank's
factors were chosen from these tables. Usage::

    python studies/hard_track/filter_tuning.py --num-seeds 6
    python studies/hard_track/filter_tuning.py --num-seeds 8 --safe --factors 1
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from baselines.estimator import ADAPTIVE_SCALES, Filtered, MPCTunedFiltered
from baselines.safety import MPCTunedFilteredSafe
from cpf_commands.bench.run import run_bench

#: The sensing scenarios without a separation, where ``mpc_tuned_ekf`` is the best design.
SENSING = ["hard_sensing", "hard_sensing_waves", "hard_underactuated_sensing", "hard_heterogeneous"]


def _design(base: type[Filtered], scales: tuple[float, ...]) -> type[Filtered]:
    """``base`` with the filter bank ``scales`` (a class, built per scenario by ``run_bench``)."""
    label = "bank" if len(scales) > 1 else f"x{scales[0]:g}"
    return type(f"{base.__name__}_{label}", (base,), {"name": label, "noise_scales": scales})


def main(argv: Sequence[str] | None = None) -> dict[str, dict[str, float]]:
    """Print and return the mean cost per filter and scenario."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0, help="first training seed")
    parser.add_argument(
        "--factors", type=float, nargs="+", default=[0.001, 0.003, 0.01, 0.1, 1.0, 3.0, 10.0]
    )
    parser.add_argument("--safe", action="store_true", help="hard_large_fleet, safety-filtered")
    parser.add_argument("--max-steps", type=int, default=None)
    args = parser.parse_args(argv)
    base: type[Filtered] = MPCTunedFilteredSafe if args.safe else MPCTunedFiltered
    tasks = ["hard_large_fleet"] if args.safe else SENSING
    designs = {f"x{f:g}": _design(base, (f,)) for f in args.factors}
    designs[f"bank {ADAPTIVE_SCALES}"] = _design(base, ADAPTIVE_SCALES)
    cells = run_bench(
        designs,
        tasks,
        num_seeds=args.num_seeds,
        seed=args.seed,
        max_steps=args.max_steps,
        figures=False,
        reference=next(iter(designs)),
    )
    table: dict[str, dict[str, float]] = {}
    ended: dict[str, int] = {}
    for cell in cells:
        table.setdefault(cell.policy, {})[cell.scenario] = float(np.mean(cell.metrics["cost"]))
        ended[cell.policy] = ended.get(cell.policy, 0) + int(np.sum(cell.metrics["terminated"]))
    seeds = f"training seeds {args.seed}-{args.seed + args.num_seeds - 1}"
    print(f"mpc_tuned on each filter, mean cost over {seeds}:\n")
    print("| velocity and bias noise | " + " | ".join(tasks) + " | episodes ended early |")
    print("|---|" + "---|" * len(tasks) + "---|")
    for label, costs in table.items():
        row = " | ".join(f"{costs[task]:.1f}" for task in tasks)
        print(f"| {label} | {row} | {ended[label]} |")
    return table


if __name__ == "__main__":
    main()
