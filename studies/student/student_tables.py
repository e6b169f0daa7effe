r"""Print runs/student/README.md's tables from the committed benchmark episodes.

    python studies/student/student_tables.py                       # runs/student
    python studies/student/student_tables.py --root runs/student

For each of ``bench_test``, ``bench_shift`` and ``bench_procedural``, and
their ``_k6`` (6-slot students), ``_deepsets`` (encoder and history
students), ``_tuned``, ``_tuned_deepsets``, ``_tuned_applied``,
``_tuned_yield``, ``_tuned_yield_told``, ``_tuned_yield_twin`` and
``_tuned_deepsets_twin`` versions, ``bench_procedural_large_deepsets_twin``
and ``bench_paper_scenarios_twin`` (the paper's seven named scenarios)
(students on ``mpc_tuned``, which there takes ``mpc``'s place below) (those
that exist),
one row per scenario: the mean episode cost of ``nn_dsc``,
``mpc`` and ``oracle`` (where it ran) and of each student (one per training
seed), each student's paired cost difference to ``mpc`` (mean over seeds
with its 95 % bootstrap interval, ``cpf_bench.stats``) and its
verdict against ``mpc`` (``beats``: the whole interval below 0; ``loses``:
above 0; else ``no difference``), and its verdict against ``nn_dsc`` as
``cpf-bench`` wrote it in ``summary.md``. Then per student: the scenarios on
which it beats ``mpc``, those on which it loses to ``nn_dsc`` or is mixed
(better cost, a guarded metric worse), those it did not run on, and (where
``oracle`` ran) the interquartile mean over scenarios of the normalized
score (J_nn_dsc - J) / (J_nn_dsc - J_oracle) of the mean costs, over the
scenarios it ran on (``cpf-bench`` does not run a student on a graph of more
neighbours than its input has slots).

Then, per bench folder, every student's guarded verdict (``cpf-bench``'s rule,
``cpf_bench.verdict``: the cost and the final-window physical
metrics) against ``mpc`` and against each policy of ``--against`` (default
``mpc_tuned``, the strongest deployable design) whose episodes on the same
scenarios and seeds are in a ``--deployable`` episodes table, e.g. the
results page's::

    python studies/student/student_tables.py --deployable results/bench_test/episodes.csv \
        results/bench_shift/episodes.csv

An ``oracle`` in those tables also replaces each folder's own ``oracle`` in the
cost table and the normalized score (on the folder's seeds): the bound as the
package computes it now, whichever version the folder's run had.
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cpf_bench.report import CellResult, read_episodes_csv
from cpf_bench.stats import iqm, paired_difference
from cpf_bench.verdict import verdicts

#: The bench folders, each with the deployable policy its students are a residual on (the
#: reference of its cost table).
BENCHES = {
    **{
        f"bench_{split}{variant}": "mpc"
        for variant in ("", "_k6", "_deepsets")
        for split in ("test", "shift", "procedural")
    },
    **{
        f"bench_{split}{variant}": "mpc_tuned"
        for variant in (
            "_tuned",
            "_tuned_deepsets",
            "_tuned_applied",
            "_tuned_yield",
            "_tuned_yield_told",
            "_tuned_yield_twin",
            "_tuned_deepsets_twin",
        )
        for split in ("test", "shift", "procedural")
    },
    "bench_procedural_large_deepsets_twin": "mpc_tuned",
    "bench_paper_scenarios_twin": "mpc_tuned",
}
STUDENT = "agents/student"


def _episodes(path: Path) -> dict[tuple[str, str], dict[int, float]]:
    """(policy, scenario) -> seed -> episode cost, from an ``episodes.csv``."""
    costs: dict[tuple[str, str], dict[int, float]] = defaultdict(dict)
    with path.open() as file:
        for row in csv.DictReader(file):
            costs[(row["policy"], row["scenario"])][int(row["seed"])] = float(row["cost"])
    return costs


def _verdicts(summary: Path) -> dict[tuple[str, str], str]:
    """(policy, scenario) -> verdict against the reference, from a ``summary.md``."""
    found = {}
    for line in summary.read_text().splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) == 6 and cells[2].isdigit():
            found[(cells[0], cells[1])] = cells[5]
    return found


def _against(costs: dict[int, float], reference: dict[int, float]) -> tuple[float, float, float]:
    """Mean paired difference (policy - reference) and its 95 % interval."""
    seeds = sorted(reference)
    return paired_difference([costs[s] for s in seeds], [reference[s] for s in seeds])


def _table(
    folder: Path, deployable: Sequence[CellResult] = (), reference: str = "mpc"
) -> list[str]:
    """The folder's cost table, with the verdicts and scores (module docstring).

    ``reference`` is the deployable policy each student's cost is paired with.

    An ``oracle`` cell of ``deployable`` on the same scenario replaces the folder's
    (on the seeds the folder's ``nn_dsc`` ran).
    """
    costs = _episodes(folder / "episodes.csv")
    for cell in deployable:
        seeds = costs.get(("nn_dsc", cell.scenario), {})
        if cell.policy == "oracle" and seeds and set(seeds) <= set(cell.seeds):
            cost = dict(zip(cell.seeds, cell.metrics["cost"].tolist(), strict=True))
            costs[("oracle", cell.scenario)] = {seed: cost[seed] for seed in seeds}
    verdicts = _verdicts(folder / "summary.md")
    students = sorted({p for p, _ in costs if STUDENT in p})
    scenarios = list(dict.fromkeys(s for _, s in costs))
    has_oracle = all(("oracle", s) in costs for s in scenarios)
    mean = {key: float(np.mean(list(values.values()))) for key, values in costs.items()}
    lines = [
        f"{folder.name}: mean cost per scenario; each student's cost difference to {reference} "
        f"[95 %] and verdicts (vs {reference}; vs nn_dsc)",
        "",
        f"| scenario | nn_dsc | {reference} | "
        + ("oracle | " if has_oracle else "")
        + " | ".join(Path(s).name for s in students)
        + " |",
        "|---|---|---|" + ("---|" if has_oracle else "") + "---|" * len(students),
    ]
    beats_reference: dict[str, list[str]] = defaultdict(list)
    loses_nn_dsc: dict[str, list[str]] = defaultdict(list)
    scores: dict[str, list[float]] = defaultdict(list)
    ran: dict[str, int] = defaultdict(int)
    missing: dict[str, list[str]] = defaultdict(list)
    for scenario in scenarios:
        cells = [f"{mean[('nn_dsc', scenario)]:.1f}", f"{mean[(reference, scenario)]:.1f}"]
        if has_oracle:
            cells.append(f"{mean[('oracle', scenario)]:.1f}")
        for student in students:
            if (student, scenario) not in costs:  # cpf-bench lists it under "Not run"
                cells.append("not run")
                missing[student].append(scenario)
                continue
            ran[student] += 1
            delta, low, high = _against(costs[(student, scenario)], costs[(reference, scenario)])
            versus_reference = "beats" if high < 0 else "loses" if low > 0 else "no difference"
            versus_nn_dsc = verdicts.get((student, scenario), "-")
            if versus_reference == "beats":
                beats_reference[student].append(scenario)
            if versus_nn_dsc.startswith(("loses", "mixed")):
                loses_nn_dsc[student].append(scenario)
            if has_oracle:
                gap = mean[("nn_dsc", scenario)] - mean[("oracle", scenario)]
                scores[student].append(
                    (mean[("nn_dsc", scenario)] - mean[(student, scenario)]) / gap
                )
            cells.append(
                f"{mean[(student, scenario)]:.1f} ({delta:+.2f} [{low:+.2f}, {high:+.2f}]; "
                f"{versus_reference}; {versus_nn_dsc})"
            )
        lines.append(f"| {scenario} | " + " | ".join(cells) + " |")
    lines.append("")
    for student in students:
        score = f", IQM normalized score {float(iqm(scores[student])):.3f}" if has_oracle else ""
        lines.append(
            f"- {Path(student).name}: beats {reference} on "
            f"{len(beats_reference[student])}/{ran[student]} "
            f"({', '.join(beats_reference[student]) or 'none'}); loses or is mixed against "
            f"nn_dsc on "
            f"{', '.join(loses_nn_dsc[student]) or 'none'}; not run on "
            f"{', '.join(missing[student]) or 'none'}{score}"
        )
    return lines


def _on_seeds(cell: CellResult, seeds: set[int]) -> CellResult:
    """``cell`` restricted to ``seeds`` (in its own order)."""
    keep = [k for k, seed in enumerate(cell.seeds) if seed in seeds]
    metrics = {name: values[keep] for name, values in cell.metrics.items()}
    return CellResult(cell.policy, cell.scenario, tuple(cell.seeds[k] for k in keep),
                      cell.deterministic, metrics)  # fmt: skip


def _guarded(folder: Path, deployable: list[CellResult], against: list[str]) -> list[str]:
    """Each student's guarded verdict against ``mpc`` and the ``against`` policies.

    A reference's cells come from the folder itself or from ``deployable``, and
    both sides are restricted to the seeds both ran (paired episodes).
    """
    cells = read_episodes_csv((folder / "episodes.csv").read_text())
    students = [c for c in cells if STUDENT in c.policy]
    references = ["mpc", *against]
    found = {(c.policy, c.scenario): c for c in [*deployable, *cells] if c.policy in references}
    names = sorted({Path(c.policy).name for c in students})
    lines = [
        f"{folder.name}: guarded verdicts (cost and final-window physical metrics) against "
        + ", ".join(references),
        "",
        "| scenario | reference | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for scenario in dict.fromkeys(c.scenario for c in students):
        for reference in references:
            base = found.get((reference, scenario))
            if base is None:
                continue
            row = []
            for name in names:
                cell = next((c for c in students if Path(c.policy).name == name
                             and c.scenario == scenario), None)  # fmt: skip
                if cell is None:
                    row.append("not run")
                    continue
                seeds = set(cell.seeds) & set(base.seeds)
                judged = verdicts([_on_seeds(cell, seeds), _on_seeds(base, seeds)], reference)
                row.append(f"{judged[0].label} (N {len(seeds)})")
            lines.append(f"| {scenario} | {reference} | " + " | ".join(row) + " |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--root", default="results/student", help="folder of the bench folders")
    parser.add_argument("--deployable", nargs="*", default=[], metavar="EPISODES_CSV",
                        help="episodes tables of the --against policies")  # fmt: skip
    parser.add_argument("--against", nargs="*", default=["mpc_tuned"], metavar="POLICY",
                        help="references besides mpc for the guarded verdicts")  # fmt: skip
    args = parser.parse_args()
    deployable = [cell for path in args.deployable
                  for cell in read_episodes_csv(Path(path).read_text())]  # fmt: skip
    for name, reference in BENCHES.items():
        folder = Path(args.root) / name
        if (folder / "episodes.csv").is_file():
            print("\n".join(_table(folder, deployable, reference)), end="\n\n")
            print("\n".join(_guarded(folder, deployable, args.against)), end="\n\n")


if __name__ == "__main__":
    main()
