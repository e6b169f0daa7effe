"""``cpf-curves``: learning curves of several training runs, IQM over training seeds.

Reads the ``evaluations.csv`` of each run folder (one per training seed; the
cost on the held-out seeds its ``run.json`` names: the validation seeds,
``cpf_env.scenarios.splits.VALIDATION_SEED`` and up, or for a run recorded
before them the ``test`` seeds): a ``cpf-train --out``
folder, or a ``cpf-distill`` run (``--out``, or ``--log`` where given) with
``--eval-num-seeds N``, whose rows are the student before round 0 (its base) and
after each DAgger round at the labelled vessel-steps so far (the simulated
ones, as ``cpf-train`` counts them; the seconds include the teacher's), or a
``cpf-fit-filter --out`` folder with ``--eval-num-seeds N``, whose rows are
its base at 0 vessel-steps and each round's filter at the vessel-steps
simulated so far. It writes to ``--out``:

- ``curves.csv``: one row per point of either axis: ``axis`` (``vessel_steps``
  or ``wall_clock_seconds``), ``x``, ``iqm`` (interquartile mean over the runs
  of the mean evaluation cost), ``ci_low``, ``ci_high`` (95 % percentile
  bootstrap over the runs, ``cpf_bench.stats``), ``runs`` and
  ``base_cost`` (the first line to beat), then ``<name>_cost`` of every
  further line (``--base-policy A B``);
- ``curves.png``: both curves with their intervals, each run faint, each
  line to beat dashed;

and prints the time to beat each line: the first vessel-step count (and
wall-clock second) at which the IQM is below its cost, and at which the
whole interval is. One run has no interval: it prints and draws its cost
alone (``curves.csv`` then has ci_low = ci_high = iqm = the run's cost).

Vessel-steps axis: the evaluation points every run has (runs with one
schedule evaluate at the same counts). Wall-clock axis: every time at which
some run evaluated, between the latest first evaluation and the earliest last
one; each run's cost at time t is its latest evaluation at or before t.

The lines to beat: with ``--base-policy NAME [NAME ...]``, those analytic
policies run by the benchmark on the runs' evaluation settings
(``run.json``: scenarios, seeds, horizon; runs evaluated on different seeds
are refused): the reference and the best deployable design, say, for the
time to beat each; without it, the runs' evaluation at 0 vessel-steps,
which for a residual agent is exactly its base policy (the correction
starts at zero).

Example::

    cpf-curves runs/lossy_s0 runs/lossy_s1 runs/lossy_s2 --out runs/curves_lossy
    cpf-curves runs/sensing_s* --base-policy nn_dsc mpc_tuned_ekf --out runs/curves_sensing
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from numpy.typing import NDArray

from cpf_bench.stats import bootstrap_interval, iqm
from cpf_commands.bench.run import run_bench
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import EVALUATION_SEED

__all__ = [
    "Curve",
    "RunCurve",
    "curves_csv",
    "curves_main",
    "read_run",
    "steps_curve",
    "time_curve",
]

AXES = ("vessel_steps", "wall_clock_seconds")
#: A cost within this fraction of a line's is level with it (floating-point rounding).
TIE = 1e-9


@dataclass(frozen=True)
class RunCurve:
    """One run's evaluations.

    Attributes:
        name: The run folder's name.
        steps: (E,) vessel-steps of the evaluations.
        seconds: (E,) wall-clock seconds of the run at each evaluation.
        cost: (E,) mean evaluation cost.
    """

    name: str
    steps: NDArray[np.float64]
    seconds: NDArray[np.float64]
    cost: NDArray[np.float64]


@dataclass(frozen=True)
class Curve:
    """IQM over runs along one axis, with its interval.

    Attributes:
        axis: ``vessel_steps`` or ``wall_clock_seconds``.
        x: (P,) points of the axis.
        values: (P, R) each run's cost at each point.
        iqm: (P,) interquartile mean over the runs.
        low: (P,) lower end of the 95 % bootstrap interval.
        high: (P,) upper end.
    """

    axis: str
    x: NDArray[np.float64]
    values: NDArray[np.float64]
    iqm: NDArray[np.float64]
    low: NDArray[np.float64]
    high: NDArray[np.float64]


def read_run(folder: Path) -> RunCurve:
    """A run folder's ``evaluations.csv``.

    Raises:
        ValueError: No or an empty ``evaluations.csv`` (the run did not evaluate).
    """
    path = folder / "evaluations.csv"
    if not path.is_file():
        raise ValueError(
            f"{folder} has no evaluations.csv; train with cpf-train --eval-every N (> 0) or "
            "cpf-distill or cpf-fit-filter --eval-num-seeds N (> 0)."
        )
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    if not rows:
        raise ValueError(f"{path} holds no evaluation.")
    try:
        columns = [
            np.array([float(row[key]) for row in rows])
            for key in ("vessel_steps", "wall_clock_seconds", "mean_cost")
        ]
    except (KeyError, ValueError) as error:
        raise ValueError(
            f"{path} is not an evaluations.csv of cpf-train, cpf-distill or cpf-fit-filter: {error}"
        ) from None
    return RunCurve(folder.name, *columns)


def _tick(value: float, _: object) -> str:
    """An axis tick: millions as ``2M``, thousands as ``40k``, else the integer."""
    for size, suffix in ((1e6, "M"), (1e3, "k")):
        if abs(value) >= size:
            return f"{value / size:g}{suffix}"
    return f"{value:.0f}"


def _summarize(axis: str, x: NDArray[np.float64], values: NDArray[np.float64]) -> Curve:
    """IQM and bootstrap interval over the runs (columns) at every point (row)."""
    intervals = np.array([bootstrap_interval([row], iqm) for row in values]).reshape(-1, 2)
    return Curve(axis, x, values, iqm(values, axis=1), intervals[:, 0], intervals[:, 1])


def steps_curve(runs: Sequence[RunCurve]) -> Curve:
    """The IQM vs vessel-steps, at the evaluation counts every run has.

    Raises:
        ValueError: The runs share no evaluation count.
    """
    common = sorted(set.intersection(*(set(run.steps.tolist()) for run in runs)))
    if not common:
        raise ValueError(
            "the runs share no evaluation vessel-step count; train them with one --eval-every "
            "(cpf-train), one rounds, steps and fleets (cpf-distill) or one --num-seeds and "
            "--rounds (cpf-fit-filter)."
        )
    values = np.array(
        [[run.cost[np.flatnonzero(run.steps == x)[-1]] for run in runs] for x in common]
    )
    return _summarize("vessel_steps", np.array(common), values)


def time_curve(runs: Sequence[RunCurve]) -> Curve:
    """The IQM vs wall-clock seconds (each run's latest evaluation at or before each time)."""
    start = max(float(run.seconds[0]) for run in runs)
    end = min(float(run.seconds[-1]) for run in runs)
    times = np.unique(np.concatenate([run.seconds for run in runs]))
    grid = times[(times >= start) & (times <= end)]
    if grid.size == 0:
        grid = np.array([end])
    values = np.array(
        [
            [run.cost[max(np.searchsorted(run.seconds, t, side="right") - 1, 0)] for run in runs]
            for t in grid
        ]
    )
    return _summarize("wall_clock_seconds", grid, values)


def first_below(curve: Curve, level: float) -> tuple[float | None, float | None]:
    """First x where the IQM is below ``level``, and first x where the whole interval is.

    Below means by more than rounding (``TIE``): runs that all start as their base (a
    residual at zero, a learned filter's correction of zeros) have an IQM that differs from
    the base's cost in its last bits, and do not beat it there.
    """
    below = np.flatnonzero(curve.iqm < level - TIE * abs(level))
    surely = np.flatnonzero(curve.high < level - TIE * abs(level))
    return (
        float(curve.x[below[0]]) if below.size else None,
        float(curve.x[surely[0]]) if surely.size else None,
    )


def curves_csv(curves: Sequence[Curve], lines: dict[str, float], runs: int) -> str:
    """``curves.csv`` text; ``lines``: name -> cost of each line to beat, the first the base."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    names = list(lines)
    writer.writerow(["axis", "x", "iqm", "ci_low", "ci_high", "runs", "base_cost",
                     *(f"{name}_cost" for name in names[1:])])  # fmt: skip
    costs = [repr(lines[name]) for name in names]
    for curve in curves:
        for i, x in enumerate(curve.x):
            writer.writerow(
                [curve.axis, repr(float(x)), repr(float(curve.iqm[i])), repr(float(curve.low[i])),
                 repr(float(curve.high[i])), runs, *costs]
            )  # fmt: skip
    return buffer.getvalue()


def figure(curves: Sequence[Curve], lines: dict[str, float], names: Sequence[str]) -> Figure:
    """Both learning curves side by side (Agg figure, no time stamp)."""
    drawing = Figure(figsize=(11, 4.2))
    labels = {"vessel_steps": "vessel-steps", "wall_clock_seconds": "wall-clock seconds"}
    for index, curve in enumerate(curves):
        axes = drawing.add_subplot(1, len(curves), index + 1)
        style = "steps-post" if curve.axis == "wall_clock_seconds" else "default"
        for r in range(curve.values.shape[1]):
            axes.plot(curve.x, curve.values[:, r], color="tab:blue", alpha=0.25, lw=0.8,
                      drawstyle=style)  # fmt: skip
        label = f"IQM over {len(names)} training seeds" if len(names) > 1 else "one run"
        axes.plot(curve.x, curve.iqm, color="tab:blue", lw=2, drawstyle=style, label=label)
        if len(names) > 1:  # one run has no interval to draw
            axes.fill_between(curve.x, curve.low, curve.high, color="tab:blue", alpha=0.2,
                              step="post" if style == "steps-post" else None,
                              label="95 % bootstrap interval")  # fmt: skip
        for k, (line, cost) in enumerate(lines.items()):
            axes.axhline(cost, color=f"C{k + 1}" if k else "k", ls="--", lw=1.2, label=line)
        axes.set_xlabel(labels[curve.axis])
        axes.xaxis.set_major_formatter(FuncFormatter(_tick))
        axes.set_ylabel("held-out evaluation cost (lower is better)")
        axes.grid(alpha=0.3)
        if index == 0:
            axes.legend(fontsize=8)
    drawing.suptitle("Held-out evaluation cost during training")
    drawing.tight_layout()
    return drawing


def _lines(
    folders: Sequence[Path], runs: Sequence[RunCurve], bases: Sequence[str] | None
) -> dict[str, float]:
    """Name -> evaluation cost of each line to beat (see the module docstring)."""
    from agents.training.evaluation import DEFAULT_EVAL_NUM_SEEDS

    records = [json.loads((folder / "run.json").read_text()) for folder in folders]
    seeds = {_first_seed(record) for record in records}
    if len(seeds) > 1:
        raise ValueError(
            f"the runs were evaluated on different seeds (first seeds {sorted(seeds)}: "
            "validation seeds and, before them, the test seeds); draw them apart."
        )
    if bases:
        evaluation = records[0].get("evaluation") or {}
        # "seeds", "steps": a run written before they were named num_seeds, max_steps
        num_seeds = evaluation.get("num_seeds", evaluation.get("seeds", DEFAULT_EVAL_NUM_SEEDS))
        cells = run_bench(
            list(bases),
            evaluation.get("scenarios") or list(_trained(records[0])[0]),
            num_seeds=int(num_seeds),
            seed=seeds.pop(),
            max_steps=evaluation.get("max_steps", evaluation.get("steps")),
            split="test",
        )
        return {
            base: float(np.mean([np.mean(c.metrics["cost"]) for c in cells if c.policy == base]))
            for base in dict.fromkeys(bases)
        }
    if any(_trained(record)[1] == "none" for record in records):
        raise ValueError(
            "runs trained from scratch have no base to compare with; give --base-policy NAME."
        )
    starts = [run.cost[run.steps == 0] for run in runs]
    if any(start.size == 0 for start in starts):
        raise ValueError(
            "a run has no evaluation at 0 vessel-steps (its base); give --base-policy NAME."
        )
    return {"base policy": float(iqm(np.array([start[0] for start in starts])))}


def _trained(record: dict) -> tuple[list[str], str]:
    """The scenarios a run trained on and its base policy (``run.json``).

    A ``cpf-train`` or ``cpf-distill`` run records its ``config``; a ``cpf-fit-filter``
    run its ``filter`` (the base is the design under the filter).
    """
    from agents.training.config import config_from_record

    if "filter" in record:
        return list(record["filter"]["scenarios"]), str(record["filter"]["base"])
    config = config_from_record(record["config"])
    return list(config.scenarios), config.base_policy


def _first_seed(record: dict) -> int:
    """The first seed a run's evaluations reset with (``run.json``'s ``evaluation``).

    A run recorded before the validation seeds has no ``seed`` and was evaluated on
    the ``test`` seeds, from ``EVALUATION_SEED``.
    """
    return int((record.get("evaluation") or {}).get("seed", EVALUATION_SEED))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-curves",
        description="Learning curves of cpf-train, cpf-distill or cpf-fit-filter runs (one per "
        "training seed): IQM of the "
        "held-out evaluation cost with 95 % bootstrap intervals vs vessel-steps and vs "
        "wall-clock seconds; writes curves.csv and curves.png and prints when the IQM first "
        "beats the base policy.",
    )
    parser.add_argument(
        "runs", nargs="+", metavar="RUN_DIR",
        help="cpf-train --out folders, cpf-distill run folders (--out, or --log if given) or "
        "cpf-fit-filter --out folders of runs with --eval-num-seeds",
    )  # fmt: skip
    parser.add_argument("--out", required=True, help="output folder (curves.csv, curves.png)")
    parser.add_argument(
        "--base-policy", default=None, nargs="+", metavar="NAME",
        help="analytic policies whose costs on the runs' evaluation seeds are the lines to "
        "beat, the first "
        "curves.csv's base_cost (default: the runs' evaluation at 0 vessel-steps, their base "
        "policy)",
    )  # fmt: skip
    return parser


def _amount(x: float, unit: str) -> str:
    """A point of an axis as printed: whole vessel-steps, seconds to 0.1."""
    return f"{x:,.0f} {unit}" if unit == "vessel-steps" else f"{x:,.1f} {unit}"


def _when(x: float | None, end: float, unit: str) -> str:
    """``from X unit``, or that it never happened up to the runs' last point ``end``."""
    if x is None:
        return f"never within the runs' evaluations (to {_amount(end, unit)})"
    return f"from {_amount(x, unit)}"


