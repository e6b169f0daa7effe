"""Training residual (or from-scratch) agents with Stable-Baselines3 on ``FleetVecEnv``.

``train(config, out)`` (``config`` an ``agents.training.config.TrainConfig``)
builds ``FleetVecEnv`` (or ``MixtureVecEnv``) -> ``VecMonitor`` ->
``VecNormalize`` (observations only; rewards stay in their units so episode costs read as the
benchmark's), creates PPO or SAC with residual-learning defaults and learns
in the run folder ``out`` (a lock refuses a second run on the same folder;
``agents.training.run_folder`` lists its files and how they are written whole;
``overwrite`` trains beside the old run, which stays until the new agent is
written): held-out evaluations and the best
agent (``best/``), checkpoints every K vessel-steps (``checkpoint/``, from
which ``resume=True`` continues bit for bit), and at the end (or after
Ctrl-C) the agent itself:

- ``policy.safetensors``, ``normalization.json``, ``config.json`` (the exact
  ``TrainConfig``, the package versions and the training time) and
  ``manifest.json``: the data-only agent (``agents.folder.format``) that
  ``agents.load_policy(out)`` reads;
- ``model.zip``: SB3's own save, to continue training with plain SB3 (a pickle,
  never read by evaluation nor by ``resume``);
- ``progress.csv`` (and TensorBoard event files with ``tensorboard_log``).

``init_from`` starts PPO from an agent folder of the same recipe (a distilled
student, say) instead of the zero residual: ``agents.training.init_from``.

Residual-learning defaults (Johannink et al. 2019, Silver et al. 2018, and
our measurements in ``docs/residual_rl.md``): the policy's mean action starts
at exactly zero (its output layer is zeroed), so training starts from the
base policy; the initial exploration noise is small (``log_std_init = -1``,
a standard deviation of 0.37 of the residual range, i.e. 7 % of the force
limits at ``scale = 0.2``); the residual range is 20 % of the limits.

PPO settings are chosen for throughput at thousands of slots, where the
updates, not the simulator, dominate (``docs/residual_rl.md`` has the
measurements): short rollouts (32 steps x num_envs samples), large
minibatches (8,192) and few epochs (4).
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path

from stable_baselines3.common.callbacks import BaseCallback

from agents.training.config import TrainConfig
from agents.training.device import torch_device
from agents.training.init_from import InitSource, read_init_source
from agents.training.run_folder import (
    TrainingRun,
    prepare_resume,
    read_init_record,
    write_run_record,
)
from agents.training.schedule import Evaluator, RunSchedule
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import check_training

__all__ = ["train"]


def train(
    config: TrainConfig,
    out: str | Path,
    progress: bool = True,
    overwrite: bool = False,
    callbacks: Sequence[BaseCallback] = (),
    evaluate: Evaluator | None = None,
    schedule: RunSchedule | None = None,
    resume: bool = False,
    tensorboard_log: str | Path | None = None,
    run_files: Mapping[str, str] | None = None,
    device: str = "cpu",
    init_from: str | Path | None = None,
) -> Path:
    """Train an agent into the run folder ``out`` (see the module docstring).

    Args:
        config: The run.
        out: Output folder (created).
        progress: Show a progress bar (with the latest evaluation cost) and say how the
            budget was rounded.
        overwrite: Replace a run already in ``out``: the new run is trained beside it
            and replaces it whole once its agent is written; killed before, the old
            run stays as it was.
        callbacks: More SB3 callbacks (a sweep's reporting to Ray Tune, say).
        evaluate: Agent folder -> mean cost per scenario on held-out seeds (``cpf-train``
            passes the validation seeds, ``agents.training.evaluation``); None: no evaluation.
        schedule: Evaluation and checkpoint periods (default: neither).
        resume: Continue the run in ``out`` from its last checkpoint; ``config`` must be
            the run's own (``run.json``) but for a larger ``timesteps``.
        tensorboard_log: Also write TensorBoard event files to ``tensorboard_log/<out name>``.
        run_files: File name -> text, written into ``out`` when the run (or its resumed
            part) starts (``cpf-train`` saves its resolved ``hyperparameters.toml`` so).
        device: The torch device SB3 trains on: ``"cpu"`` (default), ``"auto"``, ``"cuda"``,
            ``"cuda:N"`` (``agents.training.device.torch_device``); recorded in ``run.json``, not in
            the ``TrainConfig``. The agent folder loads on the CPU whatever trained it;
            resuming is bit for bit on the CPU (torch's GPU generators are not checkpointed).
        init_from: An agent folder (a ``cpf-distill`` student, say) to start PPO's actor
            and observation statistics from (``agents.training.init_from``: same recipe, critic
            fresh, statistics frozen); recorded in ``run.json`` and ``config.json``. A
            resumed run keeps its own record and may not name another.

    Returns:
        The output folder.

    Raises:
        FileExistsError: ``out`` holds files and neither ``overwrite`` nor ``resume``.
        ValueError: ``out`` is empty, a file, a symbolic link, not writable or short of
            space for the run, a device this machine does not have, a held-out
            evaluation scenario or seed (``splits.check_training``), nothing to resume,
            a configuration that differs from the run's own, or an ``init_from``
            folder of another recipe (nothing is written then).
        TrainingInterrupted: Ctrl-C; the checkpoint and the agent so far are written.
        cpf_env.infra.atomic.FolderLockedError: Another run is writing ``out``.
    """
    for name in config.scenarios:
        check_training(name, range(config.seed, config.seed + config.fleets))
    where = str(torch_device(device))
    folder = _output_folder(out)
    if resume and init_from is not None:
        raise ValueError(
            "--init-from starts a run; --resume continues one from its checkpoint (the run "
            "keeps the init folder it started from): drop --init-from."
        )
    source = None if init_from is None else read_init_source(init_from, config)
    schedule = schedule or RunSchedule()
    if tensorboard_log is not None:
        try:
            import tensorboard  # noqa: F401
        except ImportError as error:
            raise ValueError(
                "--tensorboard-log needs tensorboard: pip install -e '.[rl]'."
            ) from error
    atomic.check_writable(folder)  # the space is checked once the model exists
    with atomic.FolderLock(folder, "another training run"):  # recovers a killed swap first
        init: InitSource | dict[str, str] | None = source
        if resume:
            resume_state = prepare_resume(folder, config, getattr(evaluate, "settings", None))
            workdir = folder
            init = read_init_record(folder)
        else:
            replacing = folder.is_dir() and any(folder.iterdir())
            if replacing and not overwrite:
                held = "a trained model" if (folder / "config.json").exists() else "files"
                raise FileExistsError(
                    f"{folder} already holds {held}; choose another output folder, "
                    "overwrite it (cpf-train --force, train(..., overwrite=True)) or "
                    "continue it (cpf-train --resume)."
                )
            # The new run is built beside the old one, which stays until the new agent is
            # written; a killed run's staging folder goes with the next lock.
            workdir = atomic.new_staging_folder(folder) if replacing else folder
            resume_state = None
        fresh = workdir == folder and not resume and not folder.exists()
        try:
            try:
                workdir.mkdir(parents=True, exist_ok=True)
                write_run_record(
                    workdir,
                    config,
                    schedule,
                    getattr(evaluate, "settings", None),
                    where,
                    init.record() if isinstance(init, InitSource) else init,
                )
                for name, text in (run_files or {}).items():
                    atomic.write_text(workdir / name, text)
                run = TrainingRun(
                    config,
                    workdir,
                    schedule,
                    evaluate,
                    resume_state,
                    tensorboard_log,
                    folder,
                    where,
                    init,
                )
            except BaseException:  # refused before training (no space, say): nothing left
                if fresh:
                    shutil.rmtree(folder, ignore_errors=True)
                raise
            run.learn(progress, callbacks)
        finally:
            if workdir != folder:  # swapped in by learn, or a failed run: the old one stays
                shutil.rmtree(workdir, ignore_errors=True)
    return folder


def _output_folder(out: str | Path) -> Path:
    """``out`` as a folder path, refusing an empty one, a symbolic link and an existing file."""
    if not str(out).strip():
        raise ValueError("the output folder is empty; give one (cpf-train --out DIR).")
    folder = Path(out)
    atomic.refuse_link(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{folder} is a file; give a folder for the trained agent.")
    return folder
