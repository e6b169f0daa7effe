"""How much room each scenario leaves: the headroom table of a benchmark run.

Per scenario and for the cost over the whole episode (``cost``) and over
the final window (``cost_window``):

* J_ref, the reference's mean cost (``nn_dsc`` by default);
* J_best, the lowest mean cost of a deployable analytic policy that ran
  (``baselines.DEPLOYABLE``: the default set with ``mpc``, and the designs
  for the hard conditions, ``ilos`` and the filtered ones; trained agents and
  privileged references not), and its name;
* J_oracle, the mean cost of the headroom bound (``baselines.HEADROOM_REFERENCE``);
* headroom = 1 - J_oracle / J_best: the share of the best deployable
  analytic design's cost that a controller told everything removes, i.e.
  the room left to learning, with its 95 % paired bootstrap interval over
  the seeds both ran (``cpf_bench.stats.paired_headroom``). It is negative
  where the bound is not below the best deployable design
  (``oracle_not_lowest`` lists every policy that beats the bound on a
  scenario).

``room_closed`` scores every other policy (a trained agent, a policy of
one's own) against that room: (J_best - J) / (J_best - J_oracle), 0 at the
best deployable design of the scenario and 1 at the bound, per scenario and
as the IQM of the per-episode scores over the scenarios (each episode's cost
against the two means), with a bootstrap interval stratified by scenario:
the normalized score of the hard track, beside the one against the
reference (``report.normalized_score``).

Example:
    >>> from cpf_bench.report import CellResult
    >>> import numpy as np
    >>> cells = [
    ...     CellResult(p, "s", (0,), False, {"cost": np.array([j]), "cost_window": np.array([j])})
    ...     for p, j in (("nn_dsc", 10.0), ("mpc", 8.0), ("oracle", 6.0))
    ... ]
    >>> row = headroom_rows(cells)[0]
    >>> row["best"], round(row["headroom"], 3)
    ('mpc', 0.25)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from baselines import ALL_POLICIES, DEPLOYABLE, HEADROOM_REFERENCE
from cpf_bench.report import CellResult
from cpf_bench.stats import bootstrap_interval, iqm, paired_headroom

__all__ = [
    "RoomScore",
    "headroom_rows",
    "headroom_table",
    "oracle_not_lowest",
    "room_closed",
    "room_table",
]

#: The costs the table reads: (metric, label).
COSTS = (("cost", "whole episode"), ("cost_window", "final window"))


def _means(cells: Sequence[CellResult], metric: str) -> dict[tuple[str, str], float]:
    return {(c.policy, c.scenario): float(np.mean(c.metrics[metric])) for c in cells}


def _interval(
    cells: Sequence[CellResult], best: str, name: str, metric: str
) -> tuple[float, float]:
    """The paired interval of the headroom over the seeds ``best`` and the bound share."""
    by = {(c.policy, c.scenario): c for c in cells}
    x, y = by[(best, name)], by[(HEADROOM_REFERENCE, name)]
    shared = sorted(set(x.seeds) & set(y.seeds))
    if not shared:
        return float("nan"), float("nan")
    pick = [[cell.seeds.index(seed) for seed in shared] for cell in (x, y)]
    _, low, high = paired_headroom(x.metrics[metric][pick[0]], y.metrics[metric][pick[1]])
    return low, high


def headroom_rows(
    cells: Sequence[CellResult], reference: str = "nn_dsc", metric: str = "cost"
) -> list[dict[str, object]]:
    """One row per scenario where the bound and a deployable analytic policy ran.

    Keys: scenario, reference (J_ref or None), best (name), best_cost, oracle,
    headroom (1 - J_oracle / J_best), interval (its 95 % paired bootstrap interval).
    """
    means = _means(cells, metric)
    rows: list[dict[str, object]] = []
    for name in dict.fromkeys(cell.scenario for cell in cells):
        bound = means.get((HEADROOM_REFERENCE, name))
        deployable = {p: j for (p, s), j in means.items() if s == name and p in DEPLOYABLE}
        if bound is None or not deployable:
            continue
        best = min(deployable, key=lambda p: deployable[p])
        rows.append(
            {
                "scenario": name,
                "reference": means.get((reference, name)),
                "best": best,
                "best_cost": deployable[best],
                "oracle": bound,
                "headroom": 1.0 - bound / deployable[best] if deployable[best] else float("nan"),
                "interval": _interval(cells, best, name, metric),
            }
        )
    return rows


def oracle_not_lowest(
    cells: Sequence[CellResult], metric: str = "cost"
) -> list[tuple[str, str, float, float]]:
    """(scenario, policy, its mean, the bound's mean) for every policy with a lower mean."""
    means = _means(cells, metric)
    return [
        (s, p, j, means[(HEADROOM_REFERENCE, s)])
        for (p, s), j in means.items()
        if p != HEADROOM_REFERENCE
        and (HEADROOM_REFERENCE, s) in means
        and j < means[(HEADROOM_REFERENCE, s)]
    ]


def headroom_table(cells: Sequence[CellResult], reference: str = "nn_dsc") -> list[str]:
    """Markdown lines of the headroom table (whole episode and final window), or none."""
    whole, window = (headroom_rows(cells, reference, metric) for metric, _ in COSTS)
    if not whole:
        return []
    lines = [
        f"| scenario | J {reference} | best deployable analytic | J best | J {HEADROOM_REFERENCE} "
        "| headroom (95 % paired interval) | J best, final window | J oracle, final window "
        "| headroom, final window |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    by_name = {row["scenario"]: row for row in window}
    for row in whole:
        last = by_name[row["scenario"]]
        ref = "" if row["reference"] is None else f"{row['reference']:.4g}"
        low, high = cast(tuple[float, float], row["interval"])
        lines.append(
            f"| {row['scenario']} | {ref} | {row['best']} | {row['best_cost']:.4g} | "
            f"{row['oracle']:.4g} | {row['headroom']:.1%} ({low:.1%} to {high:.1%}) | "
            f"{last['best_cost']:.3g} "
            f"({last['best']}) | {last['oracle']:.3g} | {last['headroom']:.1%} |"
        )
    exceptions = [
        f"{policy} on {scenario} ({label}: {j:.4g} < {bound:.4g})"
        for metric, label in COSTS
        for scenario, policy, j, bound in oracle_not_lowest(cells, metric)
    ]
    if exceptions:
        lines += ["", f"Lower mean cost than {HEADROOM_REFERENCE}: " + "; ".join(exceptions) + "."]
    return lines


@dataclass(frozen=True)
class RoomScore:
    """The share of the room one policy closes (``room_closed``).

    Attributes:
        scenarios: Scenario -> (J_best - J) / (J_best - J_oracle) of the mean cost.
        iqm: IQM over every episode of those scenarios, each scored against its
            scenario's two means.
        interval: Its 95 % bootstrap interval, stratified by scenario.
    """

    scenarios: dict[str, float]
    iqm: float
    interval: tuple[float, float]


def room_closed(cells: Sequence[CellResult], metric: str = "cost") -> dict[str, RoomScore]:
    """Each policy outside ``baselines``: the share of the room it closes (module docstring).

    Scenarios where the bound is not below the best deployable design have no
    room and are left out.
    """
    rooms = {
        row["scenario"]: (float(row["best_cost"]), float(row["oracle"]))  # type: ignore[arg-type]
        for row in headroom_rows(cells, metric=metric)
        if float(row["oracle"]) < float(row["best_cost"])  # type: ignore[arg-type]
    }
    strata: dict[str, dict[str, np.ndarray]] = {}
    for cell in cells:
        if cell.policy in ALL_POLICIES or cell.scenario not in rooms:
            continue
        best, bound = rooms[cell.scenario]
        scores = (best - cell.metrics[metric]) / (best - bound)
        strata.setdefault(cell.policy, {})[cell.scenario] = scores
    return {
        policy: RoomScore(
            {name: float(scores.mean()) for name, scores in by_scenario.items()},
            float(iqm(np.concatenate(list(by_scenario.values())))),
            bootstrap_interval(list(by_scenario.values()), statistic=iqm),
        )
        for policy, by_scenario in strata.items()
    }


def room_table(cells: Sequence[CellResult]) -> list[str]:
    """Markdown lines of ``room_closed`` (whole-episode cost), or none without such a policy."""
    scored = room_closed(cells)
    if not scored:
        return []
    names = list(dict.fromkeys(name for score in scored.values() for name in score.scenarios))
    lines = [
        "| policy | IQM (95 % interval) | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for policy, score in scored.items():
        low, high = score.interval
        values = " | ".join(
            f"{score.scenarios[n]:.2f}" if n in score.scenarios else "" for n in names
        )
        lines.append(f"| {policy} | {score.iqm:.2f} ({low:.2f} to {high:.2f}) | {values} |")
    return lines
