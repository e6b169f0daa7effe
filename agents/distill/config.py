"""The settings of ``agents.distill.dagger``: the teacher, the data, the budget, the report.

``DistillConfig`` holds what ``distill`` is asked for (the teacher, rounds,
steps, epochs, the procedural fleets and their ``ScenarioDistribution``, the
label base, the loss), validated at construction; ``check_distillation``
refuses a ``TrainConfig`` and ``DistillConfig`` pair that ``distill`` cannot
run, before anything runs; ``draw_seeds`` gives each DAgger round's
procedural draws; ``DistillReport`` is what a run returns. ``cpf-distill``
reads the ``[distill]`` table of its TOML into a ``DistillConfig``.

Which base the label is taken on (``DistillConfig.label_base``). By default
(``"env"``) it is the env's base, which is shown the applied force minus the
residual (``hide_residual_from_base``): a base with a residual-force observer
(``mpc``, ``mpc_tuned``) takes the student's residual for a disturbance and
cancels it, so tau_base already holds minus the observer's copy of the
residual and the label a* holds it back plus the teacher's correction. A steady residual
of the student then labels itself: nothing in the data pulls it to zero, and
what the student holds there is arbitrary (seen as a jump of its output
wherever its inputs jump, e.g. when the graph switches). With ``"twin"`` the
label is taken on a twin of the env's base: a copy of it, seeded and reset
as the env seeds and resets it, that acts on the same observations with the
whole applied force shown (the base as ``hide_residual_from_base = false``
runs it). With no residual the twin commands what the env's base does, bit
for bit; with one, the label is the teacher's correction alone, and a
residual the teacher does not ask for is labelled zero. The rollouts, the
plant and the applied bounds stay the env's base's: the student is deployed
on it unchanged. Only the observer bases (``agents.envs.fleetwise.WHOLE_BATCH_BASES``)
take it: ``nn_dsc``'s auxiliary system, shown the whole force, would take
the residual for saturation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.envs.fleetwise import WHOLE_BATCH_BASES
from agents.training.config import TrainConfig
from baselines import ALL_POLICIES
from cpf_env.scenarios.sampler import ScenarioDistribution
from cpf_env.scenarios.splits import EVALUATION_SEED, check_training

__all__ = [
    "LABEL_BASES",
    "LABEL_MODES",
    "TEACHERS",
    "DistillConfig",
    "DistillReport",
    "check_distillation",
    "draw_seeds",
]

#: Residual modes a student can be distilled in (the teacher's command maps onto them).
LABEL_MODES = ("force", "force_and_rate")


#: Names a teacher may have: every policy of ``baselines`` (deployable or privileged).
TEACHERS = tuple(sorted(ALL_POLICIES))
#: The base a label is taken on (``DistillConfig.label_base``).
LABEL_BASES = ("env", "twin")


@dataclass(frozen=True)
class DistillConfig:
    """The teacher, the data and the DAgger budget.

    Attributes:
        teacher: A policy name of ``TEACHERS`` (deployable or privileged).
        rounds: DAgger rounds (round 0 is behaviour cloning on the teacher's rollouts).
        steps: Vector-env steps per round (samples: steps x fleets x n per round).
        epochs: Passes over the aggregated data after each round.
        batch_size: Samples per gradient step.
        learning_rate: Adam step size.
        procedural: Procedural training fleets added to the scenarios, draws
            0 .. procedural - 1 of ``ScenarioDistribution(max_degree=K)`` (K: the
            student's neighbour slots); 0 for none. Each takes one group of fleets.
        redraw: Draw fresh procedural fleets every round (``draw_seeds``: round r
            takes draws r x procedural .. (r + 1) x procedural - 1, all below
            ``splits.EVALUATION_SEED``); their episodes start at the round's start.
            False: the same draws throughout, their episodes continuing.
        fit_applied: Fit the force the plant applies (one-sided where the label sits
            at an actuator limit; see the module's docstring). False: the squared
            error on the clipped residual everywhere.
        distribution: ``ScenarioDistribution`` fields the procedural fleets are drawn
            with, over its defaults (a ``[distill.distribution]`` table, ranges as
            two-element lists), e.g. ``{"v0": (0.05, 0.6), "force_scale": (0.4, 1.0)}``
            for leaders up to 0.6 m/s and force limits down to 0.4 of nominal.
            ``max_degree`` (the student's slots) and ``name`` are not settable.
            Empty: the defaults.
        label_base: The base the teacher's command is turned into a residual on
            (``LABEL_BASES``): ``"env"``, the env's base; ``"twin"``, a copy of it
            shown the whole applied force (see the module's docstring; needs an
            observer base, ``mpc`` or ``mpc_tuned``, that hides the residual).
    """

    teacher: str = "nn_dsc_privileged"
    rounds: int = 3
    steps: int = 500
    epochs: int = 10
    batch_size: int = 4096
    learning_rate: float = 1e-3
    procedural: int = 0
    redraw: bool = False
    fit_applied: bool = False
    distribution: Mapping[str, Any] = field(default_factory=dict)
    label_base: str = "env"

    def __post_init__(self) -> None:
        if self.teacher not in TEACHERS:
            raise ValueError(
                f"teacher must be a policy of baselines (deployable or privileged), one of "
                f"{list(TEACHERS)}; got {self.teacher!r}."
            )
        for name in ("rounds", "steps", "epochs", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"DistillConfig.{name} must be an integer >= 1, got {value!r}.")
        if (
            isinstance(self.procedural, bool)
            or not isinstance(self.procedural, int)
            or self.procedural < 0
        ):
            raise ValueError(
                f"DistillConfig.procedural must be an integer >= 0 (procedural training fleets), "
                f"got {self.procedural!r}."
            )
        for name in ("redraw", "fit_applied"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(
                    f"DistillConfig.{name} must be true or false, got {getattr(self, name)!r}."
                )
        if self.label_base not in LABEL_BASES:
            raise ValueError(
                f"DistillConfig.label_base must be one of {list(LABEL_BASES)}, "
                f"got {self.label_base!r}."
            )
        if self.redraw and self.procedural == 0:
            raise ValueError(
                "DistillConfig.redraw draws fresh procedural fleets each round; set "
                "procedural >= 1 (fleets per round) or leave redraw out."
            )
        object.__setattr__(self, "distribution", _distribution_fields(self.distribution))
        if self.distribution and self.procedural == 0:
            raise ValueError(
                "DistillConfig.distribution shapes the procedural fleets; set procedural >= 1 "
                "(fleets per round) or leave distribution out."
            )
        if not (
            isinstance(self.learning_rate, int | float)
            and not isinstance(self.learning_rate, bool)
            and self.learning_rate > 0.0
        ):
            raise ValueError(f"learning_rate must be a number > 0, got {self.learning_rate!r}.")


@dataclass(frozen=True)
class DistillReport:
    """What a distillation did.

    Attributes:
        folder: The agent folder written.
        samples: Labelled vessel-steps in the final data set.
        losses: The student's loss on all data after each round: the mean squared
            error, or with ``fit_applied`` the applied-force loss (``_loss``).
        zero_loss: The same loss of the base alone (a = 0) on the final data.
        clipped: Fraction of the labels' components clipped to [-1, 1].
        at_limit: Fraction of the force labels' components at a bound of the applied
            residual (an actuator limit or the residual's reach), on the final data.
        seconds: Wall time (s).
        rounds: Per round: ``round``, ``samples`` (data so far), ``loss``,
            ``zero_loss``, ``clipped`` and ``at_limit`` (on the data so far), ``seconds``
            (since start, evaluations included).
        draws: Per round, the procedural draw seeds its rollouts ran (``draw_seeds``).
        device: The torch device the student was fitted on.
        evaluations: The rows of ``evaluations.csv`` (``agents.training.schedule.EvaluationLog``):
            the student before round 0 (its output is zero: the base policy) and after
            each round, at the labelled vessel-steps so far; empty without an evaluator.
    """

    folder: Path
    samples: int
    losses: tuple[float, ...]
    zero_loss: float
    clipped: float
    at_limit: float
    seconds: float
    rounds: tuple[dict[str, float], ...]
    draws: tuple[tuple[int, ...], ...]
    device: str
    evaluations: tuple[dict[str, float], ...]


def check_distillation(config: TrainConfig, settings: DistillConfig) -> None:
    """Refuse what ``distill`` cannot do, before anything runs (see ``distill``)."""
    for name in config.scenarios:
        check_training(name, range(config.seed, config.seed + config.fleets))
    mode = config.residual.mode
    if mode not in LABEL_MODES or config.algo != "ppo" or not config.normalize_observations:
        raise ValueError(
            "distill needs a force or force_and_rate residual (or base_policy='none') with the "
            f"PPO actor format and normalized inputs (residual.mode in {list(LABEL_MODES)}, "
            f"algo='ppo', normalize_observations); got residual.mode={mode!r}, "
            f"algo={config.algo!r}, "
            f"normalize_observations={config.normalize_observations}."
        )
    if config.residual.messages:
        raise ValueError(
            f"distill fits a student to its teacher's forces, and no teacher writes learned "
            f"messages: residual.messages = {config.residual.messages} has no labels. Learn "
            "messages with a reinforcement learner (cpf-train, or MAPPO on the BenchMARL "
            "route), or leave residual.messages out."
        )
    groups = len(config.scenarios) + settings.procedural
    if config.fleets < groups:
        raise ValueError(
            f"distill over {groups} scenarios (training scenarios and procedural draws) needs "
            f"at least one fleet each; got fleets={config.fleets}. Raise fleets."
        )
    if settings.label_base == "twin" and (
        config.base_policy not in WHOLE_BATCH_BASES or not config.residual.hide_residual_from_base
    ):
        raise ValueError(
            'label_base = "twin" takes the labels on a copy of the base shown the whole '
            "applied force: it is for a base with a residual-force observer "
            f"({', '.join(WHOLE_BATCH_BASES)}) that hides the residual "
            "(residual.hide_residual_from_base = true, the default); this run has "
            f'base_policy = "{config.base_policy}", residual.hide_residual_from_base = '
            f"{str(config.residual.hide_residual_from_base).lower()}. "
            'Leave label_base out (it defaults to "env") or change those settings.'
        )
    draws = settings.procedural * (settings.rounds if settings.redraw else 1)
    if draws > EVALUATION_SEED:
        raise ValueError(
            f"redraw with procedural={settings.procedural} over {settings.rounds} rounds draws "
            f"seeds 0 .. {draws - 1}, but training draws must stay below {EVALUATION_SEED} "
            "(held-out fleets are drawn above it); lower rounds or procedural."
        )


def draw_seeds(settings: DistillConfig, round_: int) -> list[int]:
    """The procedural draw seeds of DAgger round ``round_``.

    ``0 .. P - 1`` (P = ``procedural``) in every round, or with ``redraw`` the
    round's own: ``round_ x P .. round_ x P + P - 1``.
    """
    first = round_ * settings.procedural if settings.redraw else 0
    return list(range(first, first + settings.procedural))


def _distribution_fields(fields: Mapping[str, Any]) -> dict[str, Any]:
    """``DistillConfig.distribution`` checked, with its lists as tuples.

    Raises:
        ValueError: Not a table, a key that is not a settable ``ScenarioDistribution``
            field (the settable ones are listed), or values it refuses.
    """
    if not isinstance(fields, Mapping):
        raise ValueError(
            f"DistillConfig.distribution must be a table of ScenarioDistribution fields, "
            f"got {fields!r}."
        )
    settable = sorted(
        {f.name for f in dataclasses.fields(ScenarioDistribution)} - {"max_degree", "name"}
    )
    unknown = sorted(set(fields) - set(settable))
    if unknown:
        raise ValueError(
            f"DistillConfig.distribution has unknown keys {unknown}; settable "
            f"ScenarioDistribution fields: {settable} (max_degree follows the student's "
            "neighbour slots)."
        )
    values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()}
    try:
        ScenarioDistribution(**values)
    except (TypeError, ValueError) as error:
        raise ValueError(f"DistillConfig.distribution: {error}") from None
    return values
