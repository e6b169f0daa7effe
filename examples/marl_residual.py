"""Residual MAPPO / IPPO with BenchMARL on a cpf task, saved as a cpf-bench policy.

Trains BenchMARL's MAPPO (centralized critic on the global state) or IPPO
(local critics) on ``CpfTask.<TASK>`` with settings sized for a residual
(below), records the learning curve against vessel-steps and wall-clock, and
saves the actor with ``agents.marl.policy_folder.save_marl_policy``::

    python examples/marl_residual.py --algorithm mappo --iterations 40 --out runs/marl/mappo_s0
    cpf-bench --policies nn_dsc runs/marl/mappo_s0 --scenarios bench_lossy_links --split test

Settings that differ from BenchMARL's defaults, as the SB3 residual experiment
(``examples/train_residual_ppo.py``) does it: a 64 x 64 tanh MLP, learning
rate 3e-4, initial exploration std 0.37 (``log_std_init = -1``), and the
actor's mean output zeroed at the start, so the first policy is the base
policy itself (SB3's residual PPO zero-initializes its action layer too).
64 fleets x 100 steps per batch (32,000 vessel-steps), 8 passes of
minibatches of 1,600 fleet-steps.

Writes into ``--out``: the policy folder's files, ``curve.csv`` (per
iteration: frames, vessel-steps, seconds since start, collection and training
seconds, mean reward per vessel-step, mean return of the episodes that ended)
and ``run.json`` (settings, versions, totals, end-to-end vessel-steps/s).
"""

from __future__ import annotations  # noqa: I001  (BenchMARL after agents.marl.tasks: the alias)

import argparse
import csv
import io
import json
import time
from pathlib import Path
from typing import Any

import torch

from agents.marl.policy_folder import save_marl_policy
from agents.marl.tasks import CpfTask  # imports BenchMARL (with the TorchRL 0.14 alias)
from benchmarl.experiment.callback import Callback  # isort: skip
from cpf_env.infra import atomic

FLEETS = 64
STEPS_PER_BATCH = 100


class Curve(Callback):
    """BenchMARL callback recording one row per iteration."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.n, self.rows, self.start = n, [], time.perf_counter()
        self.frames = 0
        self._collected = self.start
        self._last = self.start

    def on_setup(self) -> None:
        """Start the clock when training starts."""
        self.start = self._last = time.perf_counter()

    def on_batch_collected(self, batch: Any) -> None:
        """Reward per vessel-step and the returns of the episodes that ended."""
        self._collected = time.perf_counter()
        reward = batch["next", "vessel", "reward"]
        done = batch["next", "done"].squeeze(-1)
        returns = batch["next", "vessel", "episode_reward"].mean(dim=(-2, -1))[done]
        self.frames += batch.numel()
        self.rows.append(
            {
                "iteration": len(self.rows) + 1,
                "frames": self.frames,
                "vessel_steps": self.frames * self.n,
                "collection_seconds": self._collected - self._last,
                "reward_per_vessel_step": float(reward.mean()),
                "episode_return": float(returns.mean()) if returns.numel() else float("nan"),
                "episodes_ended": int(done.sum()),
            }
        )

    def on_train_end(self, training_td: Any, group: str) -> None:
        """Training time of the iteration, and the wall clock."""
        now = time.perf_counter()
        self.rows[-1]["training_seconds"] = now - self._collected
        self.rows[-1]["seconds"] = now - self.start
        self._last = now


def main() -> None:
    """Parse the arguments, train, save."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algorithm", choices=("mappo", "ippo"), default="mappo")
    parser.add_argument("--task", default="bench_lossy_links")
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)

    from benchmarl.algorithms import IppoConfig, MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig

    config = ExperimentConfig.get_from_yaml()
    settings = {
        "max_n_iters": args.iterations,
        "max_n_frames": None,
        "loggers": [],
        "lr": 3e-4,
        "on_policy_n_envs_per_worker": FLEETS,
        "on_policy_collected_frames_per_batch": FLEETS * STEPS_PER_BATCH,
        "on_policy_minibatch_size": 1600,
        "on_policy_n_minibatch_iters": 8,
        "evaluation": False,
        "render": False,
        "checkpoint_at_end": False,
        "create_json": False,
        "save_folder": str(args.out.parent),
    }
    for key, value in settings.items():
        setattr(config, key, value)
    algorithm = {"mappo": MappoConfig, "ippo": IppoConfig}[args.algorithm].get_from_yaml()
    algorithm.scale_mapping = "biased_softplus_0.37"
    model = MlpConfig.get_from_yaml()
    model.num_cells = [64, 64]
    task = CpfTask[args.task.upper()].get_from_yaml()
    curve = Curve(n=5)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    experiment = Experiment(
        task=task,
        algorithm_config=algorithm,
        model_config=model,
        critic_model_config=model,
        seed=args.seed,
        config=config,
        callbacks=[curve],
    )
    curve.n = experiment.test_env.base_env.n
    actor = experiment.algorithm.get_policy_for_loss("vessel")
    with torch.no_grad():  # start from the base policy: zero mean residual
        last = [v for k, v in actor.state_dict(keep_vars=True).items() if "mlp.params" in k][-2:]
        k = experiment.test_env.base_env.core.action_size
        last[0][:k].zero_()
        last[1][:k].zero_()
    started = time.perf_counter()
    experiment.run()
    seconds = time.perf_counter() - started
    save_marl_policy(experiment, args.out, args.algorithm)
    vessel_steps = experiment.total_frames * curve.n
    run = {
        "algorithm": args.algorithm,
        "task": args.task,
        "seed": args.seed,
        "settings": {k: v for k, v in settings.items() if k != "save_folder"},
        "scale_mapping": algorithm.scale_mapping,
        "num_cells": model.num_cells,
        "iterations": experiment.n_iters_performed,
        "vessel_steps": vessel_steps,
        "seconds": seconds,
        "vessel_steps_per_second": vessel_steps / seconds,
        "collection_seconds": sum(r["collection_seconds"] for r in curve.rows),
        "training_seconds": sum(r.get("training_seconds", 0.0) for r in curve.rows),
        "versions": {
            "torch": torch.__version__,
            "torchrl": __import__("torchrl").__version__,
            "benchmarl": __import__("benchmarl").__version__,
        },
    }
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(curve.rows[0]) + ["training_seconds", "seconds"])
    writer.writeheader()
    writer.writerows(curve.rows)
    atomic.write_text(args.out / "curve.csv", text.getvalue())
    atomic.write_text(args.out / "run.json", json.dumps(run, indent=2) + "\n")
    print(json.dumps({k: run[k] for k in ("iterations", "vessel_steps", "seconds")}))
    print(f"end to end: {run['vessel_steps_per_second']:,.0f} vessel-steps/s")
    print("last rows:", *curve.rows[-3:], sep="\n")


if __name__ == "__main__":
    main()
