"""Training residual (or from-scratch) agents with Stable-Baselines3 on ``FleetVecEnv``.

``train(config, out)`` (``config`` an ``agents.train_config.TrainConfig``)
builds ``FleetVecEnv`` (or ``MixtureVecEnv``) -> ``VecMonitor`` ->
``VecNormalize`` (observations only; rewards stay in their units so episode costs read as the
benchmark's), creates PPO or SAC with residual-learning defaults and learns
in the run folder ``out`` (a lock refuses a second run on the same folder;
``agents.run_folder`` lists its files): held-out evaluations and the best
agent (``best/``), checkpoints every K vessel-steps (``checkpoint/``, from
which ``resume=True`` continues bit for bit), and at the end (or after
Ctrl-C) the agent itself:

- ``policy.safetensors``, ``normalization.json``, ``config.json`` (the exact
  ``TrainConfig``, the package versions and the training time) and
  ``manifest.json``: the data-only agent (``agents.agent_folder``) that
  ``agents.load_policy(out)`` reads;
- ``model.zip``: SB3's own save, to continue training with plain SB3 (a pickle,
  never read by evaluation nor by ``resume``);
- ``progress.csv`` (and TensorBoard event files with ``tensorboard_log``).

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
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import cast

import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from agents.mixture_env import MixtureVecEnv
from agents.schedule import Evaluator, RunSchedule
from agents.train_config import TrainConfig
from agents.vec_env import FleetVecEnv
from cpf_env.infra import atomic
from cpf_env.scenarios.splits import check_training

__all__ = ["ALGORITHMS", "build_model", "make_env", "train"]

#: SB3 algorithms by name.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC}


def make_env(config: TrainConfig, num_fleets: int | None = None) -> FleetVecEnv | MixtureVecEnv:
    """The vector env of a run (``num_fleets`` overrides ``config.fleets``).

    A ``FleetVecEnv`` for one scenario, a ``MixtureVecEnv`` for several.
    """
    base = None if config.base == "none" else config.base
    fleets = config.fleets if num_fleets is None else num_fleets
    residual = config.residual_config()
    if len(config.scenarios) > 1:
        return MixtureVecEnv(
            config.scenarios,
            num_fleets=fleets,
            base_policy=base,
            residual=residual,
            scenario_overrides=[config.scenario_overrides(name) for name in config.scenarios],
        )
    return FleetVecEnv(
        config.home_scenario,
        num_fleets=fleets,
        base_policy=base,
        residual=residual,
        **config.scenario_overrides(),
    )


def build_model(config: TrainConfig, env: VecEnv) -> BaseAlgorithm:
    """The untrained PPO or SAC model ``train`` uses, on ``env``; the mean action starts at zero.

    Args:
        config: The run (algorithm, network, learning settings, seed).
        env: The (monitored, maybe normalized) ``FleetVecEnv`` from ``make_env``.
    """
    arch = list(config.net_arch)
    if config.algo == "ppo":
        rollout = config.n_steps * env.num_envs
        if config.batch_size > rollout:
            warnings.warn(
                f"batch_size {config.batch_size} is larger than one rollout (n_steps x vessel "
                f"slots = {config.n_steps} x {env.num_envs} = {rollout}); PPO uses minibatches "
                f"of {rollout}. Lower --batch-size or raise --n-steps or --fleets.",
                stacklevel=2,
            )
        model: BaseAlgorithm = PPO(
            "MlpPolicy",
            env,
            learning_rate=config.learning_rate,
            n_steps=config.n_steps,
            batch_size=min(config.batch_size, rollout),  # <= one rollout
            n_epochs=config.n_epochs,
            gamma=config.gamma,
            seed=config.seed,
            device="cpu",
            policy_kwargs={"net_arch": arch, "log_std_init": config.log_std_init},
        )
        layer = cast(torch.nn.Linear, model.policy.action_net)
    else:
        model = SAC(
            "MlpPolicy",
            env,
            learning_rate=config.learning_rate,
            buffer_size=config.buffer_size,
            batch_size=config.batch_size,
            gradient_steps=config.gradient_steps,
            learning_starts=0,
            gamma=config.gamma,
            seed=config.seed,
            device="cpu",
            policy_kwargs={"net_arch": arch, "log_std_init": config.log_std_init},
        )
        layer = cast(torch.nn.Linear, model.actor.mu)
        log_std = cast(torch.nn.Linear, model.actor.log_std)
        with torch.no_grad():  # state-independent initial noise exp(log_std_init)
            log_std.weight.zero_()
            log_std.bias.fill_(config.log_std_init)
    with torch.no_grad():
        layer.weight.zero_()
        layer.bias.zero_()
    return model


def planned_timesteps(config: TrainConfig, num_envs: int) -> int:
    """Vessel-steps a run of ``config.timesteps`` really trains: SB3 completes whole rollouts.

    PPO collects ``n_steps x num_envs`` vessel-steps per rollout, SAC ``num_envs``
    per vector-env step, so the budget is rounded up to a multiple of that.
    """
    per_call = config.n_steps * num_envs if config.algo == "ppo" else num_envs
    return -(-config.timesteps // per_call) * per_call


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
) -> Path:
    """Train an agent into the run folder ``out`` (see the module docstring).

    Args:
        config: The run.
        out: Output folder (created).
        progress: Show a progress bar (with the latest evaluation cost) and say how the
            budget was rounded.
        overwrite: Delete a run already in ``out`` first.
        callbacks: More SB3 callbacks (a sweep's reporting to Ray Tune, say).
        evaluate: Agent folder -> mean cost per scenario on held-out seeds (``cpf-train``
            passes the benchmark's ``test`` split); None: no evaluation.
        schedule: Evaluation and checkpoint periods (default: neither).
        resume: Continue the run in ``out`` from its last checkpoint; ``config`` must be
            the run's own (``run.json``) but for a larger ``timesteps``.
        tensorboard_log: Also write TensorBoard event files to ``tensorboard_log/<out name>``.
        run_files: File name -> text, written into ``out`` when the run (or its resumed
            part) starts (``cpf-train`` saves its resolved ``hyperparameters.toml`` so).

    Returns:
        The output folder.

    Raises:
        FileExistsError: ``out`` holds files and neither ``overwrite`` nor ``resume``.
        ValueError: ``out`` is empty or a file, a held-out evaluation scenario or seed
            (``splits.check_training``), nothing to resume, or a configuration that
            differs from the run's own.
        TrainingInterrupted: Ctrl-C; the checkpoint and the agent so far are written.
        cpf_env.infra.atomic.FolderLockedError: Another run is writing ``out``.
    """
    from agents.run_folder import TrainingRun, prepare_resume, write_run_record

    for name in config.scenarios:
        check_training(name, range(config.seed, config.seed + config.fleets))
    folder = _output_folder(out)
    schedule = schedule or RunSchedule()
    if tensorboard_log is not None:
        try:
            import tensorboard  # noqa: F401
        except ImportError as error:
            raise ValueError(
                "--tensorboard-log needs tensorboard: pip install 'cpf_env[rl]'."
            ) from error
    with atomic.FolderLock(folder, "another training run"):
        if resume:
            resume_state = prepare_resume(folder, config)
            write_run_record(folder, config, schedule, getattr(evaluate, "settings", None))
        else:
            if folder.exists() and any(folder.iterdir()):
                if not overwrite:
                    held = "a trained model" if (folder / "config.json").exists() else "files"
                    raise FileExistsError(
                        f"{folder} already holds {held}; choose another output folder, "
                        "overwrite it (cpf-train --force, train(..., overwrite=True)) or "
                        "continue it (cpf-train --resume)."
                    )
                shutil.rmtree(folder)
            folder.mkdir(parents=True, exist_ok=True)
            write_run_record(folder, config, schedule, getattr(evaluate, "settings", None))
            resume_state = None
        for name, text in (run_files or {}).items():
            atomic.write_text(folder / name, text)
        TrainingRun(config, folder, schedule, evaluate, resume_state, tensorboard_log).learn(
            progress, callbacks
        )
    return folder


def _output_folder(out: str | Path) -> Path:
    """``out`` as a folder path, refusing an empty one and an existing file."""
    if not str(out).strip():
        raise ValueError("the output folder is empty; give one (cpf-train --out DIR).")
    folder = Path(out)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{folder} is a file; give a folder for the trained agent.")
    return folder
