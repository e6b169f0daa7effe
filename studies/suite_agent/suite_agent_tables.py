"""Print docs/results.md's suite-agent tables from the committed benchmark summaries.

    python studies/suite_agent/suite_agent_tables.py        # runs/suite_agent
    python studies/suite_agent/suite_agent_tables.py --best nn_dsc_delay_comp --root \
        runs/suite_agent/ablations/per_position_statistics

For each split, one row per scenario: the mean episode cost of ``nn_dsc``, of
the strongest deployable analytic baseline (``--best``, the reference of the
``bench_<split>`` runs: ``mpc``), of the ``oracle`` where it ran, and of the
three suite agents (one per training seed), and each agent's verdict against
the first two, as ``cpf-bench`` wrote them in ``summary.md`` (the verdicts
against ``nn_dsc`` come from the ``*_vs_nn_dsc`` runs, when they exist).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

SPLITS = ("test", "shift")
AGENT = "agents/suite_s"
ORACLE = "oracle"


def _verdicts(summary: Path) -> dict[tuple[str, str], str]:
    """(policy, scenario) -> verdict, from the verdict table of a ``summary.md``."""
    found = {}
    for line in summary.read_text().splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) == 6 and cells[2].isdigit():
            found[(cells[0], cells[1])] = cells[5].replace("worse: ", "")
    return found


def _costs(summary: Path) -> dict[tuple[str, str], float]:
    """(policy, scenario) -> mean episode cost, from a ``summary.csv``."""
    with summary.open() as file:
        rows = [row for row in csv.DictReader(file) if row["metric"] == "cost"]
    return {(row["policy"], row["scenario"]): float(row["mean"]) for row in rows}


def _table(root: Path, split: str, best: str) -> list[str]:
    folder = root / f"bench_{split}"
    costs = _costs(folder / "summary.csv")
    against_best = _verdicts(folder / "summary.md")
    plain = root / f"bench_{split}_vs_nn_dsc" / "summary.md"
    against_nn_dsc = _verdicts(plain) if plain.is_file() else {}
    agents = sorted({p for p, _ in costs if AGENT in p}, key=lambda p: int(p.rsplit("_s", 1)[1]))
    scenarios = list(dict.fromkeys(s for _, s in costs))
    bound = any(policy == ORACLE for policy, _ in costs)
    lines = [
        f"`{split}` split | `nn_dsc` | `{best}` | "
        + (f"`{ORACLE}` | " if bound else "")
        + f"suite agent (3 seeds) | verdict vs `{best}` | verdict vs `nn_dsc` |",
        "|---" * (6 + bound) + "|",
    ]
    for scenario in scenarios:
        learned = [costs[(agent, scenario)] for agent in agents]
        oracle = f"{costs[(ORACLE, scenario)]:.0f} | " if bound else ""
        lines.append(
            f"| {scenario} | {costs[('nn_dsc', scenario)]:.0f} | "
            f"{costs[(best, scenario)]:.0f} | {oracle}"
            f"{min(learned):.0f}-{max(learned):.0f} | "
            + "; ".join(against_best.get((a, scenario), "-") for a in agents)
            + " | "
            + "; ".join(against_nn_dsc.get((a, scenario), "-") for a in agents)
            + " |"
        )
    lines[0] = "| " + lines[0]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--root", default="results/suite_agent", help="folder of bench_<split>/")
    parser.add_argument(
        "--best", default="mpc", help="the strongest deployable analytic baseline that ran"
    )
    args = parser.parse_args()
    for split in SPLITS:
        print("\n".join(_table(Path(args.root), split, args.best)), end="\n\n")


if __name__ == "__main__":
    main()
