"""Training residual (or from-scratch) agents with Stable-Baselines3 on ``FleetVecEnv``.

``train(config, out)`` builds ``FleetVecEnv`` -> ``VecMonitor`` -> ``VecNormalize``
(observations only; rewards stay in their units so episode costs read as the
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

import dataclasses
import math
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from agents.mixture_env import MixtureVecEnv
from agents.schedule import Evaluator, RunSchedule
from agents.vec_env import FleetVecEnv
from baselines import POLICIES
from cpf_env import atomic, scenarios
from cpf_env.envs.residual import ResidualConfig
from cpf_env.scenarios.reward_weights import REWARD_FORMS
from cpf_env.scenarios.splits import check_training
from cpf_env.sim.fleet import observation_layout

__all__ = ["ALGORITHMS", "TrainConfig", "build_model", "make_env", "train"]

#: Largest training seed: numpy's legacy seeding, which SB3 calls, takes 32 bits.
MAX_SEED = 2**32 - 1
#: Accepted initial log standard deviations: exp(-20) is no noise, exp(5) = 148 already
#: saturates every action; outside, the Gaussian's density under- or overflows.
LOG_STD_RANGE = (-20.0, 5.0)

#: SB3 algorithms by name.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC}


def _is_real(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run (saved as ``config.json``).

    Attributes:
        algo: ``"ppo"`` or ``"sac"``.
        scenario: A registered scenario name, or several (a tuple): a mixture, one
            group of fleets per scenario (``agents.mixture_env``). The first is the
            agent's default evaluation scenario (``home_scenario``).
        base: A name of ``baselines.POLICIES``, or ``"none"``: the agent commands
            forces and path-variable rate itself (learning from scratch).
        fleets: Fleets simulated together (num_envs = fleets x n).
        timesteps: Training budget in vessel-steps (SB3 timesteps).
        seed: Seeds the networks (torch), SB3 and the fleets (fleet k: seed + k).
        mode: Residual mode (``cpf_env.envs.residual.RESIDUAL_MODES``).
        scale: Residual range as a fraction of the limits.
        extras: Local extras appended to the observation (``cpf_env.envs.residual.EXTRAS``).
        hide_residual_from_base: Show the base the applied force minus the residual.
        reward_form: ``"log"`` or ``"quadratic"`` to override the scenario's
            reward form, or None to keep it.
        normalize_observations: Wrap in ``VecNormalize`` (observations only).
        log_std_init: Initial log standard deviation of the exploration noise.
        learning_rate: Adam step size.
        gamma: Discount per control step.
        net_arch: Hidden layer sizes of policy and value networks.
        n_steps: PPO rollout length per slot.
        batch_size: Minibatch size (PPO: at most one rollout, n_steps x num_envs).
        n_epochs: PPO epochs per rollout.
        gradient_steps: SAC gradient steps per vector-env step.
        buffer_size: SAC replay buffer size (transitions).
        torch_threads: Threads torch may use; None keeps torch's default (all cores).
            On a quiet 2-core machine 2 threads ran PPO 1.4x faster than 1; on a
            machine shared with other jobs 1 thread was faster.
        neighbour_slots: Neighbour slots of the learner's input (``ResidualConfig``);
            None: the largest degree of the training scenarios. An agent with K slots
            runs on every scenario whose graph has degree <= K.
        reward_overrides: ``RewardWeights`` fields changed for training only (e.g.
            ``{"heading": 1.0}``), applied after ``reward_form``; the benchmark's
            cost stays the scenario's own reward.
        balance_rewards: In a mixture, divide each scenario's rewards by its running
            mean cost per step (``agents.mixture_env.BalancedRewards``), so no scenario
            steers the updates by the size of its cost alone. Ignored for one scenario.
        shared_slot_statistics: Normalize every neighbour slot with the same pooled
            statistics (``agents.slot_statistics``) instead of per-position ones.
    """

    algo: str = "ppo"
    scenario: str | tuple[str, ...] = "wang2014"
    base: str = "nn_dsc"
    fleets: int = 256
    timesteps: int = 2_000_000
    seed: int = 0
    mode: str = "force"
    scale: float = 0.2
    extras: tuple[str, ...] = ()
    hide_residual_from_base: bool = True
    reward_form: str | None = None
    normalize_observations: bool = True
    log_std_init: float = -1.0
    learning_rate: float = 3e-4
    gamma: float = 0.99
    net_arch: tuple[int, ...] = (64, 64)
    n_steps: int = 32
    batch_size: int = 8192
    n_epochs: int = 4
    gradient_steps: int = 4
    buffer_size: int = 1_000_000
    torch_threads: int | None = None
    neighbour_slots: int | None = None
    reward_overrides: dict[str, float] = dataclasses.field(default_factory=dict)
    balance_rewards: bool = True
    shared_slot_statistics: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "extras", tuple(self.extras))
        object.__setattr__(self, "net_arch", tuple(int(x) for x in self.net_arch))
        if self.algo not in ALGORITHMS:
            raise ValueError(f"algo must be one of {sorted(ALGORITHMS)}, got {self.algo!r}.")
        object.__setattr__(self, "scenario", _scenario_field(self.scenario))
        object.__setattr__(self, "reward_overrides", dict(self.reward_overrides))
        if self.neighbour_slots is None and len(self.scenarios) > 1:
            degrees = [observation_layout(scenarios.get(n)).n_slots for n in self.scenarios]
            object.__setattr__(self, "neighbour_slots", max(degrees))
        if self.base != "none" and self.base not in POLICIES:
            raise ValueError(
                f"base must be one of {sorted(POLICIES)} or 'none' (learn from scratch), "
                f"got {self.base!r}."
            )
        if self.reward_form is not None and self.reward_form not in REWARD_FORMS:
            raise ValueError(
                f"reward_form must be one of {REWARD_FORMS} or None, got {self.reward_form!r}."
            )
        integers = (
            "fleets",
            "timesteps",
            "n_steps",
            "batch_size",
            "n_epochs",
            "gradient_steps",
            "buffer_size",
        )
        for name in integers if self.torch_threads is None else (*integers, "torch_threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}.")
        if (
            isinstance(self.seed, bool)
            or not isinstance(self.seed, int)
            or not 0 <= self.seed <= MAX_SEED
        ):
            raise ValueError(
                f"seed must be an integer in [0, 2**32 - 1] (numpy's and SB3's seed range), "
                f"got {self.seed!r}."
            )
        if not self.net_arch or min(self.net_arch) < 1:
            raise ValueError(f"net_arch must list layer sizes >= 1, got {list(self.net_arch)}.")
        if not (_is_real(self.learning_rate) and self.learning_rate > 0):
            raise ValueError(f"learning_rate must be a number > 0, got {self.learning_rate!r}.")
        if not (_is_real(self.gamma) and 0 < self.gamma <= 1):
            raise ValueError(f"gamma must be in (0, 1], got {self.gamma!r}.")
        if not (
            _is_real(self.log_std_init)
            and LOG_STD_RANGE[0] <= self.log_std_init <= LOG_STD_RANGE[1]
        ):
            raise ValueError(
                f"log_std_init must be a number in [{LOG_STD_RANGE[0]}, {LOG_STD_RANGE[1]}] "
                f"(a standard deviation of exp(log_std_init) actions of range 1), got "
                f"{self.log_std_init!r}."
            )
        flags = (
            "hide_residual_from_base",
            "normalize_observations",
            "balance_rewards",
            "shared_slot_statistics",
        )
        for name in flags:
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}.")
        if self.base != "none":
            self.residual_config()  # validates mode, scale, extras and neighbour slots
        for name in self.scenarios:
            self.scenario_overrides(name)  # validates the reward overrides

    @property
    def scenarios(self) -> tuple[str, ...]:
        """The training scenarios (one, or the mixture)."""
        return (self.scenario,) if isinstance(self.scenario, str) else self.scenario

    @property
    def home_scenario(self) -> str:
        """The default evaluation scenario: the first training scenario."""
        return self.scenarios[0]

    def residual_config(self) -> ResidualConfig:
        """The ``ResidualConfig`` of this run."""
        return ResidualConfig(
            mode=self.mode,
            scale=self.scale,
            extras=self.extras,
            hide_residual_from_base=self.hide_residual_from_base,
            neighbour_slots=self.neighbour_slots,
        )

    def learner_slots(self) -> tuple[int, int]:
        """(K, floats per slot) of the learner's input: its neighbour slots' layout."""
        layout = self.residual_config().learner_layout(
            observation_layout(scenarios.get(self.home_scenario))
        )
        return layout.n_slots, layout.slot_size

    def scenario_overrides(self, name: str | None = None) -> dict[str, Any]:
        """``Scenario`` overrides of this run for one training scenario (default: the home one).

        The reward form and the reward overrides, if any.

        Raises:
            ValueError: A reward override names no ``RewardWeights`` field or has a bad value.
        """
        if self.reward_form is None and not self.reward_overrides:
            return {}
        reward = scenarios.get(self.home_scenario if name is None else name).reward
        if self.reward_form is not None:
            reward = dataclasses.replace(reward, form=self.reward_form)
        fields = {f.name for f in dataclasses.fields(reward)} - {"form", "team"}
        unknown = sorted(set(self.reward_overrides) - fields)
        if unknown:
            raise ValueError(
                f"reward_overrides names unknown reward field(s) {unknown}; valid: "
                f"{sorted(fields)}."
            )
        return {"reward": dataclasses.replace(reward, **self.reward_overrides)}  # type: ignore[arg-type]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict of the fields."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of ``to_json``; unknown keys raise ValueError."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown TrainConfig field(s) {unknown}; valid: {sorted(names)}.")
        return cls(**data)


def _scenario_field(value: Any) -> str | tuple[str, ...]:
    """``TrainConfig.scenario`` checked: a registered name, or a tuple of distinct ones."""
    names = [value] if isinstance(value, str) else list(value)
    known = scenarios.list_scenarios()
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ValueError(f"unknown scenario {unknown[0]!r}; choose one of {known}.")
    if not names or len(set(names)) != len(names):
        raise ValueError(
            f"scenario must be a registered name or distinct names (a mixture), got {value!r}."
        )
    return names[0] if len(names) == 1 else tuple(names)


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
        model: BaseAlgorithm = PPO(
            "MlpPolicy",
            env,
            learning_rate=config.learning_rate,
            n_steps=config.n_steps,
            batch_size=min(config.batch_size, config.n_steps * env.num_envs),  # <= one rollout
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
        cpf_env.atomic.FolderLockedError: Another run is writing ``out``.
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
