"""What ``train`` does between rollouts: held-out evaluation, best model, checkpoints, Ctrl-C.

``RunSchedule`` says how often (in vessel-steps); ``ScheduleCallback`` does it
at the start of a rollout (after the previous update, the one point where
SB3's loop holds no state besides the model and the env, so a checkpoint
taken there resumes bit for bit), in this order:

1. evaluation, when due: the current agent (deterministic actor, the
   normalization statistics frozen as they are) is written as an agent folder
   and handed to ``evaluate`` (folder -> mean cost per scenario; ``cpf-train``
   passes the benchmark's own evaluation on the validation seeds, so the number
   is the one ``cpf-bench --split test --seed 9000`` prints for that folder, and
   the ``test`` seeds play no part in the choice). A new best
   mean cost replaces ``best/``. ``evaluations.csv`` gets a row (rewritten
   atomically; ``EvaluationLog``, which ``cpf-distill`` uses too):
   vessel-steps, wall-clock seconds since the run started (evaluations
   included; summed over resumed parts), the evaluation's own seconds, the
   mean cost over scenarios and one ``cost_<scenario>`` column each;
2. a checkpoint, when due or when Ctrl-C was pressed (``checkpoint/``, replaced
   whole: ``agents.training.checkpoint``'s files, a copy of ``progress.csv``, ``best/``
   and this schedule's state);
3. after Ctrl-C, ``TrainingInterrupted`` ends ``learn`` (``train`` then writes
   the agent so far and re-raises it).

A first Ctrl-C only sets a flag (``GracefulInterrupt``): the current rollout
and update finish (seconds at most), then the checkpoint is written; a
second Ctrl-C raises ``KeyboardInterrupt`` at once (the last periodic
checkpoint stays).
"""

from __future__ import annotations

import csv
import io
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from tqdm.auto import tqdm

from agents.training.checkpoint import save_checkpoint
from cpf_env.infra import atomic

__all__ = [
    "BEST",
    "CHECKPOINT",
    "EVALUATIONS",
    "EvaluationLog",
    "Evaluator",
    "GracefulInterrupt",
    "ProgressBar",
    "RunSchedule",
    "ScenarioEpisodes",
    "ScheduleCallback",
    "TrainingInterrupted",
]

#: Agent-folder path -> mean cost per evaluation scenario (lower is better).
Evaluator = Callable[[Path], Mapping[str, float]]
BEST = "best"
CHECKPOINT = "checkpoint"
EVALUATIONS = "evaluations.csv"
PROGRESS = "progress.csv"


@dataclass(frozen=True)
class RunSchedule:
    """How often a run evaluates and checkpoints, in vessel-steps (SB3 timesteps).

    Both happen at the first rollout boundary at or after each multiple; 0 turns
    one off. Evaluation also runs before training (step 0: a residual agent is
    then exactly its base policy) and after the last update.

    Attributes:
        eval_every: Vessel-steps between evaluations (needs an evaluator).
        checkpoint_every: Vessel-steps between checkpoints (one is also written
            at the end, so ``--resume`` can extend a finished run).
    """

    eval_every: int = 0
    checkpoint_every: int = 0

    def __post_init__(self) -> None:
        for name in ("eval_every", "checkpoint_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0 (0: never), got {value!r}.")


class TrainingInterrupted(Exception):
    """Training stopped on Ctrl-C, at a rollout boundary, after writing a checkpoint.

    Attributes:
        timesteps: Vessel-steps trained when it stopped.
    """

    def __init__(self, timesteps: int) -> None:
        super().__init__(f"training interrupted at {timesteps:,} vessel-steps")
        self.timesteps = timesteps


