"""One training run in its folder: learn, evaluate, checkpoint, resume, write the agent.

``agents.training.trainer.train`` claims the folder and hands over to ``TrainingRun``.
The folder during and after a run (``docs/residual_rl.md`` has the user's view):

- ``run.json``: the configuration and schedule, written first (``--resume`` reads it);
- ``progress.csv``: SB3's log (continued, not restarted, by a resumed run);
- ``evaluations.csv`` and ``best/`` (an agent folder): held-out evaluations and
  the best agent so far (``agents.training.schedule``);
- ``checkpoint/``: the latest checkpoint (``agents.training.checkpoint``), replaced whole;
- at the end, or after Ctrl-C: the agent (``policy.safetensors``,
  ``normalization.json``, ``config.json``, ``manifest.json``; ``agents.folder.format``)
  and SB3's ``model.zip``.

The agent and ``model.zip`` are written whole: a copy of the run folder
(hard links, so no data is copied) gets them and replaces the folder
(``cpf_env.infra.atomic.staged_folder``), so a run killed while saving leaves the
folder as it was before the save, never a folder failing its manifest check.
A run killed while training or saving leaves its last checkpoint;
``--resume`` continues from it, and a checkpoint that already reached the
budget (a run killed while saving its agent) only writes the agent. A
replaced run (``overwrite``, ``cpf-train --force``) is trained in a staging
folder beside the old one and swapped in the same way once its agent is
written (or after Ctrl-C); killed before, the old run stays.

A resumed run ends with the same weights, normalization statistics, evaluation
costs and ``progress.csv`` values as an uninterrupted run at the same seed;
only wall-clock columns and fields (``time/*``, ``wall_clock_seconds``,
``evaluation_seconds``, ``train_seconds``, ``vessel_steps_per_second``)
differ (``tests/agents/test_resume.py``).
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import platform
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import CSVOutputFormat, KVWriter, Logger, make_output_format
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

from agents.envs.history_env import HistoryVecEnv
from agents.envs.mixture_env import BalancedRewards, MixtureVecEnv
from agents.envs.slot_statistics import SlotSharedVecNormalize
from agents.folder.actor import actor_tensors, encoder_layout, sb3_actor_layers
from agents.folder.files import AgentFolderError
from agents.folder.format import Normalization, network_from_tensors, read_agent, write_agent
from agents.training.algorithms import (
    build_model,
    make_env,
    planned_timesteps,
    unobserved_columns,
)
from agents.training.checkpoint import checkpoint_timesteps, load_checkpoint
from agents.training.config import TrainConfig, config_from_record
from agents.training.init_from import InitSource
from agents.training.schedule import (
    BEST,
    CHECKPOINT,
    EVALUATIONS,
    PROGRESS,
    Evaluator,
    GracefulInterrupt,
    ProgressBar,
    RunSchedule,
    ScenarioEpisodes,
    ScheduleCallback,
    TrainingInterrupted,
    evaluations_csv,
)
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import EVALUATION_SEED

__all__ = [
    "RUN_RECORD",
    "TrainingRun",
    "prepare_resume",
    "read_init_record",
    "read_run_record",
    "write_run_record",
]

RUN_RECORD = "run.json"


def write_run_record(
    folder: Path,
    config: TrainConfig,
    schedule: RunSchedule,
    evaluation: Any = None,
    device: str = "cpu",
    init_from: dict[str, str] | None = None,
) -> None:
    """Write ``run.json``: the configuration, schedule, evaluation settings and device of a run.

    Args:
        folder: The run folder.
        config: The run's configuration.
        schedule: Its periods.
        evaluation: The evaluator's JSON-ready ``settings`` (if it has any), or None.
        device: The torch device the run trains on (a resumed run may name another).
        init_from: The agent folder the run started from (``agents.training.init_from``), or None.
    """
    record: dict[str, Any] = {
        "config": config.to_json(),
        "device": device,
        "evaluation": evaluation,
        "schedule": {
            "eval_every": schedule.eval_every,
            "checkpoint_every": schedule.checkpoint_every,
        },
    }
    if init_from is not None:
        record["init_from"] = init_from
    atomic.write_text(folder / RUN_RECORD, json.dumps(record, indent=2) + "\n")


def read_run_record(folder: Path) -> tuple[TrainConfig, RunSchedule, Any]:
    """The configuration, schedule and evaluation settings in ``folder/run.json``.

    A record written before agent-folder format 3 (the configuration's ``base`` and flat
    residual fields, the evaluation's ``seeds``) is read in today's layout.

    Raises:
        ValueError: No run record (not a run folder), or an unreadable one.
    """
    path = folder / RUN_RECORD
    if not path.is_file():
        raise ValueError(
            f"{folder} holds no {RUN_RECORD}: nothing to resume (train with cpf-train --out "
            f"{folder} first)."
        )
    try:
        record = json.loads(path.read_text())
        evaluation = record.get("evaluation")
        if evaluation is not None and "seeds" in evaluation:  # written before num_seeds
            evaluation["num_seeds"] = evaluation.pop("seeds")
        config = config_from_record(record["config"])
        return config, RunSchedule(**record["schedule"]), evaluation
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{path} is not a readable run record: {error}") from None


def read_init_record(folder: Path) -> dict[str, str] | None:
    """The ``init_from`` record of the run in ``folder`` (``run.json``), or None."""
    try:
        return json.loads((folder / RUN_RECORD).read_text()).get("init_from")
    except (OSError, json.JSONDecodeError, AttributeError):
        return None


def prepare_resume(
    folder: Path, config: TrainConfig, evaluation: dict[str, Any] | None = None
) -> Path:
    """Check that ``config`` continues the run in ``folder``; return its checkpoint folder.

    Also tidies what a killed run left (the caller holds the folder's lock): a
    ``checkpoint/`` or ``best/`` killed between the two renames of its swap is put
    back, and staging and scratch folders are removed. A checkpoint that reached
    the budget while the folder holds no complete agent of it (the run was
    killed while saving) is returned too: the resumed run only writes the agent.

    Args:
        folder: The run folder.
        config: The configuration the resumed run trains with.
        evaluation: The resumed run's evaluation settings (``ValidationEvaluator.settings``),
            or None.

    Raises:
        ValueError: No checkpoint, ``config`` differs from the run's in anything
            but ``timesteps``, the run's evaluations reset with other seeds (a run
            recorded before the validation seeds), or a budget the checkpoint and
            the agent have reached already.
    """
    saved, _, saved_evaluation = read_run_record(folder)
    if evaluation is not None and saved_evaluation is not None:
        # a record without a seed was evaluated on the test seeds (before the validation ones)
        first, now = (e.get("seed", EVALUATION_SEED) for e in (saved_evaluation, evaluation))
        if first != now:
            raise ValueError(
                f"the run in {folder} evaluated itself on seeds from {first}, and this run "
                f"evaluates from {now}: resuming would mix the two in evaluations.csv and "
                "best/. Start a new run (another --out)."
            )
    for child in (CHECKPOINT, BEST):  # a run killed while swapping one in: put it back
        atomic.recover_folder(folder / child, remove_leftovers=True)
    for scratch in folder.glob(".evaluating-*"):  # a run killed while evaluating
        shutil.rmtree(scratch, ignore_errors=True)
    differ = [
        f.name
        for f in dataclasses.fields(config)
        if f.name != "timesteps" and getattr(saved, f.name) != getattr(config, f.name)
    ]
    if differ:
        raise ValueError(
            f"--resume continues the run in {folder} with its own configuration; these "
            f"settings differ from it: {differ}. Only the budget (-n) may change."
        )
    checkpoint = folder / CHECKPOINT
    if not (checkpoint / "state.json").is_file():
        raise ValueError(
            f"{folder} has no checkpoint to resume from (the run was killed before its "
            "first one, or ran with checkpoint_every = 0); start it again with --force."
        )
    done = checkpoint_timesteps(checkpoint)
    if config.timesteps <= done and _holds_agent(folder, done):
        raise ValueError(
            f"the checkpoint in {checkpoint} has trained {done:,} vessel-steps already, as many "
            f"as the budget of {config.timesteps:,}; give a larger -n to extend the run."
        )
    return checkpoint


def _holds_agent(folder: Path, timesteps: int) -> bool:
    """Whether ``folder`` holds a complete, final agent trained for ``timesteps`` vessel-steps."""
    try:
        record, _, _ = read_agent(folder)
    except (AgentFolderError, OSError):
        return False
    return record.get("timesteps_done") == timesteps and not record.get("interrupted")


def _link_tree(source: Path, target: Path) -> None:
    """Copy the folder ``source`` into ``target`` as hard links (copies where links fail).

    Every writer replaces files (``cpf_env.infra.atomic``) rather than writing into
    them, so the two folders never change each other's files.
    """

    def link(src: str, dst: str) -> None:
        try:
            os.link(src, dst)
        except OSError:
            shutil.copy2(src, dst)

    shutil.copytree(source, target, symlinks=True, dirs_exist_ok=True, copy_function=link)


class _AppendingCSV(CSVOutputFormat):
    """SB3's ``progress.csv`` writer, continuing the rows a checkpoint kept.

    The file is replaced, not truncated: a hard link of it (a copy of the run
    folder) keeps its content.
    """

    def __init__(self, filename: str, previous: str) -> None:
        Path(filename).unlink(missing_ok=True)
        super().__init__(filename)
        if previous:
            self.file.write(previous)
            self.file.flush()
            self.keys = previous.splitlines()[0].split(",")


def _versions() -> dict[str, str]:
    """Versions of the packages a trained model depends on."""
    import gymnasium
    import stable_baselines3

    import cpf_env

    return {
        "python": platform.python_version(),
        "cpf_env": cpf_env.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
    }


class TrainingRun:
    """The env, model, logger and callbacks of one run (fresh, or from a checkpoint).

    Args:
        config: The run's configuration.
        folder: The folder the run works in (exists): the run folder, or a staging
            folder beside it that replaces it at the end (``overwrite``).
        schedule: Evaluation and checkpoint periods.
        evaluate: Agent folder -> mean cost per scenario, or None.
        checkpoint: The checkpoint folder to resume from, or None (a fresh run).
        tensorboard_log: Parent folder of the TensorBoard event files, or None.
        destination: The run folder (claimed by the caller's lock); None: ``folder``.
        device: The torch device SB3 trains on (``agents.training.device.torch_device``).
        init_from: The agent folder a fresh run starts from (``agents.training.init_from``), or
            its record for a resumed one (the checkpoint holds the weights); None: neither.

    Raises:
        ValueError: Too little free space for the run's outputs, or a device this
            machine does not have.
    """

    def __init__(
        self,
        config: TrainConfig,
        folder: Path,
        schedule: RunSchedule,
        evaluate: Evaluator | None,
        checkpoint: Path | None,
        tensorboard_log: str | Path | None,
        destination: Path | None = None,
        device: str = "cpu",
        init_from: InitSource | dict[str, str] | None = None,
    ) -> None:
        self.config, self.folder = config, folder
        self.init_record = init_from.record() if isinstance(init_from, InitSource) else init_from
        self.destination = folder if destination is None else destination
        self.resumed = checkpoint is not None
        torch.manual_seed(config.seed)
        if config.torch_threads is not None:
            torch.set_num_threads(config.torch_threads)
        self.venv = make_env(config)
        self.venv.seed(config.seed)
        below: VecEnv = self.venv
        if config.history:  # below VecNormalize: the history is normalized with the rest
            below = HistoryVecEnv(self.venv, config.history)
        self.env: VecEnv = VecMonitor(below)
        if config.balance_rewards and isinstance(self.venv, MixtureVecEnv):
            self.env = BalancedRewards(self.env, self.venv)
        if config.normalize_observations:
            if config.shared_slot_statistics:
                slots, size = config.learner_slots()
                self.env = SlotSharedVecNormalize(
                    self.env,
                    slots,
                    size,
                    gamma=config.gamma,
                    raw_weights=config.encoder
                    is not None,  # empty slots stay 0 (agents.folder.encoder)
                )
            else:
                self.env = VecNormalize(
                    self.env, norm_obs=True, norm_reward=False, gamma=config.gamma
                )
        self.model = build_model(config, self.env, device)
        if isinstance(init_from, InitSource) and checkpoint is None:
            init_from.apply(self.model, self.env)
        if init_from is not None and isinstance(self.env, VecNormalize):
            self.env.training = False  # the folder's statistics stay (agents.training.init_from)
        atomic.check_writable(self.destination, _bytes_needed(self.model))
        previous = ""
        if checkpoint is not None and (checkpoint / PROGRESS).is_file():
            previous = (checkpoint / PROGRESS).read_text()
        outputs: list[KVWriter] = [_AppendingCSV(str(folder / PROGRESS), previous)]
        if tensorboard_log is not None:
            events = Path(tensorboard_log) / self.destination.name
            outputs.append(make_output_format("tensorboard", str(events)))
        self.model.set_logger(Logger(str(folder), outputs))
        state: dict[str, Any] = {}
        if checkpoint is not None:
            self.model._last_obs = self.env.reset()  # type: ignore[assignment]  # as learn would
            state = load_checkpoint(checkpoint, self.model)
            if (checkpoint / BEST).is_dir():
                with atomic.staged_folder(folder / BEST) as staging:
                    shutil.copytree(checkpoint / BEST, staging, dirs_exist_ok=True)
            else:
                shutil.rmtree(folder / BEST, ignore_errors=True)
            atomic.write_text(folder / EVALUATIONS, evaluations_csv(state.get("rows", [])))
        self.interrupt = GracefulInterrupt()
        self.schedule = ScheduleCallback(
            folder, schedule, self.write_agent, evaluate, self.interrupt, state or None
        )
        self.total = planned_timesteps(config, self.env.num_envs)

    def learn(self, progress: bool, callbacks: Sequence[BaseCallback]) -> None:
        """Train to the budget (or Ctrl-C), then write the agent and ``model.zip``.

        A run resumed from a checkpoint at the budget only writes them.

        Raises:
            TrainingInterrupted: After Ctrl-C, once the checkpoint and agent are written.
        """
        done = int(self.model.num_timesteps)
        if done >= self.total:
            self.model.logger.close()
            if progress:
                print(
                    f"cpf-train: the checkpoint has trained {done:,} vessel-steps, the whole "
                    "budget; writing its agent (the run was stopped while saving it).",
                    flush=True,
                )
            self._finish(interrupted=False)
            return
        if progress and self.total != self.config.timesteps:
            print(
                f"cpf-train: the budget of {self.config.timesteps:,} vessel-steps is rounded "
                f"up to {self.total:,}: {self._rounding()}.",
                flush=True,
            )
        bar = ProgressBar(self.total, done, progress, self.schedule)
        stopped: TrainingInterrupted | None = None
        try:
            with self.interrupt:
                self.model.learn(
                    self.total - done,
                    callback=[self.schedule, bar, *self._mixture_logs(), *callbacks],
                    reset_num_timesteps=not self.resumed,
                )
        except TrainingInterrupted as stop:
            stopped = stop
        finally:
            bar._on_training_end()
            self.model.logger.close()
        self._finish(interrupted=stopped is not None)
        if stopped is not None:
            raise stopped

    def _mixture_logs(self) -> list[BaseCallback]:
        """Per-scenario episode costs in the logs, for a mixture."""
        return [ScenarioEpisodes()] if len(self.config.scenarios) > 1 else []

    def _rounding(self) -> str:
        if self.config.algo == "ppo":
            return (
                f"PPO trains whole rollouts of n_steps x num_envs = {self.config.n_steps} x "
                f"{self.env.num_envs} = {self.config.n_steps * self.env.num_envs:,} vessel-steps"
            )
        return f"SAC steps all {self.env.num_envs:,} slots at once"

    def write_agent(self, folder: Path, interrupted: bool = False) -> None:
        """Write the current agent (actor, frozen normalization, record) into ``folder``."""
        module = sb3_actor_layers(self.model, self.config.algo)[0]  # the actor's encoder, if any
        encoder = None if module is None else encoder_layout(module)
        network = network_from_tensors(
            actor_tensors(self.model, self.config.algo),
            self.config.algo,
            self.config.net_arch,
            folder / "policy.safetensors",
            encoder,
        )
        normalization = None
        if isinstance(self.env, VecNormalize):
            rms = cast(RunningMeanStd, self.env.obs_rms)
            unobserved = list(unobserved_columns(self.model))  # the actor's inputs only
            normalization = Normalization(
                np.delete(rms.mean, unobserved), np.delete(rms.var, unobserved), self.env.epsilon,
                self.env.clip_obs,
            )  # fmt: skip
        seconds = self.schedule.seconds()
        training = seconds - self.schedule.evaluations.seconds
        steps = int(self.model.num_timesteps)
        record: dict[str, Any] = {
            "config": self.config.to_json(),
            "num_envs": self.venv.num_envs,
            "timesteps_done": steps,
            "train_seconds": round(training, 1),  # held-out evaluations excluded
            "vessel_steps_per_second": round(steps / training) if training > 0 else 0,
            "evaluation_seconds": round(self.schedule.evaluations.seconds, 1),
            "wall_clock_seconds": round(seconds, 1),
            "versions": _versions(),
        }
        if self.init_record is not None:
            record["init_from"] = self.init_record
        if interrupted:
            record["interrupted"] = True
        write_agent(folder, record, network, normalization)

    def _finish(self, interrupted: bool) -> None:
        """Replace the run folder with a copy of the working folder, the agent and ``model.zip``.

        Killed before the swap, the run folder is as it was (its checkpoint stays).
        """
        saved = io.BytesIO()
        self.model.save(saved)  # SB3's format; evaluation never reads it
        with atomic.staged_folder(self.destination) as staging:
            _link_tree(self.folder, staging)
            atomic.write_bytes(staging / "model.zip", saved.getvalue())
            self.write_agent(staging, interrupted=interrupted)


def _bytes_needed(model: Any) -> int:
    """Disk space a run's outputs need at most (a generous estimate).

    The model's parameters appear, with the optimizer's two moments, in
    ``model.zip`` and the checkpoint, each up to twice while being replaced,
    and as the actor in the agent, ``best/`` and an evaluation's scratch copy;
    SAC's replay buffer is in the checkpoint (twice while it is replaced).
    """
    parameters = sum(p.numel() * p.element_size() for p in model.policy.parameters())
    buffer = getattr(model, "replay_buffer", None)
    stored = vars(buffer).values() if buffer is not None else ()
    replay = sum(value.nbytes for value in stored if isinstance(value, np.ndarray))
    return 16 * parameters + 2 * replay + 2**20
