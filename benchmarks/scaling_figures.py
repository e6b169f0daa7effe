"""How far one machine goes, and what a sweep costs on 1, 10 and 100 nodes.

Measures, on this machine:

1. **Memory per fleet**: the simulator's arrays (exact, ``nbytes``), and the
   resident memory of a whole training process (``FleetVecEnv`` + PPO with
   its rollout buffer, after one rollout) at two fleet counts: the slope is
   the memory per extra fleet, the intercept the fixed cost of the process.
2. **Ray**: the resident memory of an idle local Ray instance (the process
   tree this script starts), the start-up time, and the overhead per trial
   (a sweep of tiny trials: wall time per trial minus their training time,
   amortised over the trials; workers are reused between trials, so the
   first trial of a worker costs more and later ones less),
   and the time of a trial's evaluation (as the trial records it).
3. **Training throughput per trial** with one CPU per trial, as many trials
   at once as there are cores (a short sweep; vessel-steps/s per trial).

Then prints the cost of a sweep of ``--trials`` trials of ``--trial-steps``
vessel-steps each on 1, 10 and 100 nodes of this machine's size, from those
figures: wall time and CPU-hours. Nodes are assumed identical to this one
and trials independent (no shared bottleneck but the Ray head, which only
schedules); the model is ``waves x (trial overhead + training + evaluation)``
with ``waves = ceil(trials / concurrent trials)``.

Linux only (reads ``/proc``). Needs the ``ray`` and ``rl`` extras. Usage::

    python benchmarks/scaling_figures.py                   # about 80 s (warm kernel cache)
    python benchmarks/scaling_figures.py --skip-ray        # memory only
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

PAGE = os.sysconf("SC_PAGE_SIZE")


def _rss(pid: int) -> int:
    """Resident memory of one process (bytes), 0 if it is gone."""
    try:
        return int(Path(f"/proc/{pid}/statm").read_text().split()[1]) * PAGE
    except (FileNotFoundError, ProcessLookupError):
        return 0


def _tree(root: int) -> list[int]:
    """``root`` and all its descendants."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (FileNotFoundError, ProcessLookupError, IndexError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found, stack = [], [root]
    while stack:
        pid = stack.pop()
        found.append(pid)
        stack += children.get(pid, [])
    return found


def _training_process_rss(fleets: int, scenario: str, queue: multiprocessing.Queue) -> None:
    """In a fresh process: build FleetVecEnv + PPO, collect and learn one rollout, report RSS."""
    from agents.training.algorithms import build_model, make_env
    from agents.training.config import TrainConfig

    config = TrainConfig(scenario=scenario, fleets=fleets, timesteps=1, torch_threads=1)
    venv = make_env(config)
    venv.seed(0)
    from stable_baselines3.common.vec_env import VecMonitor

    model = build_model(config, VecMonitor(venv))
    model.learn(1)  # one rollout of n_steps x num_envs and one update
    queue.put(_rss(os.getpid()))


def memory(scenario: str, fleet_counts: tuple[int, int]) -> dict[str, float]:
    """Simulator bytes per fleet, and a training process's RSS slope and intercept."""
    from cpf_env.scenarios import get
    from cpf_env.sim.fleet import FleetSim

    sim = FleetSim(get(scenario), num_fleets=256)
    arrays = sum(value.nbytes for value in sim.arrays) / 256
    context = multiprocessing.get_context("spawn")
    rss = []
    for fleets in fleet_counts:
        queue: multiprocessing.Queue = context.Queue()
        process = context.Process(target=_training_process_rss, args=(fleets, scenario, queue))
        process.start()
        rss.append(queue.get())
        process.join()
    slope = (rss[1] - rss[0]) / (fleet_counts[1] - fleet_counts[0])
    return {
        "sim_bytes_per_fleet": arrays,
        "train_bytes_per_fleet": slope,
        "train_fixed_bytes": rss[0] - slope * fleet_counts[0],
        "rss": dict(zip(fleet_counts, rss, strict=True)),
    }


