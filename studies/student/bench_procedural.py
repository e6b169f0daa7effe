r"""Bench policies on held-out procedural fleets: draws no training run sees.

The suite's seven fleets are what students are distilled on; this runs
policies on fleets of ``cpf_env.scenarios.sampler.ScenarioDistribution`` drawn
with ``sample(seed, evaluation=True)`` (draw seeds 10000 and up, which no
training draw uses), capped at ``--max-degree`` neighbours (default 4, the
4-slot students' input), with ``cpf-bench``'s own runner
(``cpf_commands.bench.run.run_bench``: paired episode seeds from 10000, the
same tables, ranking and verdicts). ``cpf-bench`` does not run a fixed-slot
student on a fleet of higher degree than its slots; an encoder student
(``TrainConfig(encoder="deepsets")``) runs on any degree, so larger fleets
and degrees (``--sizes 8 12 --max-degree 11``) show it on graphs no
training draw had.

Example (what runs/student/bench_procedural holds)::

    python studies/student/bench_procedural.py --draws 8 --num-seeds 5 \
        --policies nn_dsc mpc runs/student/agents/student_s0 \
        --out runs/student/bench_procedural
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from cpf_commands.bench.run import run_bench
from cpf_env.scenarios.sampler import ScenarioDistribution
from cpf_env.scenarios.splits import EVALUATION_SEED

#: The 4-slot students' neighbour slots: the suite's largest degree (bench_switching's star).
MAX_DEGREE = 4
#: Fleet sizes drawn by default (``ScenarioDistribution``'s).
SIZES = ScenarioDistribution().sizes


def main(argv: Sequence[str] | None = None) -> int:
    """Draw the held-out fleets and bench the policies on them."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    parser.add_argument("--policies", nargs="+", required=True, help="as cpf-bench --policies")
    parser.add_argument("--draws", type=int, default=8, help="held-out fleets (draw seeds 10000+)")
    parser.add_argument("--num-seeds", type=int, default=5, help="episodes per policy and fleet")
    parser.add_argument(
        "--max-degree", type=int, default=MAX_DEGREE,
        help="largest neighbour count of a drawn fleet (ScenarioDistribution.max_degree)",
    )  # fmt: skip
    parser.add_argument(
        "--sizes", type=int, nargs=2, default=list(SIZES), metavar=("LO", "HI"),
        help="fleet size range, vessels (ScenarioDistribution.sizes)",
    )  # fmt: skip
    parser.add_argument("--out", required=True, help="output folder, as cpf-bench --out")
    parser.add_argument("--force", action="store_true", help="replace an existing --out")
    args = parser.parse_args(argv)
    if args.draws < 1 or args.num_seeds < 1:
        parser.error("--draws and --num-seeds must be >= 1.")
    if Path(args.out).exists() and not args.force:
        parser.error(f"{args.out} exists; pass --force to replace it.")
    try:
        distribution = ScenarioDistribution(sizes=tuple(args.sizes), max_degree=args.max_degree)
    except ValueError as error:
        parser.error(str(error))
    fleets = [distribution.sample(EVALUATION_SEED + k, evaluation=True) for k in range(args.draws)]
    for fleet in fleets:
        print(distribution.describe(fleet))
    given = sys.argv[1:] if argv is None else list(argv)
    command = "python studies/student/bench_procedural.py " + " ".join(given)
    run_bench(
        args.policies,
        fleets,
        num_seeds=args.num_seeds,
        out=args.out,
        command=command,
        figures=False,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
