"""The sweep that chose ``mpc_tuned``'s estimator: v0-estimator settings on training seeds.

    NUMBA_NUM_THREADS=1 python studies/headroom/mpc_tuning.py   # seeds 0-4, every suite scenario
    NUMBA_NUM_THREADS=1 python studies/headroom/mpc_tuning.py --num-seeds 2 --scenarios bench_mild
    NUMBA_NUM_THREADS=1 python studies/headroom/mpc_tuning.py --oracle --scenarios bench_saturation

Runs ``mpc_tuned`` (``baselines.mpc_tuned``) at each setting of ``GRID`` (gains
k5 = k6 in 1/s, and the speed estimate's rate limit as a fraction of the
nominal surge acceleration at the force limit; ``inf`` is no limit, so
``1, inf`` is ``mpc`` itself) on every suite scenario over the training
seeds 0, 1, ... (``cpf_env.scenarios.splits.check_training`` refuses
evaluation seeds: the evaluation splits play no part in the choice), and
prints a markdown table of the mean episode cost per scenario and setting,
then each setting's geometric mean over scenarios of its cost over
``mpc``'s and the number of scenarios where it costs more than ``mpc``.
With ``--oracle``, the ``oracle`` instead, without its reference-speed ramp
and with each rate of ``ORACLE_RATES`` (``baselines.mpc.SPEED_RATE`` is its
default).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from baselines.mpc import OraclePolicy
from baselines.mpc_tuned import MPCTuned
from cpf_bench.rollout import rollout
from cpf_env import scenarios
from cpf_env.scenarios import splits
from cpf_env.scenarios.suite import list_suite

#: The oracle's ramps (fractions of the nominal surge acceleration; inf: none) under --oracle.
ORACLE_RATES = (math.inf, 0.25, 0.5)
#: (k5 = k6 in 1/s, speed-rate fraction) settings; the first is ``mpc``.
GRID = ((1.0, math.inf), (3.0, math.inf), (5.0, math.inf), (5.0, 0.5), (5.0, 0.25), (5.0, 0.1),
        (8.0, 0.25))  # fmt: skip


def _label(gain: float, rate: float) -> str:
    return "mpc" if (gain, rate) == GRID[0] else f"k {gain:g}, rate {rate:g}"


def _oracle(names: list[str], seeds: list[int]) -> None:
    """Print the oracle's mean cost per scenario at each of ``ORACLE_RATES``."""
    print("| scenario | " + " | ".join(f"oracle, ramp {rate:g}" for rate in ORACLE_RATES) + " |")
    print("|---" * (len(ORACLE_RATES) + 1) + "|")
    for name in names:
        splits.check_training(name, seeds)
        scenario = scenarios.get(name)
        row = [rollout(OraclePolicy(scenario, speed_rate=rate), scenario, seeds)["cost"]
               for rate in ORACLE_RATES]  # fmt: skip
        print(f"| `{name}` | " + " | ".join(f"{np.mean(cost):.2f}" for cost in row) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-seeds", type=int, default=5, help="training seeds 0 .. N-1")
    parser.add_argument("--scenarios", nargs="+", default=list_suite())
    parser.add_argument("--oracle", action="store_true", help="sweep the oracle's ramp instead")
    args = parser.parse_args()
    if args.oracle:
        _oracle(args.scenarios, list(range(args.num_seeds)))
        return
    seeds = list(range(args.num_seeds))
    costs: dict[tuple[str, str], float] = {}
    start = time.perf_counter()
    for name in args.scenarios:
        splits.check_training(name, seeds)
        scenario = scenarios.get(name)
        for gain, rate in GRID:
            policy = MPCTuned(scenario, speed_rate=rate, k5=gain, k6=gain)
            cost = rollout(policy, scenario, seeds)["cost"]
            costs[(name, _label(gain, rate))] = float(np.mean(cost))
    labels = [_label(*setting) for setting in GRID]
    print(f"Mean episode cost over training seeds 0-{args.num_seeds - 1}\n")
    print("| scenario | " + " | ".join(labels) + " |")
    print("|---" * (len(labels) + 1) + "|")
    for name in args.scenarios:
        row = [f"{costs[(name, label)]:.2f}" for label in labels]
        print(f"| `{name}` | " + " | ".join(row) + " |")
    ratios = {
        label: [costs[(name, label)] / costs[(name, "mpc")] for name in args.scenarios]
        for label in labels
    }
    print("| geometric mean / `mpc` | " + " | ".join(
        f"{math.exp(np.mean(np.log(r))):.3f}" for r in ratios.values()) + " |")  # fmt: skip
    print("| scenarios above `mpc` | " + " | ".join(
        str(sum(x > 1.0 for x in r)) for r in ratios.values()) + " |")  # fmt: skip
    print(f"\n{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