def curves_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-curves``: see ``cpf-curves --help``."""
    parser = _parser()
    args = parser.parse_args(argv)
    folders = [Path(run) for run in args.runs]
    try:
        runs = [read_run(folder) for folder in folders]
        lines = _lines(folders, runs, args.base_policy)
        curves = [steps_curve(runs), time_curve(runs)]
    except (ValueError, OSError, KeyError, json.JSONDecodeError) as error:
        parser.error(str(error))
    with atomic.staged_folder(args.out) as staging:
        atomic.write_text(staging / "curves.csv", curves_csv(curves, lines, len(runs)))
        drawing = figure(curves, lines, [run.name for run in runs])
        drawing.savefig(staging / "curves.png", dpi=100, metadata={"Software": None})
    steps, seconds = curves
    costs = ", ".join(f"{line} {cost:.6g}" for line, cost in lines.items())
    print(f"cpf-curves: {len(runs)} run{'s' if len(runs) != 1 else ''}; cost of {costs}")
    single = len(runs) == 1  # one training seed: a cost, no IQM and no interval
    for line, cost in lines.items():
        for curve, unit in ((steps, "vessel-steps"), (seconds, "s")):
            below, surely = first_below(curve, cost)
            if single:
                print(f"  cost below {line} {_when(below, float(curve.x[-1]), unit)}")
            else:
                print(
                    f"  IQM below {line} {_when(below, float(curve.x[-1]), unit)}; whole 95 % "
                    f"interval below {_when(surely, float(curve.x[-1]), unit)}"
                )
    final = (
        f"  final cost {steps.iqm[-1]:.6g} (one run: no interval; train several seeds for one)"
        if single
        else f"  final IQM {steps.iqm[-1]:.6g} [{steps.low[-1]:.6g}, {steps.high[-1]:.6g}]"
    )
    print(f"{final} at {steps.x[-1]:,.0f} vessel-steps; wrote {args.out}/curves.csv, curves.png")
    return 0


if __name__ == "__main__":
    sys.exit(curves_main())
