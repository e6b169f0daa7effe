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
minibatches of 1,600 fleet-steps. With ``--encoder`` the actor reads the
neighbour slots through the DeepSets encoder (``agents.marl.models``: slot MLP
of width 32, mean over the linked slots, then 64 x 64; inputs normalized with
statistics shared by the slots), so the saved policy runs on any degree; the
critic stays the 64 x 64 MLP. With ``--privileged-state`` MAPPO's critic
also reads what no vessel observes (the task's ``privileged_state``): an
asymmetric actor-critic; the saved actor is as local as ever.

Every ``--eval-every`` iterations the actor plays one episode on each of
``--eval-fleets`` fixed training seeds (0, 1, ...; unstaggered, deterministic
action, ``--eval-max-steps`` long: default the scenario's own length, as
``cpf-bench`` plays it) against the base policy alone on the same seeds
(``agents.marl.fixed_seeds.FixedSeedEvaluation``): the training returns mostly
measure the episodes' random starts, these differences measure the actor.
With ``--keep-best`` the saved actor is the evaluated one with the highest
fixed-seed return minus the base's, the actor before training (the base
itself, 0) included, instead of the last: selection on training seeds, so
``cpf-bench``'s evaluation seeds stay unseen (SB3's ``EvalCallback`` keeps
its best model the same way).

