"""Reproduce the simulation of Wang, Wang & Peng (2014) with the reference controller.

Runs the paper's reproduction configuration (``wang2014_fine``: five
Cybership II vessels, 150 s at a 0.01 s control step, ``nn_dsc`` with the
integrating weight-law reading ``leakage="plain"``), writes Figs. 3-7,
``metrics.json`` and ``trajectory.npz`` to ``outputs/wang2014_fine_nn_dsc/``
and prints the paper's five claims with the measured values. Same as
``cpf-run``; every ``cpf-run`` option works (``--help``).

Usage::

    python examples/reproduce_wang2014.py [--steps N] [--out DIR] [--scenario wang2014]
"""

from __future__ import annotations

from cpf_commands.run.cli import run_main

PROG = "reproduce_wang2014.py"


def main(steps: int | None = None, out: str = "outputs", figures: bool = True) -> int:
    """Run the reproduction; ``steps=None`` runs the paper's full 150 s (15,000 steps)."""
    argv = ["--out", out]
    if steps is not None:
        argv += ["--steps", str(steps)]
    if not figures:
        argv.append("--no-figures")
    return run_main(argv, prog=PROG)


if __name__ == "__main__":
    import sys

    raise SystemExit(run_main(sys.argv[1:], prog=PROG))
