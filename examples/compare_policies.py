"""Compare your own controller with the baselines, through the benchmark's code.

``cpf-bench`` compares named baselines and trained agents from the command
line; from Python, ``run_bench`` also takes policy objects, or callables that
build one per scenario. Here the candidate is the paper's controller with
halved kinetic gains K2, compared with ``nn_dsc`` and ``backstepping`` on the
same paired seeds; the table printed is the run's ``summary.md``.

Usage::

    python examples/compare_policies.py [--scenarios bench_mild bench_saturation]
        [--num-seeds 5] [--max-steps N] [--out outputs/compare_policies]
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from baselines import NNDSCGains, make_policy
from cpf_bench.report import CellResult
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.envs.policy import FleetPolicy
from cpf_env.scenarios import Scenario

SOFT_K2 = tuple(0.5 * k for k in NNDSCGains().K2)


def soft_nn_dsc(scenario: Scenario) -> FleetPolicy:
    """The candidate: ``nn_dsc`` with half its kinetic gains, built for ``scenario``."""
    return make_policy("nn_dsc", scenario, K2=SOFT_K2)


def main(argv: Sequence[str] | None = None) -> list[CellResult]:
    """Parse arguments, run the comparison, print summary.md and return the results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenarios",
        nargs="+",
        default=["bench_mild", "bench_saturation"],
        choices=scenarios.list_scenarios(),
    )
    parser.add_argument("--num-seeds", type=int, default=5)
    parser.add_argument("--max-steps", type=int, default=None)
    parser.add_argument("--out", default="outputs/compare_policies")
    args = parser.parse_args(argv)
    policies = {"nn_dsc": "nn_dsc", "backstepping": "backstepping", "nn_dsc_soft": soft_nn_dsc}
    cells = run_bench(
        policies,
        args.scenarios,
        num_seeds=args.num_seeds,
        max_steps=args.max_steps,
        out=args.out,
        command=shlex.join(
            ["python", "examples/compare_policies.py", *(sys.argv[1:] if argv is None else argv)]
        ),
        figures=False,
    )
    print((Path(args.out) / "summary.md").read_text())
    return cells


if __name__ == "__main__":
    main()