def ray_figures(scenario: str, tiny_trials: int, steps: int, fleets: int) -> dict[str, float]:
    """Idle Ray memory and start-up; overhead per trial; training throughput per trial."""
    import ray

    from cpf_commands.sweep.cli import run_sweep
    from cpf_commands.sweep.spec import SweepSpec
    from cpf_env.sim.precompile import precompile

    precompile([scenario])
    start = time.perf_counter()
    ray.init(include_dashboard=False, logging_level="warning", log_to_driver=False)
    startup = time.perf_counter() - start
    time.sleep(5.0)
    idle = sum(_rss(pid) for pid in _tree(os.getpid()) if pid != os.getpid())
    ray.shutdown()
    cores = os.cpu_count() or 1
    figures: dict[str, float] = {"ray_startup_s": startup, "ray_idle_bytes": idle}
    with tempfile.TemporaryDirectory() as folder:
        tiny = SweepSpec(
            (scenario,),
            tuple(range(tiny_trials)),
            fixed={"timesteps": 1, "fleets": 4},
            eval_num_seeds=0,
        )
        start = time.perf_counter()
        rows = run_sweep(tiny, Path(folder) / "tiny", quiet=True)
        wall = time.perf_counter() - start - startup
        train = float(np.mean([row["train_seconds"] for row in rows]))
        figures["trial_overhead_s"] = wall * min(cores, tiny_trials) / tiny_trials - train
        real = SweepSpec(
            (scenario,),
            tuple(range(cores)),
            fixed={"timesteps": steps, "fleets": fleets},
            eval_num_seeds=10,
        )
        rows = run_sweep(real, Path(folder) / "real", quiet=True)
    figures["trial_steps_per_s"] = float(np.mean([row["vessel_steps_per_second"] for row in rows]))
    figures["trial_train_s"] = float(np.mean([row["train_seconds"] for row in rows]))
    figures["trial_eval_s"] = float(np.mean([row["eval_seconds"] for row in rows]))
    figures["cores"] = cores
    return figures


def sweep_cost(figures: dict[str, float], trials: int, trial_steps: int) -> list[str]:
    """Markdown rows: nodes, concurrent trials, waves, wall time, CPU-hours."""
    per_trial = (
        figures["trial_overhead_s"]
        + trial_steps / figures["trial_steps_per_s"]
        + figures["trial_eval_s"]
    )
    rows = ["| nodes | trials at once | waves | wall time | CPU-hours |", "|---|---|---|---|---|"]
    for nodes in (1, 10, 100):
        at_once = min(trials, int(nodes * figures["cores"]))
        waves = math.ceil(trials / at_once)
        wall = figures["ray_startup_s"] + waves * per_trial
        hours = trials * per_trial / 3600
        rows.append(
            f"| {nodes} | {at_once} | {waves} | {wall / 3600:.2f} h ({wall:.0f} s) | {hours:.1f} |"
        )
    rows.append("")
    rows.append(
        f"One trial: {figures['trial_overhead_s']:.1f} s overhead + {trial_steps:,} steps at "
        f"{figures['trial_steps_per_s']:,.0f} vessel-steps/s + {figures['trial_eval_s']:.1f} s "
        f"evaluation = {per_trial:.0f} s."
    )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="bench_lossy_links")
    parser.add_argument("--fleets", nargs=2, type=int, default=[256, 2048], help="RSS at these")
    parser.add_argument("--skip-ray", action="store_true", help="memory figures only")
    parser.add_argument("--tiny-trials", type=int, default=6, help="trials for the overhead")
    parser.add_argument("--steps", type=int, default=200_000, help="steps of the timed trials")
    parser.add_argument("--trial-fleets", type=int, default=64, help="fleets per timed trial")
    parser.add_argument("--trials", type=int, default=100, help="sweep size of the cost table")
    parser.add_argument("--trial-steps", type=int, default=5_000_000, help="steps per trial")
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"
    )
    mem = memory(args.scenario, tuple(args.fleets))
    n = __import__("cpf_env").scenarios.get(args.scenario).n
    print(f"scenario {args.scenario} (n = {n})")
    print(f"simulator arrays: {mem['sim_bytes_per_fleet'] / 1024:.1f} KiB per fleet")
    for fleets, rss in mem["rss"].items():
        print(f"training process (FleetVecEnv + PPO) at {fleets} fleets: {rss / 2**20:.0f} MiB")
    print(
        f"  -> {mem['train_bytes_per_fleet'] / 1024:.0f} KiB per extra fleet, "
        f"{mem['train_fixed_bytes'] / 2**20:.0f} MiB fixed"
    )
    if args.skip_ray:
        return
    fig = ray_figures(args.scenario, args.tiny_trials, args.steps, args.trial_fleets)
    idle = fig["ray_idle_bytes"] / 2**20
    print(f"local Ray: start-up {fig['ray_startup_s']:.1f} s, idle {idle:.0f} MiB")
    print(
        f"per trial: {fig['trial_overhead_s']:.1f} s overhead ({args.tiny_trials} tiny trials); "
        f"{fig['trial_steps_per_s']:,.0f} vessel-steps/s training with 1 CPU "
        f"({args.trial_fleets} fleets, {int(fig['cores'])} trials at once); "
        f"{fig['trial_eval_s']:.1f} s evaluation (10 seeds)"
    )
    print(f"\nA sweep of {args.trials} trials x {args.trial_steps:,} steps, nodes like this one:\n")
    print("\n".join(sweep_cost(fig, args.trials, args.trial_steps)))


if __name__ == "__main__":
    main()
