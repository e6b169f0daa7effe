"""The hard track's learners over their training seeds: cost, verdict and room closed.

Runs every run folder of each method (``--runs``: ``<method>_s<seed>`` agent
folders, as ``examples/hard_track/`` writes them) with the scenario's
reference ``nn_dsc``, its best deployable design and the bound on the
``test`` (20 seeds) and ``shift`` (10 seeds) splits, and prints per method:
each training seed's mean cost and guarded verdict against the best
deployable design, and the share of the room the method closes, (J_best -
J) / (J_best - J_oracle), as the IQM over every episode of every training
seed with a bootstrap interval over those episodes
(``cpf_bench.headroom.room_closed`` per agent, pooled here). Usage::

    python studies/hard_track/learners.py --runs runs/hard --best mpc_tuned_ekf
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cpf_bench.report import CellResult
from cpf_bench.stats import bootstrap_interval, iqm
from cpf_bench.verdict import verdict
from cpf_commands.bench.run import run_bench

#: A run folder's name: the method, then its training seed.
RUN = re.compile(r"^(?P<method>.+)_s(?P<seed>\d+)$")


def methods(root: Path) -> dict[str, list[str]]:
    """Method -> its run folders under ``root`` (agent folders only), by seed."""
    found: dict[str, list[tuple[int, str]]] = {}
    for folder in sorted(root.iterdir()):
        match = RUN.match(folder.name)
        if match and (folder / "manifest.json").is_file():
            found.setdefault(match["method"], []).append((int(match["seed"]), str(folder)))
    return {method: [f for _, f in sorted(runs)] for method, runs in found.items()}


def summary(
    cells: Sequence[CellResult], runs: dict[str, list[str]], best: str, bound: str = "oracle"
) -> list[str]:
    """Lines per method: each seed's cost and verdict, then the pooled room closed."""
    by_policy = {cell.policy: cell for cell in cells}
    j_best = float(np.mean(by_policy[best].metrics["cost"]))
    j_bound = float(np.mean(by_policy[bound].metrics["cost"]))
    lines = [f"  {best} {j_best:.4g}, {bound} {j_bound:.4g}"]
    for method, folders in runs.items():
        scores = []
        for folder in folders:
            cell = by_policy[folder]
            judged = verdict(cell, by_policy[best]).label
            lines.append(f"  {folder}: {np.mean(cell.metrics['cost']):.4g} {judged}")
            scores.append((j_best - cell.metrics["cost"]) / (j_best - j_bound))
        pooled = np.concatenate(scores)
        low, high = bootstrap_interval([pooled], statistic=iqm)
        lines.append(
            f"  {method}: room closed, IQM over {len(folders)} seeds x {len(scores[0])} episodes "
            f"{float(iqm(pooled)):.3f} ({low:.3f} to {high:.3f})"
        )
    return lines


def main(argv: Sequence[str] | None = None) -> None:
    """Run and print (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, required=True, help="folder of <method>_s<seed> runs")
    parser.add_argument("--scenario", default="hard_sensing")
    parser.add_argument("--best", default="mpc_tuned_ekf", help="its best deployable design")
    args = parser.parse_args(argv)
    runs = methods(args.runs)
    if not runs:
        parser.error(f"no <method>_s<seed> agent folders under {args.runs}.")
    folders = [folder for group in runs.values() for folder in group]
    for split, seeds in (("test", 20), ("shift", 10)):
        cells = run_bench(
            ["nn_dsc", args.best, "oracle", *folders], [args.scenario], seeds, split=split
        )
        print(f"{args.scenario}, {split} split ({seeds} seeds):")
        print("\n".join(summary(cells, runs, args.best)))


if __name__ == "__main__":
    main()
