"""``cpf-speed``: throughput of the simulator, the env and the reference policy.

Measures, after a warm-up that triggers numba compilation:

* ``FleetSim.step`` for B = 1 and B = 1,024 (or ``--fleets``): dynamics, links,
  observations and rewards, in vessel-steps per second;
* the PettingZoo ``ParallelEnv`` (dict API, B = 1), in env-steps per second;
* the reference policy's ``act_batch`` for the same batch sizes;
* the closed loop (policy + batched simulator).

Prints a table (or JSON with ``--json``). Numbers depend on the machine and
on ``NUMBA_NUM_THREADS``; report them with the command that produced them.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable, Sequence

import numpy as np

import cpf_env
from cpf_env.sim import FleetSim

__all__ = ["measure", "speed_main"]


def _rate(function: Callable[[], object], min_seconds: float) -> float:
    """Calls per second of ``function``, timed for at least ``min_seconds``."""
    function()
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < min_seconds:
        function()
        calls += 1
    return calls / elapsed


def measure(
    scenario: str = "wang2014",
    fleets: Sequence[int] = (1, 1024),
    policy: str = "nn_dsc",
    min_seconds: float = 2.0,
) -> list[dict[str, object]]:
    """Measure throughputs; returns one row per (component, B)."""
    from baselines import make_policy

    rows: list[dict[str, object]] = []

    def add(component: str, batch: int, n: int, per_second: float) -> None:
        rows.append(
            {
                "component": component,
                "B": batch,
                "n": n,
                "steps_per_s": round(per_second, 1),
                "vessel_steps_per_s": round(per_second * batch * n, 1),
            }
        )

    for batch in fleets:
        sim = FleetSim(cpf_env.scenarios.get(scenario), num_fleets=batch)
        reference = make_policy(policy, sim)
        obs = sim.reset(seeds=list(range(batch))).copy()
        actions = reference.act_batch(obs)
        n = sim.n

        def sim_step(sim: FleetSim = sim, actions: np.ndarray = actions) -> None:
            sim.step(actions)
            if sim.truncated.any() or sim.arrays.terminated.any():
                sim.reset()

        def policy_step(reference: object = reference, obs: np.ndarray = obs) -> None:
            reference.act_batch(obs)  # type: ignore[attr-defined]

        def closed_loop(sim: FleetSim = sim, reference: object = reference) -> None:
            sim_step(sim, reference.act_batch(sim.arrays.obs))  # type: ignore[attr-defined]

        add("FleetSim.step", batch, n, _rate(sim_step, min_seconds))
        add(f"{policy}.act_batch", batch, n, _rate(policy_step, min_seconds))
        add(f"{policy} + FleetSim.step", batch, n, _rate(closed_loop, min_seconds))

    env = cpf_env.parallel_env(scenario)
    _observations, _ = env.reset(seed=0)
    action = {agent: env.action_space(agent).sample() * 0 for agent in env.possible_agents}

    def env_step() -> None:
        _, _, terminations, truncations, _ = env.step(action)
        if any(terminations.values()) or any(truncations.values()):
            env.reset()

    add("ParallelEnv.step", 1, env.scenario.n, _rate(env_step, min_seconds))
    return rows


def speed_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-speed``: see ``cpf-speed --help``."""
    parser = argparse.ArgumentParser(prog="cpf-speed", description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="wang2014")
    parser.add_argument("--fleets", type=int, nargs="+", default=[1, 1024])
    parser.add_argument("--policy", default="nn_dsc")
    parser.add_argument("--seconds", type=float, default=2.0, help="timing per measurement")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(argv)
    rows = measure(args.scenario, args.fleets, args.policy, args.seconds)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'component':<28} {'B':>6} {'n':>3} {'steps/s':>12} {'vessel-steps/s':>16}")
    for row in rows:
        print(
            f"{row['component']:<28} {row['B']:>6} {row['n']:>3} "
            f"{row['steps_per_s']:>12,.0f} {row['vessel_steps_per_s']:>16,.0f}"
        )
    return 0
