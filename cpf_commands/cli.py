"""Command-line entry points (argparse only here, at the edge).

``cpf-run``: reproduce a scenario with a policy (default: the paper's
``wang2014`` with ``nn_dsc``), print the paper's claims with measured values,
and write figures and metrics.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

from cpf_commands.policies import policy_argument
from cpf_env import scenarios

__all__ = ["run_main"]


def _run_parser() -> argparse.ArgumentParser:
    from baselines import POLICIES

    parser = argparse.ArgumentParser(
        prog="cpf-run",
        description="Run a scenario with a policy; write Figs. 3-7, metrics.json and "
        "trajectory.npz; print the paper's claims with the measured values.",
    )
    parser.add_argument("--scenario", default="wang2014", choices=scenarios.list_scenarios())
    parser.add_argument(
        "--policy",
        default="nn_dsc",
        type=policy_argument,
        help=f"a baseline ({', '.join(sorted(POLICIES))}) or a cpf-train --out folder",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="control steps (default: the scenario's episode length)",
    )
    parser.add_argument("--out", default="outputs", help="output directory (default: outputs)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def run_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-run``: see ``cpf-run --help``."""
    from cpf_commands.reproduce import reproduce

    args = _run_parser().parse_args(argv)
    start = time.perf_counter()
    metrics, claims = reproduce(
        args.scenario,
        args.policy,
        seed=args.seed,
        steps=args.steps,
        out=args.out,
        figures=not args.no_figures,
        progress=not args.quiet,
    )
    elapsed = time.perf_counter() - start
    print(
        f"\n{args.scenario} with {args.policy}, seed {args.seed}: "
        f"{metrics['steps']} steps ({metrics['duration_s']:.1f} s simulated) in {elapsed:.1f} s"
    )
    print("Claims of Wang, Wang & Peng (2014), measured over the last quarter of the run:")
    for claim in claims:
        verdict = "holds" if claim.holds else "NOT MET"
        print(
            f"  {claim.number}. [{claim.figure}] {claim.statement}\n"
            f"     measured: {claim.measured} -> {verdict}"
        )
    if "output_directory" in metrics:
        print(f"Figures, metrics.json and trajectory.npz in {metrics['output_directory']}/")
    return 0
