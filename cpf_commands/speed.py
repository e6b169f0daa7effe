"""``cpf-speed``: throughput of the simulator, the env and the reference policy.

Measures, after a warm-up that triggers numba compilation:

* ``FleetSim.step`` for B = 1 and B = 1,024 (or ``--fleets``): dynamics, links,
  observations and rewards, in vessel-steps per second;
* the PettingZoo ``ParallelEnv`` (dict API, B = 1), in env-steps per second;
* a policy's ``act_batch`` for the same batch sizes: any the benchmark
  takes (``--policy``: an analytic design by name, the navigation-filtered
  ones included, or a trained agent's folder), by default the reference, on
  the first observation of an episode, restarted every ``RESTART_CALLS`` calls;
* the closed loop (policy + batched simulator), stepped from Python
  (``sim.step(policy.act_batch(obs))``) and, for a design whose whole step
  is compiled (``ClosedLoop.supports``), as one compiled call per step
  (``baselines.closed_loop.ClosedLoop.run(1)``, the same bits);
* the training path: ``agents.FleetVecEnv.step`` with a zero residual on the
  policy, for the same batch sizes (a baseline's name, the bases a residual
  learner takes; needs the ``rl`` extra; skipped without it);
* one whole episode of the scenario with the policy (B = 1), in seconds: for
  ``wang2014``, the paper's 150 s simulation, stepped from Python and (where
  supported) as one compiled call (``ClosedLoop.run(max_steps)``);
* with ``--bench-num-seeds N``: the wall time of ``cpf-bench``'s default evaluation
  (its default policies on the benchmark suite, N paired seeds, no files written);
* with ``--contention B``: ``FleetSim.step`` and ``FleetVecEnv.step`` at batch B
  alone and then next to one busy competitor process (a Python loop spinning on
  one core, as a neighbour on a shared machine would), in the same run, so
  that their ratio shows how the kernels' threads share a busy machine.

Prints a table, one line per (component, B): B fleets of n vessels, steps and
vessel-steps per second (or JSON with ``--json``: one record per line of the table,
with ``seconds`` added on the episode's). Numbers depend on the machine and
on ``NUMBA_NUM_THREADS``; report them with the command that produced them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from itertools import count
from typing import TYPE_CHECKING

import numpy as np
from tqdm.auto import tqdm

import cpf_env
from cpf_bench.evaluate import policy_label
from cpf_env.envs.policy import FleetPolicy
from cpf_env.sim.fleet import FleetSim

if TYPE_CHECKING:
    from agents import FleetVecEnv

__all__ = ["RESTART_CALLS", "measure", "speed_main"]

#: Calls of ``act_batch`` on one observation before the timed policy starts again: its internal
#: states (a navigation filter's estimate between fixes) stay those of an episode's start.
RESTART_CALLS = 50


def _rate(function: Callable[[], object], min_seconds: float) -> float:
    """Calls per second of ``function``, timed for at least ``min_seconds``."""
    function()
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < min_seconds:
        function()
        calls += 1
    return calls / elapsed


def _episode_seconds(
    scenario: str, policy: str, steps: int | None, compiled: bool
) -> tuple[float, int, int]:
    """Wall time (s) of one closed-loop episode at B = 1, its steps and n (after a warm-up).

    Stepped from Python, or (``compiled``) as one ``ClosedLoop.run`` call for
    the whole horizon, which does not stop at a termination.
    """
    from baselines.closed_loop import ClosedLoop
    from cpf_commands.common.policies import resolve_policy

    task = cpf_env.scenarios.get(scenario)
    horizon = task.max_steps if steps is None else int(steps)
    sim = FleetSim(task, num_fleets=1)
    reference = resolve_policy(policy, task)
    sim.reset(seeds=[0])
    if compiled:
        ClosedLoop(reference, sim).run(1)  # warm-up: compiled kernels
    else:
        reference.act_batch(sim.arrays.obs)  # warm-up: compiled kernels, first allocations
    reference.reset()
    start = time.perf_counter()
    obs = sim.reset(seeds=[0])
    if compiled:
        ClosedLoop(reference, sim).run(horizon)
    else:
        for _ in range(horizon):
            obs = sim.step(reference.act_batch(obs))
            if sim.arrays.terminated[0]:
                break
    return time.perf_counter() - start, int(sim.arrays.step[0]), sim.n


@contextlib.contextmanager
def busy_competitor() -> Iterator[subprocess.Popen[bytes]]:
    """One other process spinning on a core while the block runs (a busy neighbour)."""
    process = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.5)  # let it start spinning
        yield process
    finally:
        process.kill()
        process.wait()


def _bench_seconds(seeds: int) -> tuple[float, int]:
    """Wall time (s) of ``cpf-bench``'s default policies on the suite, and its episodes."""
    from cpf_commands.bench.run import default_policies, run_bench
    from cpf_env.scenarios.suite import list_suite

    start = time.perf_counter()
    cells = run_bench(default_policies(), list_suite(), num_seeds=seeds, out=None, figures=False)
    return time.perf_counter() - start, sum(len(cell.seeds) for cell in cells)