class GracefulInterrupt:
    """Context manager: the first SIGINT sets ``requested``, the second raises KeyboardInterrupt.

    Does nothing outside the main thread (signal handlers cannot be set there).
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None
        self._installed = False

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        del signum, frame
        self.requested = True
        signal.signal(signal.SIGINT, self._previous)
        tqdm.write(
            "cpf-train: Ctrl-C: finishing this update, then writing a checkpoint and the agent "
            "(Ctrl-C again to abort at once; the last periodic checkpoint stays).",
        )

    def __enter__(self) -> GracefulInterrupt:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
            self._installed = True
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if self._installed and not self.requested:
            signal.signal(signal.SIGINT, self._previous)


def evaluations_csv(rows: list[dict[str, float]]) -> str:
    """``evaluations.csv`` text of the rows (columns in first-row order)."""
    buffer = io.StringIO()
    if rows:
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return buffer.getvalue()


class EvaluationLog:
    """A run's held-out evaluations: the rows of ``evaluations.csv``, and ``best/``.

    ``cpf-train`` (through ``ScheduleCallback``) and ``cpf-distill`` (through
    ``agents.distill.dagger``) evaluate with it. Each evaluation writes the current
    agent as an agent folder in a scratch folder, hands it to ``evaluate``
    and appends a row: ``vessel_steps``, ``wall_clock_seconds`` (the run's
    clock after the evaluation, evaluations included), ``evaluation_seconds``
    (this one's own, writing the folder included), ``mean_cost`` (over the
    scenarios) and one ``cost_<scenario>`` column each.

    Args:
        evaluate: Agent folder -> mean cost per scenario; None for a run that does not
            evaluate (it keeps the log's state for its checkpoints, and ``run`` is refused).
        best: The folder a new lowest mean cost replaces (a copy of the agent
            evaluated), or None to keep none.
        rows: Earlier rows (a resumed run).
        best_cost: The lowest mean cost so far (a resumed run), or None.
        seconds: Seconds spent evaluating so far (a resumed run).

    Attributes:
        rows: The rows, oldest first.
        best_cost: The lowest mean cost so far (inf before the first evaluation).
        seconds: Seconds spent evaluating in all.
    """

    def __init__(
        self,
        evaluate: Evaluator | None,
        best: Path | None,
        rows: list[dict[str, float]] | None = None,
        best_cost: float | None = None,
        seconds: float = 0.0,
    ) -> None:
        self.evaluate, self.best = evaluate, best
        self.rows: list[dict[str, float]] = list(rows or [])
        self.best_cost = np.inf if best_cost is None else float(best_cost)
        self.seconds = float(seconds)

    @property
    def latest_cost(self) -> float | None:
        """Mean cost of the latest evaluation, or None before the first."""
        return self.rows[-1]["mean_cost"] if self.rows else None

    def run(
        self,
        write_agent: Callable[[Path], None],
        vessel_steps: int,
        clock: Callable[[], float],
        scratch: Path | None = None,
    ) -> dict[str, float]:
        """Evaluate the agent ``write_agent`` writes; keep it if best; append and return its row.

        Args:
            write_agent: Writes the agent into an existing, empty folder.
            vessel_steps: The run's vessel-steps so far (the row's ``vessel_steps``).
            clock: The run's wall-clock seconds so far, read after the evaluation.
            scratch: Where the agent folder is written for the evaluation (removed
                after it); None: the system's temporary folder.
        """
        if self.evaluate is None:
            raise ValueError("this run has no evaluator; give one to evaluate.")
        start = time.perf_counter()
        with tempfile.TemporaryDirectory(dir=scratch, prefix=".evaluating-") as folder:
            agent = Path(folder)
            write_agent(agent)
            costs = {name: float(cost) for name, cost in self.evaluate(agent).items()}
            mean = float(np.mean(list(costs.values())))
            if mean < self.best_cost:
                self.best_cost = mean
                if self.best is not None:
                    with atomic.staged_folder(self.best) as staging:
                        for path in agent.iterdir():
                            shutil.copy2(path, staging / path.name)
        spent = time.perf_counter() - start
        self.seconds += spent
        row = {
            "vessel_steps": int(vessel_steps),
            "wall_clock_seconds": round(clock(), 3),
            "evaluation_seconds": round(spent, 3),
            "mean_cost": mean,
            **{f"cost_{name}": cost for name, cost in costs.items()},
        }
        self.rows.append(row)
        return row


class ScheduleCallback(BaseCallback):
    """Evaluates, keeps the best agent and checkpoints a run (see the module docstring).

    Args:
        folder: The run's output folder.
        schedule: The periods.
        write_agent: Writes the model's current agent into an existing folder.
        evaluate: Agent folder -> mean cost per scenario, or None (no evaluation).
        interrupt: Its ``requested`` flag stops training at the next boundary.
        state: The schedule's state from a checkpoint (``state()``), to resume.
    """

    def __init__(
        self,
        folder: Path,
        schedule: RunSchedule,
        write_agent: Callable[[Path], None],
        evaluate: Evaluator | None,
        interrupt: GracefulInterrupt | None = None,
        state: dict[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.folder, self.schedule, self.evaluate = folder, schedule, evaluate
        self._write_agent = write_agent
        self._interrupt = interrupt
        state = state or {}
        self.evaluations = EvaluationLog(
            evaluate,
            folder / BEST,
            state.get("rows", []),
            state.get("best_cost"),
            state.get("eval_seconds", 0.0),
        )
        self.next_eval = int(state.get("next_eval", 0))
        self.next_checkpoint = int(state.get("next_checkpoint", schedule.checkpoint_every))
        self.last_checkpoint = int(state.get("last_checkpoint", -1))
        self.seconds_before = float(state.get("seconds", 0.0))
        self._start = time.perf_counter()

    def seconds(self) -> float:
        """Wall-clock seconds of the run so far (earlier resumed parts included)."""
        return self.seconds_before + time.perf_counter() - self._start

    def state(self) -> dict[str, Any]:
        """JSON-ready state, stored in each checkpoint."""
        evaluations = self.evaluations
        return {
            "rows": evaluations.rows,
            "best_cost": evaluations.best_cost if np.isfinite(evaluations.best_cost) else None,
            "next_eval": self.next_eval,
            "next_checkpoint": self.next_checkpoint,
            "last_checkpoint": self.last_checkpoint,
            "seconds": self.seconds(),
            "eval_seconds": evaluations.seconds,
        }

    def _on_step(self) -> bool:
        return True

    def _on_training_start(self) -> None:
        rows = self.evaluations.rows
        last = rows[-1] if rows else None
        if last is not None and last["vessel_steps"] == self.model.num_timesteps:
            self._log(last)  # resumed right after this evaluation: not yet in progress.csv

    def _log(self, row: Mapping[str, float]) -> None:
        for name, value in row.items():
            if name == "mean_cost" or name.startswith("cost_"):
                self.logger.record(f"eval/{name}", value)

    def _on_rollout_start(self) -> None:
        steps = self.model.num_timesteps
        if self._evaluating() and steps >= self.next_eval:
            self.run_evaluation()
        interrupted = self._interrupt is not None and self._interrupt.requested
        due = self.schedule.checkpoint_every > 0 and steps >= self.next_checkpoint
        if due or interrupted:
            every = self.schedule.checkpoint_every
            if every > 0:
                self.next_checkpoint = (steps // every + 1) * every
            self.write_checkpoint()
        if interrupted:
            raise TrainingInterrupted(steps)

    def _on_training_end(self) -> None:
        steps = self.model.num_timesteps
        rows = self.evaluations.rows
        if self._evaluating() and (not rows or rows[-1]["vessel_steps"] != steps):
            self.run_evaluation()
        if self.schedule.checkpoint_every > 0 and self.last_checkpoint != steps:
            self.write_checkpoint()

    def _evaluating(self) -> bool:
        return self.evaluate is not None and self.schedule.eval_every > 0

    def run_evaluation(self) -> None:
        """Evaluate the current agent, log it, keep it if best, rewrite evaluations.csv."""
        steps = int(self.model.num_timesteps)
        row = self.evaluations.run(self._write_agent, steps, self.seconds, scratch=self.folder)
        every = self.schedule.eval_every
        self.next_eval = (steps // every + 1) * every
        atomic.write_text(self.folder / EVALUATIONS, evaluations_csv(self.evaluations.rows))
        self._log(row)

    def write_checkpoint(self) -> None:
        """Replace ``checkpoint/`` with the state at this boundary."""
        self.last_checkpoint = int(self.model.num_timesteps)
        with atomic.staged_folder(self.folder / CHECKPOINT) as staging:
            save_checkpoint(staging, self.model, self.state())
            if (self.folder / PROGRESS).is_file():
                shutil.copy2(self.folder / PROGRESS, staging / PROGRESS)
            if (self.folder / BEST).is_dir():
                shutil.copytree(self.folder / BEST, staging / BEST)


class ProgressBar(BaseCallback):
    """tqdm bar over vessel-steps with the latest evaluation's mean cost and the time it took.

    Args:
        total: Vessel-steps the run ends at.
        initial: Vessel-steps already done (a resumed run).
        enabled: Show the bar.
        schedule: The run's ``ScheduleCallback`` (its latest evaluation), or None; it must
            come before the bar in the callback list, so that the bar shows the final
            evaluation too.
    """

    def __init__(
        self, total: int, initial: int, enabled: bool, schedule: ScheduleCallback | None
    ) -> None:
        super().__init__()
        self._bar = tqdm(
            total=total, initial=initial, unit="step", unit_scale=True, disable=not enabled
        )
        self._schedule = schedule
        self._shown: float | None = None

    def _on_step(self) -> bool:
        self._bar.update(self.training_env.num_envs)
        return True

    def _on_rollout_end(self) -> None:
        schedule = self._schedule
        if schedule is not None and schedule.evaluations.latest_cost is not None:
            self._bar.set_postfix(
                eval_cost=f"{schedule.evaluations.latest_cost:.4g}",
                eval_s=f"{schedule.evaluations.seconds:.0f}",
                refresh=False,
            )

    def _on_training_end(self) -> None:
        self._on_rollout_end()  # the final evaluation, which runs just before (callback order)
        self._bar.close()


class ScenarioEpisodes(BaseCallback):
    """Logs each mixture scenario's mean episodic cost per rollout (``rollout/ep_cost/<name>``).

    Reads the infos of ending slots: ``MixtureVecEnv`` names their scenario and
    ``VecMonitor`` adds the episode's return (``"episode"["r"]``).
    """

    def __init__(self) -> None:
        super().__init__()
        self._costs: dict[str, list[float]] = {}

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            if "episode" in info and "scenario" in info:
                self._costs.setdefault(info["scenario"], []).append(-float(info["episode"]["r"]))
        return True

    def _on_rollout_end(self) -> None:
        for name, costs in self._costs.items():
            self.logger.record(f"rollout/ep_cost/{name}", float(np.mean(costs)))
        self._costs = {}
