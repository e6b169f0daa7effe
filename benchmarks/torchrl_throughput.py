"""TorchRL throughput: ``PettingZooWrapper`` over the ParallelEnv vs the native ``TorchRLFleetEnv``.

Both routes run the loop a TorchRL collector runs: a uniformly random action
from the action spec (``env.rand_action``), then ``env.step_and_maybe_reset``
(fleets that end are reset through the ``"_reset"`` mask), timed for a fixed
wall-clock budget after a short warm-up (the best of three
timed blocks, as ``timeit`` reports). The trajectory is not stored (that
cost belongs to the learner and is the same per vessel-step on both routes);
one extra row times ``env.rollout``, which stacks the trajectory.

Routes:

1. ``PettingZooWrapper(cpf_env.parallel_env(info_level=...))``, one group of
   vessels, one fleet, at the three info levels (a route that fails is
   reported with its error);
2. ``cpf_env.envs.torchrl_env.TorchRLFleetEnv`` at several batch sizes B.

Prints vessel-steps per second and the ratio native / wrapper at B = 256.
Needs the ``torchrl`` extra. Usage::

    python benchmarks/torchrl_throughput.py --seconds 4 --fleets 1 16 256 1024
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings

try:
    import torch
    from torchrl.envs import EnvBase, PettingZooWrapper
except ImportError as error:  # an optional stack: say which extra brings it
    raise SystemExit(
        f"{error}; this example needs the torchrl extra: "
        f'pip install -e ".[torchrl]" (your PyTorch build first)'
    ) from error

import cpf_env
from cpf_commands.common.arguments import positive_int
from cpf_env.envs.torchrl_env import TorchRLFleetEnv


def vessel_steps_per_second(env: EnvBase, vessels: int, seconds: float, blocks: int = 3) -> float:
    """Best rate of ``blocks`` timed blocks of random-action ``step_and_maybe_reset`` calls.

    The machine may be shared, so the best block (as ``timeit`` reports) is the
    figure least disturbed by other processes.

    Args:
        env: The env (seeded).
        vessels: Vessels stepped per call (B * n).
        seconds: Wall-clock budget (s), split into ``blocks`` blocks after 20 warm-up calls.
        blocks: Number of timed blocks.

    Returns:
        Vessel-steps per second.
    """
    td = env.reset()
    for _ in range(20):
        _, td = env.step_and_maybe_reset(env.rand_action(td))
    best = 0.0
    for _ in range(blocks):
        steps, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds / blocks:
            for _ in range(10):
                _, td = env.step_and_maybe_reset(env.rand_action(td))
            steps += 10
        best = max(best, steps * vessels / elapsed)
    return best


def rollout_vessel_steps_per_second(env: EnvBase, vessels: int, steps: int) -> float:
    """Time one ``env.rollout(steps)`` (random actions, trajectory stacked), after a warm-up."""
    env.rollout(5, break_when_any_done=False)
    start = time.perf_counter()
    env.rollout(steps, break_when_any_done=False)
    return steps * vessels / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--scenario", default="wang2014", choices=cpf_env.scenarios.list_scenarios()
    )
    parser.add_argument("--seconds", type=float, default=4.0, help="budget per row (s)")
    parser.add_argument("--fleets", type=positive_int, nargs="+", default=[1, 16, 256, 1024])
    parser.add_argument("--rollout-steps", type=int, default=100, help="0 skips the rollout row")
    parser.add_argument(
        "--torch-threads",
        type=positive_int,
        default=1,
        help="torch intra-op threads (1: the tensors per step are small, and torch's thread "
        "pool stalls on a loaded machine; the simulator's numba threads are separate)",
    )
    args = parser.parse_args()
    if args.seconds <= 0 or args.rollout_steps < 0:
        parser.error("--seconds must be > 0 and --rollout-steps >= 0")
    torch.set_num_threads(args.torch_threads)
    warnings.filterwarnings("ignore")  # TorchRL's deprecation notices would hide the table
    n = cpf_env.scenarios.get(args.scenario).n
    print(
        f"scenario {args.scenario} (n = {n}), {args.seconds:g} s per row (best of 3 blocks), torch "
        f"{torch.__version__} with {args.torch_threads} thread(s), {os.cpu_count()} CPUs, "
        f"{platform.processor() or platform.machine()}"
    )
    rows: list[tuple[str, int, float | str]] = []
    for level in ("full", "minimal", "none"):
        name = f"PettingZooWrapper, info_level={level}"
        try:
            wrapped = PettingZooWrapper(cpf_env.parallel_env(args.scenario, info_level=level))
        except (RuntimeError, TypeError, ValueError) as error:
            rows.append((name, 1, f"fails: {type(error).__name__}: {error}"))
            continue
        wrapped.set_seed(0)
        rows.append((name, 1, vessel_steps_per_second(wrapped, n, args.seconds)))
    for fleets in args.fleets:
        native = TorchRLFleetEnv(args.scenario, num_fleets=fleets)
        native.set_seed(0)
        rows.append(
            ("TorchRLFleetEnv", fleets, vessel_steps_per_second(native, fleets * n, args.seconds))
        )
    if args.rollout_steps and 256 in args.fleets:
        native = TorchRLFleetEnv(args.scenario, num_fleets=256)
        native.set_seed(0)
        speed = rollout_vessel_steps_per_second(native, 256 * n, args.rollout_steps)
        rows.append((f"TorchRLFleetEnv, rollout({args.rollout_steps}) stacked", 256, speed))
    print(f"\n{'route':<44} {'B':>5} {'vessel-steps/s':>15}")
    for name, fleets, speed in rows:
        shown = f"{speed:15,.0f}" if isinstance(speed, float) else f"  {speed}"
        print(f"{name:<44} {fleets:>5} {shown}")
    native_256 = [s for name, b, s in rows if name == "TorchRLFleetEnv" and b == 256]
    for name, _, speed in rows:
        if name.startswith("PettingZooWrapper") and isinstance(speed, float) and native_256:
            print(f"native B = 256 / {name}: {native_256[0] / speed:.1f}x (target >= 20x)")


if __name__ == "__main__":
    main()