Writes into ``--out``: the policy folder's files, ``curve.csv`` (per
iteration: frames, vessel-steps, collection and training seconds, mean reward
per vessel-step of the batch, mean return of the episodes that ended in it,
seconds since start; on evaluated iterations the actor's return and
second-half reward per vessel-step on the fixed seeds, each also minus the
base's, and the return's part of each reward term) and ``run.json``
(settings, versions, totals, end-to-end vessel-steps/s without the
evaluations, the evaluation before training and the base's numbers, and
``kept``: which iteration's actor the folder holds, 0 for the one before
training). Nothing else: BenchMARL's own run folder (its pickled config)
goes to a temporary folder that is removed at the end.
"""

from __future__ import annotations  # noqa: I001  (BenchMARL after agents.marl.tasks: the alias)

import argparse
import copy
import csv
import io
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from agents.folder.actor import PolicyNetwork
from agents.marl.fixed_seeds import EVALUATION_FIELDS, FixedSeedEvaluation
from agents.marl.models import NeighbourSetMlpConfig
from agents.marl.policy_folder import save_marl_policy
from agents.marl.tasks import CpfTask  # imports BenchMARL (with the TorchRL 0.14 alias)
from benchmarl.experiment.callback import Callback  # isort: skip
from cpf_env.infra import atomic

FLEETS = 64
STEPS_PER_BATCH = 100
#: The columns of ``curve.csv``; ``eval_*`` are empty on iterations not evaluated.
COLUMNS = (
    "iteration",
    "frames",
    "vessel_steps",
    "collection_seconds",
    "reward_per_vessel_step",
    "episode_return",
    "episodes_ended",
    "training_seconds",
    "evaluation_seconds",
    "seconds",
    *(f"eval_{name}" for name in EVALUATION_FIELDS),
)


class Curve(Callback):
    """BenchMARL callback recording one row per iteration, the fixed-seed evaluation every few.

    Args:
        n: Vessels per fleet.
        evaluation: The fixed-seed evaluation, or None.
        every: Evaluate after iterations ``every``, ``2 every``, ... and the last.
        iterations: The number of iterations of the run.

    Attributes:
        best: (iteration, fixed-seed return minus the base's, the actor's state dict)
            of the best evaluation so far, or None: selection off. ``train`` turns it
            on (``--keep-best``) by calling ``note`` on the actor before training
            (iteration 0); each later evaluation that beats it calls ``note`` again.
    """

    def __init__(
        self, n: int, evaluation: FixedSeedEvaluation | None, every: int, iterations: int
    ) -> None:
        super().__init__()
        self.n, self.rows, self.start = n, [], time.perf_counter()
        self.evaluation, self.every, self.iterations = evaluation, every, iterations
        self.best: tuple[int, float, dict[str, torch.Tensor]] | None = None
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
        """Training time of the iteration, the evaluation if due, and the wall clock."""
        now = time.perf_counter()
        row = self.rows[-1]
        row["training_seconds"] = now - self._collected
        iteration = row["iteration"]
        due = iteration % self.every == 0 or iteration == self.iterations
        if self.evaluation is not None and due:
            assert self.experiment is not None
            scores = self.evaluation.evaluate(self.experiment.policy)
            row.update({f"eval_{name}": value for name, value in scores.items()})
            if self.best is not None and scores["return_minus_base"] > self.best[1]:
                self.note(iteration, scores["return_minus_base"])
        self._last = time.perf_counter()
        row["evaluation_seconds"] = self._last - now
        row["seconds"] = self._last - self.start

    def note(self, iteration: int, gain: float) -> None:
        """Keep a copy of the actor as the best so far (iteration 0: before training)."""
        assert self.experiment is not None
        actor = self.experiment.algorithm.get_policy_for_loss("vessel")
        self.best = (iteration, gain, copy.deepcopy(actor.state_dict()))

    def restore_best(self) -> dict[str, Any]:
        """Put the best actor noted back into the experiment; return ``run.json``'s ``kept``.

        Without selection (``best`` None) the actor stays the last iteration's.
        """
        if self.best is None:
            return {"rule": "last", "iteration": len(self.rows)}
        assert self.experiment is not None
        iteration, gain, state = self.best
        self.experiment.algorithm.get_policy_for_loss("vessel").load_state_dict(state)
        return {"rule": "best", "iteration": iteration, "eval_return_minus_base": gain}


def main() -> None:
    """Parse the arguments, then train and save (``train``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algorithm", choices=("mappo", "ippo"), default="mappo")
    parser.add_argument("--task", default="bench_lossy_links")
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--max-steps", type=int, default=None, help="training episode length (the task's: 200)"
    )
    parser.add_argument(
        "--stagger",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="spread the fleets' episode ends (the task's default; off: all end together)",
    )
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--mode",
        choices=("force", "force_and_rate"),
        default=None,
        help="residual mode (the task's: force); force_and_rate also corrects the path "
        "variable's rate",
    )
    parser.add_argument(
        "--messages",
        type=int,
        default=None,
        help="message entries the learner writes, learned end to end (the task's: 0); they "
        "follow the base's own entries and must fit in the scenario's message_size",
    )
    parser.add_argument(
        "--encoder",
        action="store_true",
        help="the actor reads the neighbour slots through the DeepSets encoder "
        "(agents.marl.models; the task's shared_slot_statistics on)",
    )
    parser.add_argument(
        "--privileged-state",
        action="store_true",
        help="MAPPO's critic also reads what no vessel observes (the task's privileged_state: "
        "the true lumped force, v0, each vessel's offset from the fleet's mean path variable)",
    )
    parser.add_argument(
        "--eval-every", type=int, default=2, help="evaluate on fixed seeds every N iterations"
    )
    parser.add_argument(
        "--eval-fleets", type=int, default=32, help="fixed training seeds (0 ..), 0: none"
    )
    parser.add_argument(
        "--eval-max-steps", type=int, default=None, help="evaluation episode length (scenario's)"
    )
    parser.add_argument(
        "--device",
        default="cpu",
        help="torch device BenchMARL samples and trains on: cpu, cuda or cuda:N (the simulator "
        "and the base policy run on the CPU whatever it is; the saved policy loads on the CPU)",
    )
    parser.add_argument(
        "--keep-best",
        action="store_true",
        help="save the actor of the best fixed-seed evaluation (the one before training "
        "included) instead of the last",
    )
    args = parser.parse_args()
    if args.keep_best and args.eval_fleets < 1:
        parser.error("--keep-best selects on the fixed-seed evaluation: give --eval-fleets >= 1.")
    if args.privileged_state and args.algorithm != "mappo":
        parser.error(
            "--privileged-state is for MAPPO's centralized critic; IPPO's critics read no "
            "global state (use --algorithm mappo)."
        )
    torch.set_num_threads(1)
    # BenchMARL writes its own run folder (a pickled config); the run's record is run.json.
    with tempfile.TemporaryDirectory(prefix="benchmarl-") as scratch:
        train(args, scratch)


