"""PPO on RLlib's new API stack with one RLModule shared by every vessel (parameter sharing).

The ParallelEnv goes to RLlib through its own PettingZoo wrapper,
``ParallelPettingZooEnv``, registered under a name with ``register_env``; every
agent (``vessel_0 .. vessel_{n-1}``) maps to one module id, so all vessels act
with, and train, the same network on their own local observations. Sampling
runs on EnvRunners (``--env-runners 0``: in the driver; ``k``: k Ray actors),
training on a local Learner. Each iteration prints env-steps/s (one env step =
the whole fleet acting once; vessel-steps = env steps x n vessels) and the mean
episode return; the last checkpoint goes to ``--out``. Needs the ``rllib`` extra
(``pip install -e ".[rllib]"``); see ``docs/rllib.md``.

Usage::

    python examples/rllib_ppo.py                                   # 3 small iterations
    python examples/rllib_ppo.py --iterations 50 --env-runners 2 --envs-per-runner 4
    python examples/rllib_ppo.py --measure   # + warm throughput, env alone, Ray memory

The defaults (local sampling, 2,000 env steps per iteration, 500-step episodes)
run in about a minute on two cores; they show the set-up, not a trained agent.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

try:
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env
except ImportError as error:  # an optional stack: say which extra brings it
    raise SystemExit(
        f"{error}; this example needs the rl and rllib extras: "
        f'pip install -e ".[rl,rllib]" (your PyTorch build first)'
    ) from error

import cpf_env
from cpf_commands.common.arguments import positive_int
from cpf_env.envs.core import INFO_LEVELS

#: Name the env is registered under (``config.environment(ENV_NAME, env_config=...)``).
ENV_NAME = "cpf_env_parallel"
#: The one module id every vessel maps to.
SHARED_MODULE = "shared_vessel"


def make_rllib_env(env_config: dict[str, Any]) -> ParallelPettingZooEnv:
    """RLlib's env creator: ``cpf_env.parallel_env(**env_config)`` in ``ParallelPettingZooEnv``.

    Args:
        env_config: ``scenario`` (name) plus any keyword of ``cpf_env.parallel_env``
            (``max_steps``, ``info_level``, ``render_mode``, scenario overrides).
            RLlib passes an ``EnvContext`` (a dict with worker/vector indices).
    """
    kwargs = dict(env_config)
    scenario = kwargs.pop("scenario", "wang2014")
    return ParallelPettingZooEnv(cpf_env.parallel_env(scenario, **kwargs))


def map_to_shared(agent_id: str, episode: Any, **kwargs: Any) -> str:
    """Policy mapping: every vessel uses the shared module."""
    del agent_id, episode, kwargs
    return SHARED_MODULE


def shared_module_path(checkpoint: str | Path) -> Path:
    """Folder of the shared module inside an algorithm checkpoint (``RLModule.from_checkpoint``).

    Absolute: RLlib reads checkpoints through pyarrow's file systems, which
    refuse a relative path ("URI has empty scheme").
    """
    return Path(checkpoint).resolve() / "learner_group" / "learner" / "rl_module" / SHARED_MODULE


def greedy_actions(
    module: Any, observations: dict[str, np.ndarray], env: ParallelPettingZooEnv
) -> dict[str, np.ndarray]:
    """Deterministic actions of the shared module for every vessel, in the env's units.

    What RLlib's EnvRunner does at inference: the module's Gaussian means (the first
    half of ``action_dist_inputs``; the second half are log standard deviations),
    in RLlib's normalized units (``normalize_actions``: [-1, 1] spans the bounds),
    mapped onto each vessel's action bounds and clipped to them.

    Args:
        module: The shared RLModule (``RLModule.from_checkpoint(shared_module_path(...))``).
        observations: Agent -> observation of shape (obs_dim,), as ``env.reset``/``step`` give.
        env: The wrapped env, for the action bounds.

    Returns:
        Agent -> action of shape (act_dim,), float32, within ``env.action_space[agent]``.
    """
    import torch

    agents = list(observations)
    batch = {"obs": torch.as_tensor(np.stack([observations[a] for a in agents]))}
    with torch.no_grad():
        inputs = module.forward_inference(batch)["action_dist_inputs"].numpy()
    means = inputs[:, : inputs.shape[1] // 2]
    actions = {}
    for agent, mean in zip(agents, means, strict=True):
        space = env.action_space[agent]
        unsquashed = space.low + (mean + 1.0) * (space.high - space.low) / 2.0
        actions[agent] = np.clip(unsquashed, space.low, space.high).astype(np.float32)
    return actions


def build_config(
    scenario: str = "wang2014",
    max_steps: int = 500,
    info_level: str = "none",
    env_runners: int = 0,
    envs_per_runner: int = 1,
    seed: int = 0,
    train_batch_size_per_learner: int = 2000,
    minibatch_size: int = 1000,
    num_epochs: int = 5,
    hidden: Sequence[int] = (64, 64),
) -> PPOConfig:
    """PPO on the new API stack, one shared RLModule for all vessels of ``scenario``.

    Args:
        scenario: A registered scenario name (``cpf_env.scenarios.list_scenarios()``).
        max_steps: Episode length in control steps (``dt`` s each).
        info_level: Per-step infos, ``"full"``, ``"minimal"`` or ``"none"``
            (nothing here reads them; ``"none"`` is cheapest).
        env_runners: Remote EnvRunner actors; 0 samples in the driver process.
        envs_per_runner: Envs stepped together (vectorized) by each EnvRunner.
        seed: Seeds RLlib (module initialization, env resets, sampling).
        train_batch_size_per_learner: Env steps per iteration; each gives n
            vessel samples to the shared module.
        minibatch_size: SGD minibatch, in module (vessel) samples; RLlib requires
            it to be at most ``train_batch_size_per_learner``.
        num_epochs: Passes over each train batch.
        hidden: Hidden layer widths of the policy and value networks.

    Returns:
        The ``PPOConfig``; ``config.build_algo()`` makes the algorithm.
    """
    register_env(ENV_NAME, make_rllib_env)
    module = RLModuleSpec(model_config=DefaultModelConfig(fcnet_hiddens=list(hidden)))
    return (
        PPOConfig()
        .api_stack(enable_rl_module_and_learner=True, enable_env_runner_and_connector_v2=True)
        .environment(
            ENV_NAME,
            env_config={"scenario": scenario, "max_steps": max_steps, "info_level": info_level},
        )
        .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=envs_per_runner)
        .multi_agent(policies={SHARED_MODULE}, policy_mapping_fn=map_to_shared)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={SHARED_MODULE: module}))
        .training(
            train_batch_size_per_learner=train_batch_size_per_learner,
            minibatch_size=minibatch_size,
            num_epochs=num_epochs,
        )
        .learners(num_learners=0)
        .debugging(seed=seed)
    )


def ray_tree_rss_mb() -> float | None:
    """Resident memory (MB) of this process and all its descendants (the local Ray tree).

    Reads ``/proc`` (Linux); None elsewhere. Ray's GCS, raylet and worker
    processes are children of the driver that started them.
    """
    proc = Path("/proc")
    if not (proc / "self" / "stat").exists():
        return None
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            status = (entry / "status").read_text()
        except OSError:  # the process ended while we looked
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
        kb = [line.split()[1] for line in status.splitlines() if line.startswith("VmRSS:")]
        rss[int(entry.name)] = int(kb[0]) if kb else 0
    total, stack = 0, [os.getpid()]
    while stack:
        pid = stack.pop()
        total += rss.get(pid, 0)
        stack.extend(children.get(pid, []))
    return total / 1024.0


class PeakMemory:
    """Peak of ``ray_tree_rss_mb`` sampled every ``period`` s in a thread, inside a ``with``."""

    def __init__(self, period: float = 0.5) -> None:
        self.period = period
        self.peak_mb: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        while not self._stop.wait(self.period):
            mb = ray_tree_rss_mb()
            if mb is not None:
                self.peak_mb = max(self.peak_mb or 0.0, mb)

    def __enter__(self) -> PeakMemory:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def env_alone_rate(env_config: dict[str, Any], seconds: float) -> float:
    """Env-steps/s of the wrapped env alone (zero actions, no RLlib around it)."""
    env = make_rllib_env(env_config)
    env.reset(seed=0)
    actions = {
        agent: np.zeros(space.shape, np.float32) for agent, space in env.action_space.items()
    }
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = env.step(actions)
        steps += 1
        if terminated["__all__"] or truncated["__all__"]:
            env.reset()
    return steps / (time.perf_counter() - start)


def sampling_rate(algo: Any, env_steps: int) -> float:
    """Env-steps/s of sampling alone: every EnvRunner samples ``env_steps`` at once, timed."""
    group = algo.env_runner_group
    start = time.perf_counter()
    if group.num_remote_env_runners() == 0:
        algo.env_runner.sample(num_timesteps=env_steps, random_actions=False)
        total = env_steps
    else:
        group.foreach_env_runner(
            lambda runner: runner.sample(num_timesteps=env_steps), local_env_runner=False
        )
        total = env_steps * group.num_remote_env_runners()
    return total / (time.perf_counter() - start)


def iteration_line(i: int, result: dict[str, Any], seconds: float) -> str:
    """One printed line per iteration: env steps, env-/vessel-steps/s, return, loss."""
    runners = result["env_runners"]
    env_steps = int(runners["num_env_steps_sampled"])
    vessel_steps = int(runners["num_module_steps_sampled"][SHARED_MODULE])
    episode_return = float(runners.get("episode_return_mean", np.nan))
    shown = "-" if np.isnan(episode_return) else f"{episode_return:.1f}"  # no episode ended
    loss = result["learners"][SHARED_MODULE]["total_loss"]
    return (
        f"{i:4d} {env_steps:9d} {seconds:7.1f} {env_steps / seconds:12,.0f} "
        f"{vessel_steps / seconds:15,.0f} {shown:>14s} {loss:10.3g}"
    )


def train(
    algo: Any, iterations: int, scenario: str, memory: dict[str, float | None]
) -> list[float]:
    """Run ``iterations`` of ``algo.train()``, print one line each; record peak memory.

    Returns:
        End-to-end env-steps/s of each iteration (sampling + update, wall clock).
    """
    n = cpf_env.scenarios.get(scenario).n
    print(f"{scenario}: {n} vessels, one module {SHARED_MODULE!r}")
    print("iter env-steps  wall s   env-steps/s  vessel-steps/s  episode return       loss")
    rates = []
    with PeakMemory() as peak:
        for i in range(1, iterations + 1):
            start = time.perf_counter()
            result = algo.train()
            seconds = time.perf_counter() - start
            print(iteration_line(i, result, seconds), flush=True)
            rates.append(result["env_runners"]["num_env_steps_sampled"] / seconds)
    memory["peak during training"] = peak.peak_mb
    return rates


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="rllib_ppo.py",
        description="RLlib PPO (new API stack), one RLModule shared by all vessels.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--scenario",
        default="wang2014",
        choices=cpf_env.scenarios.list_scenarios(),
        help="scenario",
    )
    parser.add_argument("--iterations", type=positive_int, default=3, help="training iterations")
    parser.add_argument("--env-runners", type=int, default=0, help="remote EnvRunners (0: local)")
    parser.add_argument(
        "--envs-per-runner", type=positive_int, default=1, help="envs per EnvRunner"
    )
    parser.add_argument("--seed", type=int, default=0, help="RLlib seed")
    parser.add_argument("--max-steps", type=positive_int, default=500, help="episode length, steps")
    parser.add_argument(
        "--train-batch-size-per-learner",
        type=positive_int,
        default=2000,
        help="env steps per iteration",
    )
    parser.add_argument(
        "--minibatch-size",
        type=positive_int,
        default=1000,
        help="SGD minibatch, vessel steps (<= --train-batch-size-per-learner)",
    )
    parser.add_argument("--num-epochs", type=positive_int, default=5, help="passes over each batch")
    parser.add_argument("--info-level", default="none", choices=INFO_LEVELS, help="per-step infos")
    parser.add_argument(
        "--num-cpus", type=positive_int, default=None, help="CPUs for Ray (default: all)"
    )
    parser.add_argument(
        "--torch-threads", type=positive_int, default=1, help="torch threads, driver"
    )
    parser.add_argument("--out", default="runs/rllib_ppo", help="checkpoint directory")
    parser.add_argument(
        "--measure",
        action="store_true",
        help="also print sampling-only and env-alone env-steps/s and the Ray tree's memory",
    )
    args = parser.parse_args(argv)
    if args.env_runners < 0:
        parser.error(f"--env-runners must be >= 0, got {args.env_runners}")
    if args.minibatch_size > args.train_batch_size_per_learner:
        parser.error(
            f"--minibatch-size {args.minibatch_size} is larger than "
            f"--train-batch-size-per-learner {args.train_batch_size_per_learner}; RLlib needs "
            "the minibatch within the train batch: lower --minibatch-size or raise "
            "--train-batch-size-per-learner."
        )
    import torch

    torch.set_num_threads(args.torch_threads)
    config = build_config(
        args.scenario,
        max_steps=args.max_steps,
        info_level=args.info_level,
        env_runners=args.env_runners,
        envs_per_runner=args.envs_per_runner,
        seed=args.seed,
        train_batch_size_per_learner=args.train_batch_size_per_learner,
        minibatch_size=args.minibatch_size,
        num_epochs=args.num_epochs,
    )
    started_ray = not ray.is_initialized()  # a caller's Ray session is used and left running
    if started_ray:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    try:
        memory = {"Ray started": ray_tree_rss_mb()}
        algo = config.build_algo()
        try:
            memory["algorithm built, idle"] = ray_tree_rss_mb()
            rates = train(algo, args.iterations, args.scenario, memory)
            checkpoint = algo.save_to_path(str(Path(args.out).resolve()))
            print(f"checkpoint: {checkpoint}")
            if args.measure:
                report_measurements(algo, config, args, rates, memory)
        finally:
            algo.stop()
    finally:
        if started_ray:
            ray.shutdown()
    return 0


def report_measurements(
    algo: Any,
    config: PPOConfig,
    args: argparse.Namespace,
    rates: list[float],
    memory: dict[str, float | None],
) -> None:
    """Print the throughput summary (warm iterations) and the Ray tree's memory."""
    n = cpf_env.scenarios.get(args.scenario).n
    warm = rates[1:] or rates
    end_to_end = float(np.mean(warm))
    sampling = sampling_rate(algo, 3 * args.train_batch_size_per_learner)
    alone = env_alone_rate(config.env_config, seconds=2.0)
    runners = f"{args.env_runners} runners x {args.envs_per_runner} envs"
    print(f"\nthroughput ({args.scenario}, {runners}, info_level={args.info_level}):")
    print(f"{'route':44s} {'env-steps/s':>12s} {'vessel-steps/s':>15s}")
    rows = {
        f"RLlib PPO end to end (iterations 2..{len(rates)})": end_to_end,
        "RLlib sampling only": sampling,
        "wrapped env alone (zero actions)": alone,
    }
    for name, rate in rows.items():
        print(f"{name:44s} {rate:12,.0f} {rate * n:15,.0f}")
    print("memory of the Ray process tree (RSS sum, MB):")
    for name, mb in memory.items():
        print(f"  {name:28s} {'n/a (no /proc)' if mb is None else f'{mb:,.0f}'}")


if __name__ == "__main__":
    raise SystemExit(main())
