"""``TrainConfig``: everything that defines a training run, checked before anything runs.

``cpf-train`` builds it from its defaults, a hyperparameter file and the
command line; ``agents.training.trainer.train`` runs it; every agent folder keeps it
in ``config.json``, from which ``agents.load_policy`` rebuilds the learner's
input and base policy.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from agents.envs.history import history_size
from baselines import DEPLOYABLE
from cpf_env import scenarios
from cpf_env.envs.residual import EXTRAS, ResidualConfig, learner_config
from cpf_env.scenarios.reward_weights import REWARD_FORMS
from cpf_env.sim.fleet import observation_layout
from cpf_env.sim.observation import SLOTS

__all__ = [
    "ALGORITHM_NAMES",
    "ENCODERS",
    "FLAT_RESIDUAL_FIELDS",
    "INIT_LOG_STD",
    "LOG_STD_RANGE",
    "MAX_SEED",
    "TrainConfig",
    "config_from_record",
    "upgrade_record",
]

#: Algorithms ``agents.training.trainer.ALGORITHMS`` maps to SB3 classes.
ALGORITHM_NAMES = ("ppo", "sac")
#: Neighbour encoders of the actor (``agents.folder.encoder``); None: an MLP over the flat input.
ENCODERS = ("deepsets",)
#: ``ResidualConfig`` fields that records before agent-folder format 3 held at the top level.
FLAT_RESIDUAL_FIELDS = (
    "mode",
    "scale",
    "extras",
    "hide_residual_from_base",
    "neighbour_slots",
    "yield_at_limit",
)
#: Largest training seed: numpy's legacy seeding, which SB3 calls, takes 32 bits.
MAX_SEED = 2**32 - 1
#: Accepted initial log standard deviations: exp(-20) is no noise, exp(5) = 148 already
#: saturates every action; outside, the Gaussian's density under- or overflows.
LOG_STD_RANGE = (-20.0, 5.0)
#: Initial log standard deviation of a run started from an agent folder
#: (``agents.training.init_from``; ``cpf-train --init-from`` unless one is given): 0.08 of the
#: residual range, small enough to keep the folder's behaviour (default -1: 0.37).
INIT_LOG_STD = -2.5


def _is_real(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run (saved as ``config.json``).

    Attributes:
        algo: ``"ppo"`` or ``"sac"``.
        scenario: A registered scenario name, or several (a tuple): a mixture, one
            group of fleets per scenario (``agents.envs.mixture_env``). The first is the
            agent's default evaluation scenario (``home_scenario``).
        base_policy: A name of ``baselines.DEPLOYABLE``, or ``"none"``: the agent commands
            forces and path-variable rate itself (learning from scratch).
        residual: How the learner's action enters (``cpf_env.envs.residual.ResidualConfig``:
            ``mode``, ``scale``, ``kinematic_scale``, ``extras``,
            ``hide_residual_from_base``, ``neighbour_slots``, ``yield_at_limit``,
            ``messages``), or a
            mapping of those fields (a TOML ``[residual]`` table). In a mixture, its
            ``neighbour_slots`` left None become the largest degree of the training
            scenarios, so the agent runs on every one of them.
        fleets: Fleets simulated together (num_envs = fleets x n).
        timesteps: Training budget in vessel-steps (SB3 timesteps).
        seed: Seeds the networks (torch), SB3 and the fleets (fleet k: seed + k).
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
        reward_overrides: ``RewardWeights`` fields changed for training only (e.g.
            ``{"heading": 1.0}``), applied after ``reward_form``; the benchmark's
            cost stays the scenario's own reward.
        balance_rewards: In a mixture, divide each scenario's rewards by its running
            mean cost per step (``agents.envs.mixture_env.BalancedRewards``), so no scenario
            steers the updates by the size of its cost alone. Ignored for one scenario.
        shared_slot_statistics: Normalize every neighbour slot with the same pooled
            statistics (``agents.envs.slot_statistics``) instead of per-position ones.
        encoder: ``"deepsets"``: the actor reads the neighbour slots through a
            ``NeighbourSetEncoder`` (PPO only; with ``normalize_observations`` it
            needs ``shared_slot_statistics``), so the agent runs on any number of
            slots; None: an MLP over the flat input of K slots.
        history: Own-history entries appended to the learner's input
            (``agents.envs.history_env.HistoryVecEnv`` in training, kept by the loaded policy
            in evaluation); 0: none.
        asymmetric_critic: PPO's critic also reads what no vessel observes
            (``cpf_env.evaluation.privileged.unobserved_state``: the true lumped force,
            v0, the vessel's offset from the fleet's mean path variable), the actor
            only the local input (``agents.training.algorithms.AsymmetricActorCriticPolicy``);
            the agent folder holds the actor, as for any run (PPO only).
    """

    algo: str = "ppo"
    scenario: str | tuple[str, ...] = "wang2014"
    base_policy: str = "nn_dsc"
    residual: ResidualConfig = dataclasses.field(default_factory=ResidualConfig)
    fleets: int = 256
    timesteps: int = 2_000_000
    seed: int = 0
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
    reward_overrides: dict[str, float] = dataclasses.field(default_factory=dict)
    balance_rewards: bool = True
    shared_slot_statistics: bool = False
    encoder: str | None = None
    history: int = 0
    asymmetric_critic: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "net_arch", tuple(int(x) for x in self.net_arch))
        if self.algo not in ALGORITHM_NAMES:
            raise ValueError(f"algo must be one of {sorted(ALGORITHM_NAMES)}, got {self.algo!r}.")
        object.__setattr__(self, "scenario", _scenario_field(self.scenario))
        object.__setattr__(self, "reward_overrides", dict(self.reward_overrides))
        residual = _residual_field(self.residual)
        if residual.neighbour_slots is None and len(self.scenarios) > 1:
            degrees = [observation_layout(scenarios.get(n)).n_slots for n in self.scenarios]
            residual = dataclasses.replace(residual, neighbour_slots=max(degrees))
        object.__setattr__(self, "residual", residual)
        if self.base_policy != "none" and self.base_policy not in DEPLOYABLE:
            raise ValueError(
                f"base_policy must be one of {sorted(DEPLOYABLE)} or 'none' (learn from "
                f"scratch), got {self.base_policy!r}."
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
            "normalize_observations",
            "balance_rewards",
            "shared_slot_statistics",
            "asymmetric_critic",
        )
        for name in flags:
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}.")
        self._check_actor()
        for name in self.scenarios:
            self.scenario_overrides(name)  # validates the reward overrides

    def _check_actor(self) -> None:
        """Validate ``encoder`` and ``history`` (and what the encoder needs)."""
        if self.encoder is not None and self.encoder not in ENCODERS:
            raise ValueError(
                f"encoder must be one of {list(ENCODERS)} or None (an MLP), got {self.encoder!r}."
            )
        if isinstance(self.history, bool) or not isinstance(self.history, int) or self.history < 0:
            raise ValueError(
                f"history must be an integer >= 0 (own-history entries; 0: none), got "
                f"{self.history!r}."
            )
        if self.asymmetric_critic and self.algo != "ppo":
            raise ValueError(
                "asymmetric_critic is implemented for PPO (an actor-critic with separate "
                f"inputs); use algo='ppo' or asymmetric_critic=false, got algo={self.algo!r}."
            )
        if self.encoder is None:
            return
        if self.algo != "ppo":
            raise ValueError(
                f"encoder={self.encoder!r} is implemented for PPO; use algo='ppo' or no encoder."
            )
        if self.normalize_observations and not self.shared_slot_statistics:
            raise ValueError(
                f"encoder={self.encoder!r} runs one set of weights on every slot, so the slots "
                "need one set of statistics: set shared_slot_statistics=true "
                "(--set shared_slot_statistics=true), or normalize_observations=false."
            )

    @property
    def scenarios(self) -> tuple[str, ...]:
        """The training scenarios (one, or the mixture)."""
        return (self.scenario,) if isinstance(self.scenario, str) else self.scenario

    @property
    def home_scenario(self) -> str:
        """The default evaluation scenario: the first training scenario."""
        return self.scenarios[0]

    def learner_config(self) -> ResidualConfig:
        """The learner's composition: ``residual``, or the learner's own without a base.

        ``base_policy="none"``: ``cpf_env.envs.residual.learner_config``'s (forces and rate,
        no extras).
        """
        return learner_config(None, self.residual) if self.base_policy == "none" else self.residual

    def learner_slots(self) -> tuple[int, int]:
        """(K, floats per slot) of the learner's input: its neighbour slots' layout.

        Raises:
            ValueError: The home scenario's degree exceeds ``neighbour_slots``.
        """
        layout = self.residual.learner_layout(observation_layout(scenarios.get(self.home_scenario)))
        return layout.n_slots, layout.slot_size

    def learner_tail(self) -> int:
        """Floats after the neighbour slots of the learner's input, per vessel.

        The extras (``cpf_env.envs.residual.EXTRAS``), then the own history
        (``agents.envs.history.history_size``: H x (18 + a + 1), a the learner's action size).
        """
        learner = self.learner_config()
        extras = sum(EXTRAS[name] for name in learner.extras)
        return extras + history_size(self.history, learner.action_size)

    def learner_input_size(self) -> int:
        """The learner's input length per vessel in training: 18 + K (3 + m) + ``learner_tail()``.

        Raises:
            ValueError: The home scenario's degree exceeds ``neighbour_slots``.
        """
        slots, slot_size = self.learner_slots()
        return SLOTS + slots * slot_size + self.learner_tail()

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
        """A JSON-ready dict of every field, ``residual`` as an object of its fields."""
        record = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        record["residual"] = dataclasses.asdict(self.residual)
        return record

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of ``to_json``: absent fields take their defaults; unknown keys: ValueError.

        Records written before agent-folder format 3 go through ``upgrade_record`` first.
        """
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown TrainConfig field(s) {unknown}; valid: {sorted(names)}.")
        return cls(**data)


def upgrade_record(data: dict[str, Any]) -> dict[str, Any]:
    """A ``TrainConfig`` record written before agent-folder format 3, in today's layout.

    Those records (``config.json`` of format 1 and 2 folders, ``run.json`` of their
    runs) name the base policy ``base`` and hold the ``ResidualConfig`` fields at the
    top level; today's hold ``base_policy`` and a ``residual`` object. Other fields
    pass through unchanged, so ``from_json`` still refuses an unknown one.
    """
    moved = ("base", *FLAT_RESIDUAL_FIELDS)
    record = {key: value for key, value in data.items() if key not in moved}
    if "base" in data:
        record["base_policy"] = data["base"]
    residual = {key: data[key] for key in FLAT_RESIDUAL_FIELDS if key in data}
    if residual:
        record["residual"] = residual
    return record


def config_from_record(data: dict[str, Any]) -> TrainConfig:
    """The ``TrainConfig`` of a run record (``run.json``'s ``config``) of any version.

    A record written before agent-folder format 3 always holds ``base``, today's never:
    such a record goes through ``upgrade_record`` first.
    """
    return TrainConfig.from_json(upgrade_record(data) if "base" in data else data)


def _residual_field(value: Any) -> ResidualConfig:
    """``TrainConfig.residual`` checked: a ``ResidualConfig``, or a mapping of its fields."""
    if isinstance(value, ResidualConfig):
        return value
    if not isinstance(value, dict):
        raise ValueError(
            f"residual must be a ResidualConfig or a table of its fields, got {value!r}."
        )
    names = [f.name for f in dataclasses.fields(ResidualConfig)]
    unknown = sorted(set(value) - set(names))
    if unknown:
        raise ValueError(f"residual has unknown field(s) {unknown}; valid: {names}.")
    return ResidualConfig(**value)


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
