"""How close the crossing pairs' formation should bring them: the offset swept.

A crossing pair's synchronized formation passes ``offset / sqrt(2)`` apart
(``cpf_env.scenarios.crossing``). Runs ``hard_crossing`` with each formation
offset (its paths and nominal starts rebuilt, everything else as
registered) on training seeds (below the evaluation seeds) under the
``oracle``, ``mpc_tuned`` and ``mpc_tuned_safe``, and prints the mean
whole-episode cost, the oracle's progress and closest approach, and the room
1 - J_oracle / J_best (J_best the cheaper deployable design).
``hard.CROSSING_OFFSET`` was chosen from this table. Usage::

    python studies/hard_track/crossing_geometry.py --num-seeds 3
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from baselines import OraclePolicy
from baselines.mpc_tuned import MPCTuned
from baselines.safety import MPCTunedSafe
from cpf_commands.bench.run import run_bench
from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import hard
from cpf_env.scenarios.crossing import crossing_fleet
from cpf_env.scenarios.scenario import Scenario

#: Labels -> builders (not the registered names, so that no cell of these unregistered
#: layouts lands in the bench cache).
POLICIES: dict[str, Callable[[object], FleetPolicy]] = {
    "oracle": OraclePolicy,
    "mpc_tuned": MPCTuned,
    "mpc_tuned_safe": MPCTunedSafe,
}


def with_offset(offset: float) -> Scenario:
    """``hard_crossing`` with the formation offset ``offset`` (m), named after it."""
    task = hard.hard_crossing()
    paths, initial, _ = crossing_fleet(2, offset=offset)
    return task.replace(
        name=f"hard_crossing_offset_{offset:g}",
        paths=paths,
        initial=dataclasses.replace(task.initial, eta=initial.eta),
    )


def main(argv: Sequence[str] | None = None) -> dict[float, dict[str, float]]:
    """Print and return offset -> {policy: mean cost}."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0, help="first training seed")
    parser.add_argument("--offsets", type=float, nargs="+", default=[0.3, 0.8, 1.0, 1.2])
    parser.add_argument("--max-steps", type=int, default=None)
    args = parser.parse_args(argv)
    costs: dict[float, dict[str, float]] = {}
    print(
        "| offset (m) | formation passes at (m) | oracle | mpc_tuned | mpc_tuned_safe | "
        "oracle's progress | oracle's closest (m) | room |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for offset in args.offsets:
        cells = run_bench(POLICIES, [with_offset(offset)], num_seeds=args.num_seeds,
                          seed=args.seed, max_steps=args.max_steps,
                          figures=False)  # fmt: skip
        metrics = {cell.policy: cell.metrics for cell in cells}
        costs[offset] = {label: float(np.mean(m["cost"])) for label, m in metrics.items()}
        best = min(costs[offset]["mpc_tuned"], costs[offset]["mpc_tuned_safe"])
        oracle = metrics["oracle"]
        print(
            f"| {offset:g} | {offset / np.sqrt(2.0):.2f} | {costs[offset]['oracle']:.1f} | "
            f"{costs[offset]['mpc_tuned']:.1f} | {costs[offset]['mpc_tuned_safe']:.1f} | "
            f"{np.mean(oracle['progress']):.2f} | {np.min(oracle['separation_min']):.2f} | "
            f"{1.0 - costs[offset]['oracle'] / best:.0%} |"
        )
    return costs


if __name__ == "__main__":
    main()
