"""Training on a GPU: ``cpf-train`` for 1 M vessel-steps on ``cuda``, in vessel-steps per second.

The learners take ``--device`` (``cpf-train``, ``cpf-distill``; BenchMARL's
``experiment.sampling_device`` and ``experiment.train_device`` on the
``cpf-marl`` route). The simulator and the analytic bases run on the CPU
whatever the device; the network's forward passes and PPO's updates move
to it. This trains PPO from scratch on a hard-track scenario for
``--timesteps`` vessel-steps on ``--device`` and, with ``--compare-cpu``,
the same budget on the CPU right after, and prints the wall time and the
vessel-steps per second of each (and their ratio: the same load for both).
Without a CUDA device it prints why and exits 0, so it can stand in any
script. Usage::

    python benchmarks/gpu_check.py --timesteps 1000000 --compare-cpu
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path


def _train(device: str, args: argparse.Namespace, root: Path) -> tuple[int, float]:
    """Vessel-steps and seconds of one ``cpf-train`` run (no evaluation) on ``device``.

    The vessel-steps are those trained (``-n`` rounded up to whole rollouts, from
    ``progress.csv``); the seconds are the wall time of the whole command.
    """
    from cpf_commands.train import train_main

    out = root / device.replace(":", "_")
    argv = [
        "--scenarios", args.scenario, "--base-policy", "none", "--fleets", str(args.fleets),
        "-n", str(args.timesteps), "--eval-every", "0", "--device", device, "--quiet",
        "--out", str(out),
    ]  # fmt: skip
    start = time.perf_counter()
    code = train_main(argv)
    seconds = time.perf_counter() - start
    if code != 0:
        raise SystemExit(f"cpf-train {' '.join(argv)} exited with {code}.")
    with (out / "progress.csv").open() as table:
        trained = int(list(csv.DictReader(table))[-1]["time/total_timesteps"])
    return trained, seconds


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    """Train on the device (and the CPU); print and return device -> vessel-steps per second."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", help="torch device to train on")
    parser.add_argument("--timesteps", type=int, default=1_000_000, help="vessel-steps")
    parser.add_argument("--scenario", default="hard_sensing", help="training scenario")
    parser.add_argument("--fleets", type=int, default=256, help="fleets simulated together")
    parser.add_argument("--compare-cpu", action="store_true", help="the same run on the CPU")
    args = parser.parse_args(argv)
    import torch

    if args.device.startswith("cuda") and not torch.cuda.is_available():
        print(f"skipped: torch {torch.__version__} sees no CUDA device on this machine.")
        return {}
    rates = {}
    with tempfile.TemporaryDirectory() as folder:
        for device in [args.device, *(["cpu"] if args.compare_cpu else [])]:
            trained, seconds = _train(device, args, Path(folder))
            rates[device] = trained / seconds
            print(f"{device}: {trained:,} vessel-steps in {seconds:.1f} s, "
                  f"{rates[device]:,.0f} vessel-steps/s")  # fmt: skip
    if len(rates) == 2:
        print(f"{args.device} / cpu: {rates[args.device] / rates['cpu']:.2f}")
    return rates


if __name__ == "__main__":
    main()