def _step_or_reset(sim: FleetSim, actions: np.ndarray, policy: FleetPolicy | None = None) -> None:
    """One step of every fleet, then ``_restart_if_ended``."""
    sim.step(actions)
    _restart_if_ended(sim, policy)


def _restart_if_ended(sim: FleetSim, policy: FleetPolicy | None = None) -> None:
    """Every fleet (and ``policy``) starts again once any episode has ended."""
    if sim.truncated.any() or sim.arrays.terminated.any():
        sim.reset()
        if policy is not None:
            policy.reset()


def _contended_steps(
    scenario: str, policy: str, batch: int
) -> list[tuple[str, Callable[[], object], int]]:
    """(label, one step, n) of ``FleetSim.step`` and ``FleetVecEnv.step`` at batch B."""
    task = cpf_env.scenarios.get(scenario)
    sim = FleetSim(task, num_fleets=batch)
    sim.reset(seeds=list(range(batch)))
    held = np.zeros((batch, task.n, sim.act_dim))

    steps: list[tuple[str, Callable[[], object], int]] = [
        ("FleetSim.step", lambda: _step_or_reset(sim, held), task.n)
    ]
    vec = _training_env(scenario, policy, batch)
    if vec is not None:
        zero = np.zeros((vec.num_envs, vec.controller.action_size), dtype=np.float32)
        label = f"FleetVecEnv.step (residual on {policy_label(policy)})"
        steps.append((label, lambda: vec.step(zero), vec.n))
    return steps


def _training_env(scenario: str, policy: str, batch: int) -> FleetVecEnv | None:
    """A reset ``FleetVecEnv`` (residual on ``policy``), or None.

    None without the ``rl`` extra, or for a policy that is not a baseline's name:
    a residual learner's base is named (``cpf-train --base-policy``).
    """
    from cpf_commands.common.policies import baseline_names

    if policy not in baseline_names():
        return None
    try:
        from agents import FleetVecEnv
    except ImportError:  # stable-baselines3 / torch not installed
        return None
    vec = FleetVecEnv(scenario, num_fleets=batch, base_policy=policy)
    vec.seed(0)
    vec.reset()
    return vec


