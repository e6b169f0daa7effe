"""``cpf-fit-filter``: fit a learned correction of a navigation filter (``agents.estimation``).

Runs the base design (a deployable design on the navigation filter: by
default ``mpc_tuned_mmae``; ``mpc_tuned_ekf``, ``mpc_tuned_ekf_safe``...) on
``--num-seeds`` training seeds of each ``--scenarios`` (from ``--seed``;
seeds from 9000 up are refused), records every vessel's recent fix offsets
and applied forces and its filter's error against the true state, fits the
ridge regression from the one to the other, and measures the base and the
fitted filter on ``--eval-num-seeds`` validation seeds of each scenario. The
folder ``--out`` holds the correction as data (safetensors, JSON,
manifest); ``agents.load_policy`` and ``cpf-bench --policies DIR`` read it.
An existing ``--out`` is refused unless ``--force``. Example::

    cpf-fit-filter --scenarios hard_sensing hard_heterogeneous --out runs/learned_filter
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from agents.estimation.fit import RIDGE, fit_filter
from agents.estimation.folder import save_filter
from agents.estimation.policy import WINDOW


def fit_filter_main(argv: Sequence[str] | None = None) -> None:
    """Parse the arguments, fit, write the folder and print the validation costs."""
    parser = argparse.ArgumentParser(prog="cpf-fit-filter", description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", required=True, help="training scenarios")
    parser.add_argument("--num-seeds", type=int, default=16, help="episodes per scenario")
    parser.add_argument("--seed", type=int, default=0, help="first training seed")
    parser.add_argument("--base", default="mpc_tuned_mmae", help="a design on a navigation filter")
    parser.add_argument("--window", type=int, default=WINDOW, help="steps of history")
    parser.add_argument("--ridge", type=float, default=RIDGE, help="penalty per sample")
    parser.add_argument("--eval-num-seeds", type=int, default=10, help="validation seeds")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--force", action="store_true", help="replace an existing --out")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.force:
        parser.error(f"{args.out} exists; give another --out, or --force to replace it.")
    if args.num_seeds < 1 or args.window < 1:
        parser.error("--num-seeds and --window must be at least 1.")
    try:
        correction, record = fit_filter(
            args.scenarios,
            args.num_seeds,
            base=args.base,
            window=args.window,
            ridge=args.ridge,
            eval_num_seeds=args.eval_num_seeds,
            seed=args.seed,
        )
    except ValueError as error:
        parser.error(str(error))
    save_filter(args.out, correction, record)
    print(f"fitted on {record['samples']} vessel-steps in {record['seconds']:.0f} s: {args.out}")
    names = ("x", "y", "psi", "u", "v", "r")
    rms = zip(names, record["error_rms"], record["error_rms_fitted"], strict=True)
    print("error RMS (training):", ", ".join(f"{n} {a:.4g} -> {b:.4g}" for n, a, b in rms))
    for name, costs in record["validation"].items():
        change = costs["filter"] / costs["base"] - 1.0
        print(
            f"{name}: {args.base} {costs['base']:.1f}, learned filter {costs['filter']:.1f} "
            f"({change:+.1%}; validation seeds {record['validation_seeds'][0]}-"
            f"{record['validation_seeds'][-1]})"
        )


if __name__ == "__main__":
    fit_filter_main()
