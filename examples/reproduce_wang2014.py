"""Reproduce the simulation of Wang, Wang & Peng (2014) with the reference controller.

Runs the paper's scenario (``wang2014``: five Cybership II vessels, 150 s)
with ``nn_dsc``, writes Figs. 3-7, ``metrics.json`` and ``trajectory.npz`` to
``outputs/wang2014_nn_dsc/`` and prints the paper's five claims with the
measured values. Same as ``cpf-run``.

Usage::

    python examples/reproduce_wang2014.py [--steps N] [--out DIR]
"""

from __future__ import annotations

from cpf_commands.cli import run_main


def main(steps: int | None = None, out: str = "outputs", figures: bool = True) -> int:
    """Run the reproduction; ``steps=None`` runs the paper's full 3,000 steps."""
    argv = ["--scenario", "wang2014", "--policy", "nn_dsc", "--out", out]
    if steps is not None:
        argv += ["--steps", str(steps)]
    if not figures:
        argv.append("--no-figures")
    return run_main(argv)


if __name__ == "__main__":
    import sys

    raise SystemExit(run_main(["--scenario", "wang2014", *sys.argv[1:]]))
