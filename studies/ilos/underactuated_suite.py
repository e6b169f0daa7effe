"""The suite's seven scenarios on hulls without a sway actuator: ``ilos`` against the others.

Each scenario of ``cpf_env.scenarios.suite.list_suite()`` with its sway limits set to 0
(``tau_max = (X, 0, N)``, ``tau_min = (-X, 0, -N)``: a propeller and a rudder), run on
the ``test`` split's seeds by ``cpf-bench``'s engine; the fully actuated designs keep
commanding a sway force, which the plant does not apply. Prints the mean
whole-episode cost and the final-window cross-track error per policy.

Usage::

    python studies/ilos/underactuated_suite.py --num-seeds 20 --policies nn_dsc ilos
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.suite import list_suite


def underactuated(name: str) -> Scenario:
    """Suite scenario ``name`` with no sway force, named ``<name>_no_sway``."""
    task = scenarios.get(name)
    tau_min, tau_max = task.tau_limits
    tau_min[:, 1], tau_max[:, 1] = 0.0, 0.0
    rows = lambda a: tuple(tuple(float(x) for x in row) for row in a)  # noqa: E731
    return task.replace(name=f"{name}_no_sway", tau_max=rows(tau_max), tau_min=rows(tau_min))


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=20)
    parser.add_argument("--policies", nargs="+", default=["nn_dsc", "ilos"])
    parser.add_argument("--scenarios", nargs="+", default=list_suite())
    args = parser.parse_args(argv)
    tasks = [underactuated(name) for name in args.scenarios]
    cells = run_bench(args.policies, tasks, num_seeds=args.num_seeds, figures=False)
    print("| scenario | " + " | ".join(args.policies) + " |")
    print("|---|" + "---|" * len(args.policies))
    for task in tasks:
        row = []
        for policy in args.policies:
            cell = next(c for c in cells if c.policy == policy and c.scenario == task.name)
            cost = float(np.mean(cell.metrics["cost"]))
            cross = float(np.mean(cell.metrics["cross_track_error_rms_window"]))
            row.append(
                f"{cost:.0f} ({cross:.2f} m, {int(np.sum(cell.metrics['terminated']))} failed)"
            )
        print(f"| {task.name} | " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