def train(args: argparse.Namespace, scratch: str) -> None:
    """Train as ``args`` say, BenchMARL's run folder under ``scratch``; write ``args.out``."""
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
        "save_folder": scratch,
        "sampling_device": args.device,
        "train_device": args.device,
        "buffer_device": args.device,
    }
    for key, value in settings.items():
        setattr(config, key, value)
    algorithm = {"mappo": MappoConfig, "ippo": IppoConfig}[args.algorithm].get_from_yaml()
    algorithm.scale_mapping = "biased_softplus_0.37"
    critic = MlpConfig.get_from_yaml()
    critic.num_cells = [64, 64]
    task = CpfTask[args.task.upper()].get_from_yaml()
    task.config["stagger"] = args.stagger
    task.config["privileged_state"] = args.privileged_state
    if args.max_steps is not None:
        task.config["max_steps"] = args.max_steps
    if args.mode is not None:
        task.config["mode"] = args.mode
    if args.messages is not None:
        task.config["messages"] = args.messages
    model: MlpConfig | NeighbourSetMlpConfig = critic
    if args.encoder:
        task.config["shared_slot_statistics"] = True
        model = NeighbourSetMlpConfig.for_task(task.config, num_cells=[64, 64])
    curve = Curve(n=5, evaluation=None, every=args.eval_every, iterations=args.iterations)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    experiment = Experiment(
        task=task,
        algorithm_config=algorithm,
        model_config=model,
        critic_model_config=critic,
        seed=args.seed,
        config=config,
        callbacks=[curve],
    )
    curve.n = experiment.test_env.base_env.n
    actor = experiment.algorithm.get_policy_for_loss("vessel")
    networks = [module for module in actor.modules() if isinstance(module, PolicyNetwork)]
    with torch.no_grad():  # start from the base policy: zero mean residual
        if networks:  # the encoder actor
            last = [networks[0].output.weight, networks[0].output.bias]
        else:
            state = actor.state_dict(keep_vars=True)
            last = [value for key, value in state.items() if "mlp.params" in key][-2:]
        k = experiment.test_env.base_env.core.action_size
        last[0][:k].zero_()
        last[1][:k].zero_()
    at_start = base = None
    if args.eval_fleets:
        curve.evaluation = FixedSeedEvaluation(
            task.config,
            args.eval_fleets,
            statistics=experiment.test_env.base_env.input_statistics,
            max_steps=args.eval_max_steps,
        )
        base, at_start = curve.evaluation.base, curve.evaluation.evaluate(experiment.policy)
        if args.keep_best:
            curve.note(0, at_start["return_minus_base"])
    started = time.perf_counter()
    experiment.run()
    seconds = time.perf_counter() - started
    kept = curve.restore_best()
    save_marl_policy(experiment, args.out, args.algorithm)
    vessel_steps = experiment.total_frames * curve.n
    evaluation_seconds = sum(r["evaluation_seconds"] for r in curve.rows)
    run = {
        "algorithm": args.algorithm,
        "task": args.task,
        "seed": args.seed,
        "settings": {k: v for k, v in settings.items() if k != "save_folder"},
        "scale_mapping": algorithm.scale_mapping,
        "num_cells": model.num_cells,
        "encoder": args.encoder,
        "iterations": experiment.n_iters_performed,
        "vessel_steps": vessel_steps,
        "seconds": seconds,
        "vessel_steps_per_second": vessel_steps / (seconds - evaluation_seconds),
        "collection_seconds": sum(r["collection_seconds"] for r in curve.rows),
        "training_seconds": sum(r["training_seconds"] for r in curve.rows),
        "evaluation_seconds": evaluation_seconds,
        "evaluation": {
            "seeds": list(range(args.eval_fleets)),
            "every": args.eval_every,
            "max_steps": None if curve.evaluation is None else curve.evaluation.max_steps,
            "base": base,
            "at_start": at_start,
        },
        "stagger": bool(task.config["stagger"]),
        "privileged_state": args.privileged_state,
        "kept": kept,
        "versions": {
            "torch": torch.__version__,
            "torchrl": __import__("torchrl").__version__,
            "benchmarl": __import__("benchmarl").__version__,
        },
    }
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=COLUMNS)
    writer.writeheader()
    writer.writerows(curve.rows)
    atomic.write_text(args.out / "curve.csv", text.getvalue())
    atomic.write_text(args.out / "run.json", json.dumps(run, indent=2) + "\n")
    print(json.dumps({k: run[k] for k in ("iterations", "vessel_steps", "seconds")}))
    print(f"end to end: {run['vessel_steps_per_second']:,.0f} vessel-steps/s")
    print("last rows:", *curve.rows[-3:], sep="\n")


if __name__ == "__main__":
    main()
