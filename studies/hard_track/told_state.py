"""How much of the hard track's room is the sensors: the designs told the true state.

For each hard scenario with sensors, the same scenario with ideal sensors
(``Sensors()``: the true pose and velocity every step) is the design *told the
true present state*: the plant, the seeds and the cost are unchanged, only the
observation is exact. Prints, per scenario, the mean whole-episode cost of
each policy told the state, beside the hard-track costs of ``--hard`` (a
``cpf-bench --track hard`` folder: the deployable design on the sensors and
the ``oracle``), and the share of the room (J_deployable - J_oracle) that
telling the state closes. Usage::

    python studies/hard_track/told_state.py --hard results/hard_test --num-seeds 20
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cpf_bench.report import read_episodes_csv
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.model.sensors import Sensors
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.suite import list_suite


def told_state(name: str) -> Scenario:
    """Hard scenario ``name`` with ideal sensors, named ``<name>_told_state``."""
    return scenarios.get(name).replace(name=f"{name}_told_state", sensors=Sensors())


def _hard_costs(folder: Path) -> dict[tuple[str, str], float]:
    """(policy, scenario) -> mean cost over the episodes of a bench folder."""
    cells = read_episodes_csv((folder / "episodes.csv").read_text())
    return {(cell.policy, cell.scenario): float(np.mean(cell.metrics["cost"])) for cell in cells}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hard", type=Path, required=True, help="a cpf-bench --track hard folder")
    parser.add_argument("--num-seeds", type=int, default=20)
    parser.add_argument("--deployable", default="mpc_tuned_ekf", help="the design on the sensors")
    parser.add_argument("--told", default="mpc_tuned", help="the design told the state")
    args = parser.parse_args(argv)
    names = [name for name in list_suite("hard") if not scenarios.get(name).sensors.ideal]
    tasks = [told_state(name) for name in names]
    cells = run_bench([args.told], tasks, num_seeds=args.num_seeds, figures=False)
    hard = _hard_costs(args.hard)
    print(f"| scenario | {args.deployable} | {args.told} told the state | oracle | room closed |")
    print("|---|---|---|---|---|")
    for name, cell in zip(names, cells, strict=True):
        told = float(np.mean(cell.metrics["cost"]))
        deployable, bound = hard[(args.deployable, name)], hard[("oracle", name)]
        closed = (deployable - told) / (deployable - bound)
        print(f"| {name} | {deployable:.1f} | {told:.1f} | {bound:.1f} | {closed:.0%} |")


if __name__ == "__main__":
    main()
