r"""What a local controller could still gain over ``mpc_tuned``: its headroom, split by information.

    export NUMBA_NUM_THREADS=1
    python studies/headroom/headroom_tuned.py --split test --num-seeds 20 \
        --out runs/headroom_decomposition_tuned
    python studies/headroom/headroom_tuned.py --split shift --num-seeds 10 \
        --out runs/headroom_decomposition_tuned_shift

``cpf-bench`` of ``oracle``, ``mpc_tuned`` and the members of
``baselines.mpc_told`` (and ``mpc_privileged``) built with ``mpc_tuned``'s
estimator settings (``MPCTuned.DEFAULTS``: ``baselines.mpc_tuned.K5``, ``K6``
and ``baselines.mpc.SPEED_RATE``), against ``mpc_tuned`` as the reference:

=================================  ==========================================================
``mpc_tuned_told_dynamics``        its own true model and true lumped residual force: what a
                                   perfect estimator of the vessel's own dynamics would give
                                   ``mpc_tuned``
``mpc_tuned_told_links``           every neighbour's present path variable and message
``mpc_tuned_told_v0``              the true v0 now
``mpc_tuned_privileged``           all three
=================================  ==========================================================

The last three are told what other vessels hold; none is told the future
disturbances nor plans centrally, which is what ``oracle`` adds. The table in
studies/headroom/README.md ("What a local controller can reach against ``mpc_tuned``")
is read from the ``summary.csv`` this writes (``gap_closed`` on the ``cost``
rows: the share of ``mpc_tuned``'s headroom each closes).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from functools import partial

import baselines
from baselines.mpc_tuned import MPCTuned
from cpf_bench.report import CellResult
from cpf_commands.bench.run import run_bench
from cpf_env.scenarios.suite import list_suite

#: Label in the bench -> the ``baselines.mpc_told`` / ``baselines.mpc`` policy it builds.
TOLD = {
    "mpc_tuned_told_dynamics": "mpc_told_dynamics",
    "mpc_tuned_told_links": "mpc_told_links",
    "mpc_tuned_told_v0": "mpc_told_v0",
    "mpc_tuned_privileged": "mpc_privileged",
}


def main(argv: list[str] | None = None) -> list[CellResult]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("test", "shift"), default="test")
    parser.add_argument("--num-seeds", type=int, default=20, help="episodes per cell (default 20)")
    parser.add_argument("--max-steps", type=int, default=None,
                        help="episode length in control steps (default: scenario's)")  # fmt: skip
    parser.add_argument("--scenarios", nargs="+", default=list_suite(), metavar="NAME",
                        help="suite scenarios (default: all seven)")  # fmt: skip
    parser.add_argument("--out", default=None, help="output folder (default: print only)")
    args = parser.parse_args(argv)
    policies = {"oracle": "oracle", "mpc_tuned": "mpc_tuned"}
    for label, name in TOLD.items():
        policies[label] = partial(baselines.make_policy, name, **MPCTuned.DEFAULTS)
    given = sys.argv[1:] if argv is None else argv
    command = shlex.join(["python", "studies/headroom/headroom_tuned.py", *given])
    cells = run_bench(policies, args.scenarios, num_seeds=args.num_seeds, max_steps=args.max_steps,
                      out=args.out, command=command, figures=False, reference="mpc_tuned",
                      split=args.split)  # fmt: skip
    print("| policy | scenario | mean cost |")
    print("|---|---|---|")
    for cell in cells:
        print(f"| {cell.policy} | {cell.scenario} | {cell.metrics['cost'].mean():.4g} |")
    return cells


if __name__ == "__main__":
    main()
