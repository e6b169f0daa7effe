"""Per-step cost of the env paths around the compiled step, and a same-run comparison.

Times one step (microseconds, after a warm-up) of each path a user waits on,
at the batch sizes given:

* ``FleetSim.step`` (zero actions; every fleet restarts when one ends);
* the PettingZoo ``ParallelEnv.step`` (one fleet, dict actions, full infos);
* ``agents.FleetVecEnv.step`` with a zero residual on ``nn_dsc`` (needs the
  ``rl`` extra): the SB3 training path, policy included;
* ``TorchRLFleetEnv.step_and_maybe_reset`` in the residual form on ``nn_dsc``
  with a zero action (needs the ``torchrl`` extra): a collector's step.

With ``--vs ROOT`` the same cells are timed for the package under ``ROOT``
(another checkout, e.g. the main branch) and for this one, in turns
(this, other, this, other, ...: one fresh process each, ``PYTHONPATH`` pointing
at the checkout), so that both see the same machine load; each cell's
figure is the median over the rounds. Report the load with the figures.

``--clock cpu`` times the process's CPU time instead of the wall clock: on a
shared machine a waiting process's wall clock runs on while its CPU time
does not, so the comparison is steadier; it is meaningful with one thread
(``NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1``), since it sums every thread's
time, spinning included. Usage::

    python benchmarks/step_overhead.py --seconds 1
    python benchmarks/step_overhead.py --vs /path/to/main --rounds 3 --seconds 1 --clock cpu
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

SCENARIO = "wang2014"
POLICY = "nn_dsc"


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def _seconds_per_call(
    function: Callable[[], object], min_seconds: float, clock: Callable[[], float]
) -> float:
    """Mean time (s, of ``clock``) of one call of ``function``, for at least ``min_seconds``."""
    for _ in range(3):  # warm-up: compiled kernels, first allocations
        function()
    calls, start = 0, clock()
    while (elapsed := clock() - start) < min_seconds:
        function()
        calls += 1
    return elapsed / calls


def _sim_step(batch: int) -> Callable[[], object]:
    import cpf_env
    from cpf_env.sim.fleet import FleetSim

    sim = FleetSim(cpf_env.scenarios.get(SCENARIO), num_fleets=batch)
    sim.reset(seeds=list(range(batch)))
    zero = np.zeros((batch, sim.n, sim.act_dim))

    def step() -> None:
        sim.step(zero)
        if sim.truncated.any() or sim.arrays.terminated.any():
            sim.reset()

    return step


def _parallel_step(batch: int) -> Callable[[], object]:
    import cpf_env

    if batch != 1:
        raise ValueError("the ParallelEnv is one fleet")
    env = cpf_env.parallel_env(SCENARIO)
    env.reset(seed=0)
    actions = {a: np.zeros(env.action_space(a).shape, np.float32) for a in env.possible_agents}

    def step() -> None:
        env.step(actions)
        if not env.agents:
            env.reset()

    return step


def _vec_step(batch: int) -> Callable[[], object]:
    from agents import FleetVecEnv

    vec = FleetVecEnv(SCENARIO, num_fleets=batch, base_policy=POLICY)
    vec.seed(0)
    vec.reset()
    zero = np.zeros((vec.num_envs, vec.controller.action_size), dtype=np.float32)
    return lambda: vec.step(zero)


def _torchrl_step(batch: int) -> Callable[[], object]:
    import torch

    import cpf_env
    from baselines import make_policy
    from cpf_env.envs.torchrl_env import TorchRLFleetEnv

    base = make_policy(POLICY, cpf_env.scenarios.get(SCENARIO))
    env = TorchRLFleetEnv(SCENARIO, num_fleets=batch, seed=0, base_policy=base)
    zero = torch.zeros(batch, env.n, env.action_size)
    data = env.reset()

    def step() -> None:
        nonlocal data
        data.set(("vessel", "action"), zero)
        data = env.step_and_maybe_reset(data)[1]

    return step


PATHS: dict[str, Callable[[int], Callable[[], object]]] = {
    "FleetSim.step": _sim_step,
    "ParallelEnv.step": _parallel_step,
    f"FleetVecEnv.step (residual on {POLICY})": _vec_step,
    f"TorchRLFleetEnv step (residual on {POLICY})": _torchrl_step,
}
CELLS = (
    ("FleetSim.step", (1, 16, 1024)),
    ("ParallelEnv.step", (1,)),
    (f"FleetVecEnv.step (residual on {POLICY})", (1, 16, 1024)),
    (f"TorchRLFleetEnv step (residual on {POLICY})", (16, 1024)),
)


def measure(seconds: float, clock: str = "wall") -> dict[str, float | None]:
    """Microseconds per step of every cell (``"path, B = b"``); None where an extra is missing."""
    figures: dict[str, float | None] = {}
    for path, batches in CELLS:
        for batch in batches:
            try:
                step = PATHS[path](batch)
            except ImportError:
                figures[f"{path}, B = {batch}"] = None
                continue
            seconds_per_step = _seconds_per_call(step, seconds, CLOCKS[clock])
            figures[f"{path}, B = {batch}"] = 1e6 * seconds_per_step
    return figures


def _measure_in(root: Path, seconds: float, clock: str) -> dict[str, float | None]:
    """``measure`` run in a fresh process on the package under ``root``."""
    environment = {**os.environ, "PYTHONPATH": str(root)}
    command = [sys.executable, __file__, "--json", "--seconds", str(seconds), "--clock", clock]
    done = subprocess.run(
        command, env=environment, cwd=root, capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def _median(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return statistics.median(known) if known else None


def _compare(other: Path, rounds: int, seconds: float, clock: str) -> None:
    """Both checkouts in turns; print the median microseconds per step and their ratio."""
    here = Path(__file__).resolve().parents[1]
    runs: dict[Path, list[dict[str, float | None]]] = {here: [], other: []}
    for _ in range(rounds):
        for root in (here, other):
            runs[root].append(_measure_in(root, seconds, clock))
    print(f"| cell | this checkout (us/step, {clock}) | {other} (us/step) | speed-up |")
    print("|---|---|---|---|")
    for cell in runs[here][0]:
        new = _median([run[cell] for run in runs[here]])
        old = _median([run[cell] for run in runs[other]])
        ratio = f"{old / new:.2f}x" if new and old else "-"
        show = [f"{v:,.1f}" if v is not None else "not run" for v in (new, old)]
        print(f"| {cell} | {show[0]} | {show[1]} | {ratio} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="timing per cell (s)")
    parser.add_argument("--vs", type=Path, help="another checkout to time in turns with this one")
    parser.add_argument("--rounds", type=int, default=3, help="turns of each checkout with --vs")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall", help="what is timed")
    parser.add_argument("--json", action="store_true", help="print one JSON line (for --vs)")
    args = parser.parse_args()
    if args.vs is not None:
        if not (args.vs / "cpf_env" / "__init__.py").is_file():
            raise SystemExit(f"--vs {args.vs}: no cpf_env package there; give a checkout's root.")
        _compare(args.vs.resolve(), args.rounds, args.seconds, args.clock)
        return
    figures = measure(args.seconds, args.clock)
    if args.json:
        print(json.dumps(figures))
        return
    for cell, value in figures.items():
        print(f"{cell}: {'not run' if value is None else f'{value:,.1f} us/step'}")


if __name__ == "__main__":
    main()