def measure(
    scenario: str = "wang2014",
    fleets: Sequence[int] = (1, 1024),
    policy: str = "nn_dsc",
    min_seconds: float = 2.0,
    max_steps: int | None = None,
    progress: bool = False,
    contention: Sequence[int] = (),
    bench_num_seeds: int = 0,
) -> list[dict[str, object]]:
    """Measure throughputs; returns one row per (component, B).

    Args:
        scenario: Scenario name.
        fleets: Batch sizes B to time.
        policy: The policy: an analytic design by name or a trained agent's folder
            (``cpf_commands.common.policies.resolve_policy``).
        min_seconds: Timing per measurement (s).
        max_steps: Length of the timed whole episode (default: the scenario's
            ``max_steps``).
        progress: Show a progress bar (stderr), one tick per measurement.
        contention: Batch sizes at which ``FleetSim.step`` and ``FleetVecEnv.step``
            are timed alone and next to ``busy_competitor()``.
        bench_num_seeds: If > 0, time ``cpf-bench``'s default evaluation with this many seeds.
    """
    from baselines.closed_loop import ClosedLoop
    from cpf_commands.common.policies import resolve_policy

    label = policy_label(policy)
    compiled = ClosedLoop.supports(resolve_policy(policy, scenario))
    rows: list[dict[str, object]] = []
    bar = tqdm(
        total=(4 + compiled) * len(fleets)
        + 2
        + compiled
        + 4 * len(contention)
        + (bench_num_seeds > 0),
        disable=not progress,
        desc="cpf-speed",
    )

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
        reference = resolve_policy(policy, sim.scenario)
        obs = sim.reset(seeds=list(range(batch))).copy()
        actions = reference.act_batch(obs)
        n = sim.n

        def sim_step(sim: FleetSim = sim, actions: np.ndarray = actions) -> None:
            _step_or_reset(sim, actions)

        calls = count()

        def policy_step(
            reference: FleetPolicy = reference, obs: np.ndarray = obs, calls: Iterator[int] = calls
        ) -> None:
            if next(calls) % RESTART_CALLS == 0:  # a filter on one held fix drifts: start again
                reference.reset()
            reference.act_batch(obs)

        def closed_loop(sim: FleetSim = sim, reference: FleetPolicy = reference) -> None:
            _step_or_reset(sim, reference.act_batch(sim.arrays.obs), reference)

        timed: list[tuple[str, Callable[[], object]]] = [
            ("FleetSim.step", sim_step),
            (f"{label}.act_batch", policy_step),
            (f"{label} + FleetSim.step", closed_loop),
        ]
        if compiled:
            loop = ClosedLoop(reference, sim)

            def compiled_loop(
                sim: FleetSim = sim, loop: ClosedLoop = loop, reference: FleetPolicy = reference
            ) -> None:
                loop.run(1)
                _restart_if_ended(sim, reference)

            timed.append((f"{label} + FleetSim, ClosedLoop.run(1)", compiled_loop))
        for component, function in timed:
            bar.set_postfix_str(f"{component}, B = {batch}")
            sim.reset(seeds=list(range(batch)))  # each timing from a fresh episode
            reference.reset()
            add(component, batch, n, _rate(function, min_seconds))
            bar.update()

    env = cpf_env.parallel_env(scenario)
    _observations, _ = env.reset(seed=0)
    action = {agent: env.action_space(agent).sample() * 0 for agent in env.possible_agents}

    def env_step() -> None:
        _, _, terminations, truncations, _ = env.step(action)
        if any(terminations.values()) or any(truncations.values()):
            env.reset()

    bar.set_postfix_str("ParallelEnv.step")
    add("ParallelEnv.step", 1, env.scenario.n, _rate(env_step, min_seconds))
    bar.update()
    for batch in fleets:  # the training path: FleetVecEnv with the residual on the policy
        vec = _training_env(scenario, policy, batch)
        if vec is None:
            continue
        zero = np.zeros((vec.num_envs, vec.controller.action_size), dtype=np.float32)

        def vec_step(vec: FleetVecEnv = vec, zero: np.ndarray = zero) -> None:
            vec.step(zero)

        bar.set_postfix_str(f"FleetVecEnv.step, B = {batch}")
        add(f"FleetVecEnv.step (residual on {label})", batch, vec.n, _rate(vec_step, min_seconds))
        bar.update()
    for batch in contention:
        for component, contended, n in _contended_steps(scenario, policy, batch):
            for label in ("alone", "1 busy competitor"):
                with contextlib.nullcontext() if label == "alone" else busy_competitor():
                    bar.set_postfix_str(f"{component}, B = {batch}, {label}")
                    add(f"{component}, {label}", batch, n, _rate(contended, min_seconds))
                    bar.update()
    if bench_num_seeds > 0:
        bar.set_postfix_str("cpf-bench default run")
        seconds, episodes = _bench_seconds(bench_num_seeds)
        add(f"cpf-bench default ({episodes} episodes)", 1, 0, episodes / seconds)
        rows[-1]["seconds"] = seconds
        bar.update()
    for in_one_call in (False, True)[: 1 + compiled]:
        bar.set_postfix_str("whole episode" + (", compiled" if in_one_call else ""))
        seconds, steps, n = _episode_seconds(scenario, policy, max_steps, in_one_call)
        how = "ClosedLoop.run" if in_one_call else "stepped"
        add(f"{scenario} episode ({steps} steps), {label}, {how}", 1, n, steps / seconds)
        rows[-1]["seconds"] = seconds
        bar.update()
    bar.close()
    return rows


