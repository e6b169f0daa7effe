"""``FleetSim.step`` on each hard-track scenario against the same fleet without its mechanisms.

The hard track adds a fix per vessel (a counter-based normal per axis on the
steps a fix is due, a uniform for its dropout) and a second path frame to the
observation, a lag and slew limit to the applied force, and the distances
between every two vessels for the separation term. This times the
simulator's step with zero actions (every fleet restarting when one ends) on
a hard scenario and on the same scenario with ideal sensors, instant
thrusters and no separation (the core suite's machinery; for a hard scenario
built on a core task, that task), alternately in one process, ``--rounds``
times each, and prints vessel-steps per second and the ratio hard / core of
the medians: the same load for both sides. Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/hard_track_step.py --fleets 1024 --rounds 5
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence

import numpy as np

from cpf_env import scenarios
from cpf_env.model.actuators import Thrusters
from cpf_env.model.sensors import Sensors
from cpf_env.scenarios.suite import list_suite
from cpf_env.sim.fleet import FleetSim


def _rate(sim: FleetSim, seconds: float) -> float:
    """Vessel-steps per second of ``sim.step`` with zero actions over about ``seconds``."""
    actions = np.zeros((sim.num_fleets, sim.n, sim.act_dim))
    sim.reset(seeds=list(range(sim.num_fleets)))
    for _ in range(5):  # warm-up, compiled already
        sim.step(actions)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        sim.step(actions)
        steps += 1
        if sim.truncated.any() or sim.arrays.terminated.any():
            sim.reset(seeds=list(range(sim.num_fleets)))
    return steps * sim.num_fleets * sim.n / (time.perf_counter() - start)


def main(argv: Sequence[str] | None = None) -> list[tuple[str, float, float]]:
    """Time every pair; print and return (hard scenario, its median rate, the core's)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fleets", type=int, default=1024, help="batch size B")
    parser.add_argument("--rounds", type=int, default=5, help="timings per side, alternated")
    parser.add_argument("--seconds", type=float, default=1.0, help="seconds per timing")
    parser.add_argument("--scenarios", nargs="+", default=list_suite("hard"), help="hard scenarios")
    args = parser.parse_args(argv)
    rows = []
    print(f"{'hard scenario':<26} {'hard':>12} {'core':>12} {'hard / core':>12}  (vessel-steps/s)")
    for name in args.scenarios:
        task = scenarios.get(name)
        bare = task.replace(sensors=Sensors(), thrusters=Thrusters(), separation=None)
        sims = [FleetSim(task, args.fleets), FleetSim(bare, args.fleets)]
        rates: list[list[float]] = [[], []]
        for _ in range(args.rounds):
            for side, sim in enumerate(sims):
                rates[side].append(_rate(sim, args.seconds))
        hard_rate, core_rate = (statistics.median(side) for side in rates)
        rows.append((name, hard_rate, core_rate))
        print(f"{name:<26} {hard_rate:>12,.0f} {core_rate:>12,.0f} {hard_rate / core_rate:>12.2f}")
    return rows


if __name__ == "__main__":
    main()
