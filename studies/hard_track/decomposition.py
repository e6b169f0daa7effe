"""What a learner could win on the hard track: the room split by the information that closes it.

For each hard scenario, the best deployable analytic design of a
``cpf-bench --track hard`` folder (``--hard``: the lowest mean cost among
``baselines.DEPLOYABLE``) is run again, on the same seeds, plant and cost,
told what a vessel lacks, one piece at a time:

* **told the state**: ideal sensors (``Sensors()``: the true pose and
  velocity every step), where the scenario has sensors;
* **told the neighbours**: ideal links (``LinkImpairments()``: every packet,
  at once), where its links lose or delay packets;
* **told both**, where it has both.

Each prints the share of the room (J_best - J_oracle) it closes, and the rest
is what the ``oracle`` has beyond both: the true model and future
disturbances, and a centralized plan over the fleet. A negative share means
the design does worse told the truth (a filter's smoothing can calm a
feedback that a thruster lag makes ring); where the bound is not below the
design there is no room to split. Usage::

    python studies/hard_track/decomposition.py --hard results/hard_test --num-seeds 10
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from baselines import DEPLOYABLE
from cpf_bench.report import CellResult, read_episodes_csv
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.model.links import LinkImpairments
from cpf_env.model.sensors import Sensors
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.suite import list_suite

#: What each variant tells the design: name suffix -> the fields replaced.
TOLD = {
    "state": {"sensors": Sensors()},
    "neighbours": {"links": LinkImpairments()},
    "both": {"sensors": Sensors(), "links": LinkImpairments()},
}


def variants(name: str) -> dict[str, Scenario]:
    """The ``TOLD`` variants that change hard scenario ``name``, named ``<name>_told_<kind>``."""
    task = scenarios.get(name)
    missing = {"state": not task.sensors.ideal, "neighbours": task.links != LinkImpairments()}
    missing["both"] = missing["state"] and missing["neighbours"]
    return {
        kind: task.replace(name=f"{name}_told_{kind}", **TOLD[kind])  # type: ignore[arg-type]
        for kind, applies in missing.items()
        if applies
    }


def _mean(cell: CellResult, seeds: set[int]) -> float:
    """Mean cost of ``cell`` over ``seeds`` (each must be there)."""
    rows = [k for k, seed in enumerate(cell.seeds) if seed in seeds]
    if len(rows) != len(seeds):
        raise ValueError(
            f"{cell.policy} on {cell.scenario} lacks some of the seeds {sorted(seeds)}."
        )
    return float(np.mean(cell.metrics["cost"][rows]))


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    """Print and return per hard scenario the best design, its costs told each thing, the bound."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hard", type=Path, required=True, help="a cpf-bench --track hard folder")
    parser.add_argument("--num-seeds", type=int, default=10)
    parser.add_argument("--scenarios", nargs="+", default=list_suite("hard"))
    args = parser.parse_args(argv)
    cells = read_episodes_csv((args.hard / "episodes.csv").read_text())
    seeds = set(sorted({seed for cell in cells for seed in cell.seeds})[: args.num_seeds])
    first = min(seeds)
    rows: list[dict[str, object]] = []
    print("| scenario | best deployable | J_best | told the state | told the neighbours | "
          "told both | oracle | rest (model, future, central plan) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for name in args.scenarios:
        here = {cell.policy: cell for cell in cells if cell.scenario == name}
        deployable = {p: _mean(c, seeds) for p, c in here.items() if p in DEPLOYABLE}
        best = min(deployable, key=deployable.__getitem__)
        j_best, j_oracle = deployable[best], _mean(here["oracle"], seeds)
        room = j_best - j_oracle
        told = variants(name)
        costs = {}
        if told:
            ran = run_bench([best], list(told.values()), num_seeds=len(seeds), seed=first,
                            figures=False)  # fmt: skip
            costs = {
                kind: float(np.mean(c.metrics["cost"])) for kind, c in zip(told, ran, strict=True)
            }
        if room > 0.0:
            closed = {kind: f"{(j_best - cost) / room:+.0%}" for kind, cost in costs.items()}
            rest = f"{1.0 - max((j_best - c) / room for c in [j_best, *costs.values()]):.0%}"
        else:  # the bound is not below the design: no room to split
            closed = dict.fromkeys(costs, "no room")
            rest = "no room"
        text = {kind: f"{costs[kind]:.1f} ({closed[kind]})" for kind in costs}
        print(
            f"| {name} | {best} | {j_best:.1f} | {text.get('state', '-')} | "
            f"{text.get('neighbours', '-')} | {text.get('both', '-')} | {j_oracle:.1f} | "
            f"{rest} |"
        )
        rows.append({"scenario": name, "best": best, "J_best": j_best, "oracle": j_oracle,
                     "told": costs})  # fmt: skip
    return rows


if __name__ == "__main__":
    main()