def speed_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-speed``: see ``cpf-speed --help``."""
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-speed",
        description="Throughput of the simulator, the PettingZoo env and a policy (after a "
        "warm-up that compiles the kernels), and the wall time of one whole episode.",
    )
    parser.add_argument(
        "--scenario",
        default="wang2014",
        choices=cpf_env.scenarios.list_scenarios(),
        metavar="NAME",
        help="registered scenario (default: wang2014)",
    )
    parser.add_argument(
        "--fleets",
        type=int,
        nargs="+",
        default=[1, 1024],
        metavar="B",
        help="batch sizes to time (default: 1 1024)",
    )
    parser.add_argument(
        "--policy",
        default="nn_dsc",
        metavar="NAME_OR_FOLDER",
        help="any policy cpf-bench --policies takes: a baseline name (mpc_tuned_mmae on a "
        "scenario with sensors, say), package.module:NAME, a trained agent's folder or an "
        ".onnx file; the residual route (FleetVecEnv.step) is timed for a baseline's name "
        "only (default: nn_dsc)",
    )
    parser.add_argument(
        "--seconds", type=float, default=2.0, help="timing per measurement in s (default: 2)"
    )
    parser.add_argument(
        "--max-steps",
        type=int,
        default=None,
        metavar="N",
        help="length of the timed episode (default: the scenario's max_steps)",
    )
    parser.add_argument(
        "--contention",
        type=int,
        nargs="*",
        default=[],
        metavar="B",
        help="also time FleetSim.step and FleetVecEnv.step at these batch sizes alone and next "
        "to one busy competitor process (e.g. --contention 256)",
    )
    parser.add_argument(
        "--bench-num-seeds",
        type=int,
        default=0,
        metavar="N",
        help="also time cpf-bench's default evaluation (its default policies, the suite) with N "
        "seeds, e.g. 10 (default: 0, not timed)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    from cpf_commands.common.policies import resolve_policy

    try:
        resolve_policy(args.policy, args.scenario)
    except ValueError as error:
        parser.error(f"--policy {args.policy}: {error}")
    rows = measure(
        args.scenario,
        args.fleets,
        args.policy,
        args.seconds,
        max_steps=args.max_steps,
        progress=not args.quiet,
        contention=args.contention,
        bench_num_seeds=args.bench_num_seeds,
    )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    width = max(28, *(len(str(row["component"])) for row in rows))
    print(
        f"{'component':<{width}} {'B':>6} {'n':>3} {'steps/s':>12} {'vessel-steps/s':>16}"
        f" {'seconds':>8}"
    )
    for row in rows:
        seconds = f"{row['seconds']:>8.2f}" if "seconds" in row else ""
        print(
            f"{row['component']:<{width}} {row['B']:>6} {row['n']:>3} "
            f"{row['steps_per_s']:>12,.0f} {row['vessel_steps_per_s']:>16,.0f} {seconds}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(speed_main())
