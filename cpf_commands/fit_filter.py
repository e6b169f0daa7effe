"""``cpf-fit-filter``: fit a learned correction of a navigation filter (``agents.estimation``).

Runs the base design (a deployable design on the navigation filter: by
default ``mpc_tuned_mmae``; ``mpc_tuned_ekf``, ``mpc_tuned_ekf_safe``...) on
``--num-seeds`` training seeds of each ``--scenarios``, records every
vessel's recent fix offsets, applied forces and bank of filters, and its
filter's error against the true state, and fits the ridge regression from
the one to the other, then a network (``--hidden``) on what the regression
leaves; then ``--rounds`` - 1 times again, each round on
``--num-seeds`` fresh seeds run by the filter fitted so far, refitting on
all the data (``agents.estimation.fit``). Round r runs the training seeds
from ``--seed`` + r * ``--num-seeds`` (seeds from 9000 up are refused).
With ``--eval-num-seeds`` N > 0 the base and every round's filter are
measured on N validation seeds of each scenario.

The folder ``--out`` holds the correction as data (safetensors, JSON,
manifest; ``agents.load_policy`` and ``cpf-bench --policies DIR`` read it),
``run.json`` (the fit's record, the validation settings and the command)
and, with validation seeds, ``evaluations.csv``: the base at 0 vessel-steps
and each round at the vessel-steps simulated so far, ``cpf-train``'s
columns, so ``cpf-curves`` draws the learning curve. An existing ``--out``
is refused unless ``--force``. Example::

    cpf-fit-filter --scenarios hard_sensing --out runs/learned_filter
    cpf-curves runs/learned_filter --base-policy nn_dsc mpc_tuned_mmae --out runs/curves_filter
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from agents.estimation.fit import RIDGE, ROUNDS, fit_filter
from agents.estimation.folder import save_filter
from agents.estimation.network import EPOCHS, HIDDEN
from agents.estimation.policy import WINDOW
from agents.training.device import torch_device
from agents.training.schedule import EVALUATIONS, evaluations_csv
from cpf_env.infra import atomic

#: The run record ``--out`` receives beside the agent's files.
RUN_RECORD = "run.json"


def fit_filter_main(argv: Sequence[str] | None = None) -> None:
    """Parse the arguments, fit, write the folder and print the validation costs."""
    parser = argparse.ArgumentParser(prog="cpf-fit-filter", description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", required=True, help="training scenarios")
    parser.add_argument("--num-seeds", type=int, default=12, help="episodes per scenario and round")
    parser.add_argument("--seed", type=int, default=0, help="first training seed")
    parser.add_argument("--base", default="mpc_tuned_mmae", help="a design on a navigation filter")
    parser.add_argument("--window", type=int, default=WINDOW, help="steps of history")
    parser.add_argument("--ridge", type=float, default=RIDGE, help="penalty per sample")
    parser.add_argument(
        "--rounds", type=int, default=ROUNDS, help="rounds of gathering, the first on the base"
    )
    parser.add_argument(
        "--hidden", type=int, nargs="*", default=list(HIDDEN), metavar="WIDTH",
        help="the network's hidden widths; none (--hidden alone): the matrix only",
    )  # fmt: skip
    parser.add_argument("--epochs", type=int, default=EPOCHS, help="the network's passes")
    parser.add_argument(
        "--device", default="cpu",
        help="torch device that trains the network: cpu (default), auto, cuda or cuda:N",
    )  # fmt: skip
    parser.add_argument("--eval-num-seeds", type=int, default=10, help="validation seeds")
    parser.add_argument(
        "--max-steps", type=int, default=None, help="shorter episodes (default: each scenario's)"
    )
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--force", action="store_true", help="replace an existing --out")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.force:
        parser.error(f"{args.out} exists; give another --out, or --force to replace it.")
    if args.num_seeds < 1 or args.window < 1 or args.rounds < 1:
        parser.error("--num-seeds, --window and --rounds must be at least 1.")
    if args.eval_num_seeds < 0:
        parser.error("--eval-num-seeds must be >= 0 (0: no validation).")
    try:
        device = str(torch_device(args.device))
        correction, record, rows = fit_filter(
            args.scenarios,
            args.num_seeds,
            base=args.base,
            window=args.window,
            ridge=args.ridge,
            rounds=args.rounds,
            hidden=tuple(args.hidden),
            epochs=args.epochs,
            eval_num_seeds=args.eval_num_seeds,
            seed=args.seed,
            max_steps=args.max_steps,
            device=device,
            report=lambda line: print(line, flush=True),
        )
    except ValueError as error:
        parser.error(str(error))
    save_filter(args.out, correction, record)
    run = {
        "filter": record,
        "evaluation": record["evaluation"],
        "command": ["cpf-fit-filter", *(sys.argv[1:] if argv is None else argv)],
        "wall_clock_seconds": record["seconds"],
    }
    atomic.write_text(args.out / RUN_RECORD, json.dumps(run, indent=2) + "\n")
    if rows:
        atomic.write_text(args.out / EVALUATIONS, evaluations_csv(rows))
    print(
        f"fitted in {args.rounds} rounds on {record['samples']:,} samples from "
        f"{record['rounds'][-1]['vessel_steps']:,} vessel-steps in {record['seconds']:.0f} s: "
        f"{args.out}"
    )
    names = ("x", "y", "psi", "u", "v", "r")
    rms = zip(names, record["error_rms"], record["error_rms_fitted"], strict=True)
    print("error RMS (training):", ", ".join(f"{n} {a:.4g} -> {b:.4g}" for n, a, b in rms))
    first = record["evaluation"]["seed"] if rows else 0
    for name, costs in record["validation"].items():
        change = costs["filter"] / costs["base"] - 1.0
        print(
            f"{name}: {args.base} {costs['base']:.1f}, learned filter {costs['filter']:.1f} "
            f"({change:+.1%}; validation seeds {first}-{first + args.eval_num_seeds - 1})"
        )


if __name__ == "__main__":
    fit_filter_main()
