"""The suite's seven scenarios on hulls without a sway actuator: ``ilos`` against the others.

Each scenario of ``cpf_env.scenarios.suite.list_suite()`` with its sway limits set to 0
(``cpf_env.scenarios.hard.without_sway``: a propeller and a rudder), run on
the ``test`` split's seeds by ``cpf-bench``'s engine; the fully actuated designs keep
commanding a sway force, which the plant does not apply. Prints the mean
whole-episode cost and the final-window cross-track error per policy.

``--ilos-gains`` runs ``ilos`` with other gains and ``--seed`` from other
seeds (the gains were chosen on training seeds 0-3 of ``bench_saturation``).
Usage::

    python studies/ilos/underactuated_suite.py --num-seeds 20 --policies nn_dsc ilos
    python studies/ilos/underactuated_suite.py --num-seeds 4 --seed 0 \
        --scenarios bench_saturation --ilos-gains k_along=0.3 k_surge=1
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Sequence

import numpy as np

from baselines import make_policy
from cpf_commands.bench.run import run_bench
from cpf_env import scenarios
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.hard import without_sway
from cpf_env.scenarios.splits import EVALUATION_SEED
from cpf_env.scenarios.suite import list_suite


def underactuated(name: str) -> Scenario:
    """Suite scenario ``name`` without sway (``hard.without_sway``), named ``<name>_no_sway``."""
    return without_sway(scenarios.get(name)).replace(name=f"{name}_no_sway")


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=20)
    parser.add_argument("--policies", nargs="+", default=["nn_dsc", "ilos"])
    parser.add_argument("--scenarios", nargs="+", default=list_suite())
    parser.add_argument("--seed", type=int, default=EVALUATION_SEED, help="seed of episode 0")
    parser.add_argument("--ilos-gains", nargs="*", default=[], metavar="NAME=VALUE",
                        help="ilos gains (ILOSGains fields), e.g. k_along=3")  # fmt: skip
    args = parser.parse_args(argv)
    gains = {key: float(value) for key, value in (item.split("=") for item in args.ilos_gains)}
    tasks = [underactuated(name) for name in args.scenarios]
    policies = {
        name: functools.partial(make_policy, name, **gains) if name == "ilos" else name
        for name in args.policies
    }
    cells = run_bench(policies, tasks, num_seeds=args.num_seeds, seed=args.seed, figures=False)
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
