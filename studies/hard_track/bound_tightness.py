"""Is the ``oracle`` tight for its family on the hard track? Four times its samples, same seeds.

Runs ``oracle`` and ``oracle`` with ``--factor`` times its candidate plans per
revision (``RecedingHorizonGains.samples``) on the same ``test`` seeds of each
hard scenario and prints the mean whole-episode costs and the relative change
(J_more - J) / J with the range over seeds. A bound that is tight for its
family barely moves. Usage::

    python studies/hard_track/bound_tightness.py --num-seeds 3 --factor 4
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from baselines import OraclePolicy, RecedingHorizonGains
from cpf_commands.bench.run import run_bench
from cpf_env.scenarios.suite import list_suite


def main(argv: Sequence[str] | None = None) -> list[tuple[str, float, float]]:
    """Print and return (scenario, oracle's mean cost, the larger oracle's) per scenario."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=3)
    parser.add_argument("--factor", type=int, default=4, help="times the default samples")
    parser.add_argument("--scenarios", nargs="+", default=list_suite("hard"))
    parser.add_argument("--max-steps", type=int, default=None)
    args = parser.parse_args(argv)
    samples = args.factor * RecedingHorizonGains().samples
    larger = f"oracle_{samples}_samples"
    policies = {
        "oracle": "oracle",
        larger: lambda task: OraclePolicy(task, samples=samples),
    }
    cells = run_bench(
        policies,  # type: ignore[arg-type]
        args.scenarios,
        num_seeds=args.num_seeds,
        max_steps=args.max_steps,
        figures=False,
    )
    rows = []
    print(f"| scenario | oracle | {larger} | change (range over seeds) |")
    print("|---|---|---|---|")
    for name in args.scenarios:
        base, more = (
            next(c.metrics["cost"] for c in cells if c.policy == p and c.scenario == name)
            for p in ("oracle", larger)
        )
        change = (more - base) / base
        rows.append((name, float(np.mean(base)), float(np.mean(more))))
        print(
            f"| {name} | {np.mean(base):.2f} | {np.mean(more):.2f} | "
            f"{np.mean(more) / np.mean(base) - 1:+.1%} "
            f"({change.min():+.1%} to {change.max():+.1%}) |"
        )
    return rows


if __name__ == "__main__":
    main()
