"""Does ``mpc`` run on board? Its solve time per vessel and step, and the oracle's per episode.

``mpc`` plans per vessel from the vessel's own observation, so each vessel
solves its own problem: the time one ``act_batch`` call takes for one fleet
(B = 1), divided by the number of vessels, is what one vessel's computer
spends per control step. Revisions (every ``knot`` steps: sample and roll
out the candidates) cost far more than the steps in between (one feedback
evaluation), so the table reports both, and the real-time factor (time per
step / dt; below 1 keeps up with the control period) of the worst case
(p95 of the revision steps) and of the average step.

The oracle is timed per episode (B = 1, the whole horizon), as the bench
runs it.

Times are the process's CPU time (``time.process_time``), so a busy shared
machine slows the run but not the figures much; the wall time of the
oracle's episode is printed beside its CPU time. Run on one core for
numbers comparable across machines::

    NUMBA_NUM_THREADS=1 python benchmarks/mpc_timing.py --steps 400

Example:
    >>> rows = main(["--steps", "20", "--scenario", "bench_mild"])
    >>> sorted(rows)[:2]
    ['every_step_median_ms', 'every_step_p95_ms']
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np

import baselines
from cpf_env import FleetSim, scenarios


def _mpc_times(scenario_name: str, steps: int, seed: int) -> tuple[np.ndarray, int, int]:
    """CPU seconds per act_batch call of ``mpc`` on one fleet, the knot and n."""
    scenario = scenarios.get(scenario_name)
    sim = FleetSim(scenario)
    policy = baselines.make_policy("mpc", scenario)
    obs = sim.reset(seeds=[seed])
    policy.act_batch(obs)  # compile outside the timing
    policy.reset()
    obs = sim.reset(seeds=[seed])
    times = np.empty(steps)
    for k in range(steps):
        start = time.process_time()
        actions = policy.act_batch(obs)
        times[k] = time.process_time() - start
        obs = sim.step(actions)
    knot = baselines.mpc.RecedingHorizonGains().knot
    return times, knot, scenario.n


def _oracle_seconds(scenario_name: str, steps: int, seed: int) -> tuple[float, float]:
    """CPU and wall seconds of ``steps`` steps of the oracle on one fleet."""
    scenario = scenarios.get(scenario_name)
    sim = FleetSim(scenario)
    policy = baselines.make_policy("oracle", sim)
    obs = sim.reset(seeds=[seed])
    policy.act_batch(obs)  # compile outside the timing
    policy.reset()
    obs = sim.reset(seeds=[seed])
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(steps):
        obs = sim.step(policy.act_batch(obs))
    return time.process_time() - cpu, time.perf_counter() - wall


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    """Measure and print; return the figures by name (ms, or a ratio)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="bench_mild")
    parser.add_argument("--steps", type=int, default=400, help="control steps timed")
    parser.add_argument("--seed", type=int, default=10000)
    args = parser.parse_args(argv)
    times, knot, n = _mpc_times(args.scenario, args.steps, args.seed)
    per_vessel = times / n * 1e3  # ms per vessel and step
    revisions = per_vessel[::knot]
    dt_ms = scenarios.get(args.scenario).dt * 1e3
    oracle_cpu, oracle_wall = _oracle_seconds(args.scenario, args.steps, args.seed)
    rows = {
        "every_step_median_ms": float(np.median(per_vessel)),
        "every_step_p95_ms": float(np.percentile(per_vessel, 95)),
        "revision_median_ms": float(np.median(revisions)),
        "revision_p95_ms": float(np.percentile(revisions, 95)),
        "real_time_factor_mean": float(per_vessel.mean() / dt_ms),
        "real_time_factor_revision_p95": float(np.percentile(revisions, 95) / dt_ms),
        "oracle_cpu_seconds_per_1000_steps": 1000.0 * oracle_cpu / args.steps,
        "oracle_wall_seconds_per_1000_steps": 1000.0 * oracle_wall / args.steps,
    }
    print(f"mpc on {args.scenario}, {args.steps} steps, one fleet of {n}, dt = {dt_ms:g} ms (CPU)")
    for name, value in rows.items():
        print(f"  {name:32s} {value:10.4g}")
    return rows


if __name__ == "__main__":
    main()
