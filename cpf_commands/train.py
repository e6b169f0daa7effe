"""``cpf-train``: train a residual (or from-scratch) agent with Stable-Baselines3.

Familiar to RL Baselines3 Zoo users: ``--algo``, ``--scenario`` (the env),
``--seed``, ``--timesteps`` (``-n``), an output folder with the network's
weights (safetensors), the normalization statistics and the exact
configuration (JSON), tied by a manifest of hashes (``agents.folder.format``). The folder loads
with ``agents.load_policy(DIR)`` and is accepted wherever a policy name is
(``cpf-bench --policies nn_dsc DIR``, ``cpf-run --policy DIR``).

RL Zoo conventions too (``docs/residual_rl.md``, "A training run"): held-out
evaluation on the validation seeds (``cpf_env.scenarios.splits.VALIDATION_SEED``,
never the benchmark's) with the best agent kept
(``--eval-every``, ``--eval-num-seeds``; ``agents.training.evaluation``),
checkpoints and ``--resume`` (``checkpoint_every``), a checkpoint and agent
on Ctrl-C, ``--tensorboard-log DIR``, and ``--config FILE.toml``
(``cpf_commands.hyperparameters``; ``--set KEY=VALUE`` sets any other hyperparameter;
``--set`` and the flags given override the file).

Example::

    cpf-train --scenarios bench_lossy_links --seed 0 --out runs/ppo_lossy_s0
    cpf-train --config base.toml --set n_epochs=5 "net_arch=[64, 64]" --out runs/wide
    cpf-train --resume --out runs/ppo_lossy_s0 -n 4000000   # continue, or extend
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from cpf_commands.common.arguments import non_negative_int, positive_int
from cpf_commands.common.extras import missing_extra
from cpf_commands.hyperparameters import (
    SCHEDULE_KEYS,
    hyperparameters_toml,
    merge_settings,
    parse_settings,
    read_hyperparameters,
)
from cpf_env import scenarios
from cpf_env.scenarios.splits import SHIFT_SUFFIX, check_training
from cpf_env.scenarios.suite import SUITE

try:  # the learning extra; on the base install, a message instead of a traceback
    from agents.training.evaluation import DEFAULT_EVAL_NUM_SEEDS, ValidationEvaluator
except ModuleNotFoundError as error:
    raise SystemExit(missing_extra("cpf-train", error)) from None

if TYPE_CHECKING:
    from agents.training.config import TrainConfig
    from agents.training.schedule import RunSchedule

__all__ = ["DEFAULT_CHECKPOINT_EVERY", "DEFAULT_EVAL_EVERY", "train_main"]

#: The resolved hyperparameters, saved in the run folder.
HYPERPARAMETERS = "hyperparameters.toml"
#: Vessel-steps between held-out evaluations (one takes a few seconds per scenario).
DEFAULT_EVAL_EVERY = 500_000
#: Vessel-steps between checkpoints.
DEFAULT_CHECKPOINT_EVERY = 500_000


def training_scenarios() -> list[str]:
    """Registered scenarios training may draw from (the held-out ``_shift`` ones excluded)."""
    return [name for name in scenarios.list_scenarios() if not name.endswith(SHIFT_SUFFIX)]


def _scenarios(names: list[str]) -> str | tuple[str, ...]:
    """``--scenario`` values as ``TrainConfig.scenario``: ``suite`` expands to the suite."""
    expanded: list[str] = []
    for name in names:
        for item in SUITE if name == "suite" else (name,):
            if item not in expanded:
                expanded.append(item)
    return expanded[0] if len(expanded) == 1 else tuple(expanded)


def _parser() -> argparse.ArgumentParser:
    from agents.training.config import INIT_LOG_STD, TrainConfig
    from baselines import DEPLOYABLE

    defaults = TrainConfig()
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-train",
        description="Train PPO or SAC on FleetVecEnv (one slot per vessel, parameter sharing): "
        "a residual on top of an analytic policy, or from scratch (--base-policy none). Writes "
        "the agent (policy.safetensors, normalization.json, config.json, manifest.json: data "
        "only), SB3's model.zip (to resume training) and progress.csv to --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--algo", default=defaults.algo, choices=["ppo", "sac"], help="SB3 algorithm"
    )
    parser.add_argument(
        "--scenarios",
        dest="scenario",
        nargs="+",
        default=[defaults.scenario],
        choices=[*training_scenarios(), "suite"],
        metavar="SCENARIO",
        help="training scenario; several (or 'suite', the benchmark suite) train one agent on "
        "their mixture (the suite agent of docs/results.md: --config "
        "examples/hyperparameters/suite_residual_ppo.toml). Choices: "
        + ", ".join([*training_scenarios(), "suite"]),
    )
    parser.add_argument(
        "--base-policy",
        default=defaults.base_policy,
        choices=[*sorted(DEPLOYABLE), "none"],
        help="base policy the agent corrects; none: the agent commands forces and rate",
    )
    parser.add_argument(
        "--fleets",
        type=positive_int,
        default=defaults.fleets,
        help="fleets simulated together (in a mixture, shared out evenly over the scenarios)",
    )
    parser.add_argument(
        "-n",
        "--timesteps",
        type=positive_int,
        default=defaults.timesteps,
        help="budget in vessel-steps (PPO rounds it up to whole rollouts; the rounding is printed)",
    )
    parser.add_argument("--seed", type=int, default=defaults.seed, help="training seed")
    parser.add_argument(
        "--out", required=True, default=argparse.SUPPRESS, help="output folder (the run's folder)"
    )
    parser.add_argument(
        "--eval-every", type=non_negative_int, default=DEFAULT_EVAL_EVERY,
        help="vessel-steps between evaluations of the deterministic agent on the validation "
        "seeds, 9000 and up (evaluations.csv, best/); 0: none",
    )  # fmt: skip
    parser.add_argument(
        "--eval-num-seeds", type=positive_int, default=DEFAULT_EVAL_NUM_SEEDS,
        help="evaluation episodes per scenario (cpf-bench --num-seeds)",
    )  # fmt: skip
    parser.add_argument(
        "--resume", action="store_true",
        help="continue the run in --out from its last checkpoint, with its own settings "
        "(only -n may change: a larger budget extends the run)",
    )  # fmt: skip
    parser.add_argument(
        "--tensorboard-log", metavar="DIR", default=None,
        help="also write TensorBoard event files to DIR/<name of --out> "
        "(tensorboard --logdir DIR)",
    )  # fmt: skip
    parser.add_argument(
        "--set", nargs="+", action="extend", default=[], dest="settings", metavar="KEY=VALUE",
        help="override one hyperparameter, any TrainConfig field (residual.FIELD: one of its "
        "ResidualConfig) or schedule key, VALUE a TOML value (a bare word is a string): e.g. "
        "--set n_epochs=5 'net_arch=[64, 64]' residual.mode=force_and_rate residual.scale=0.3 "
        "'residual.extras=[\"base_action\"]'; over --config, under the flags",
    )  # fmt: skip
    parser.add_argument(
        "--config", metavar="FILE.toml", default=None,
        help="hyperparameter file (TOML: TrainConfig field names, a [residual] table, and "
        "eval_every, eval_num_seeds, checkpoint_every; extends = \"OTHER.toml\" starts from "
        "another file); --set and "
        "the flags given override it; the resolved values are saved as "
        "--out/hyperparameters.toml",
    )  # fmt: skip
    parser.add_argument(
        "--device", default="cpu",
        help="torch device SB3 trains on: cpu, auto (a GPU if torch sees one), cuda or cuda:N; "
        "recorded in run.json; the agent folder loads on the CPU whatever trained it",
    )  # fmt: skip
    parser.add_argument(
        "--init-from", metavar="FOLDER", default=None,
        help="start PPO's actor and observation statistics from this agent folder (a "
        "cpf-distill student, say) of the same recipe (base_policy, residual, slots, encoder, "
        "history, net_arch; a differing one is refused), the critic fresh, the statistics "
        "frozen; log_std_init "
        f"then defaults to {INIT_LOG_STD}; recorded in run.json and config.json",
    )  # fmt: skip
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--force", action="store_true", help="delete a run already in --out and start afresh"
    )
    return parser


def _given(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> set[str]:
    """The destinations of the options given on the command line (not left at their default)."""
    unset = object()
    probe = copy.deepcopy(parser)
    for action in probe._actions:  # an "extend" option (--set) starts from None, not a sentinel
        if action.dest != "help":
            action.default = None if isinstance(action, argparse._ExtendAction) else unset
    parsed = vars(probe.parse_args(argv))
    return {name for name, value in parsed.items() if value is not unset and value is not None}


#: Options that may be given with --resume (the rest come from the run's run.json).
RESUME_OPTIONS = {"out", "resume", "timesteps", "quiet", "tensorboard_log", "device"}


#: Option destinations that are not hyperparameters (what to do, not how to learn).
NOT_HYPERPARAMETERS = {
    "out",
    "resume",
    "quiet",
    "force",
    "config",
    "tensorboard_log",
    "device",
    "init_from",
    "settings",
}


def _resolve(args: argparse.Namespace, given: set[str]) -> tuple[TrainConfig, RunSchedule, int]:
    """The run's configuration, schedule and evaluation seeds.

    Precedence: the defaults, ``--config``, ``--set``, then the flags given.

    Raises:
        ValueError: A bad hyperparameter file or value.
    """
    from agents.training.config import INIT_LOG_STD, TrainConfig
    from agents.training.schedule import RunSchedule

    values = {} if args.config is None else read_hyperparameters(args.config)
    values = merge_settings(values, parse_settings(args.settings))
    for dest in sorted(given - NOT_HYPERPARAMETERS):
        values[dest] = getattr(args, dest)
    if args.init_from is not None and "log_std_init" not in values:
        values["log_std_init"] = INIT_LOG_STD  # the distilled actor's behaviour, barely perturbed
    fields = {k: v for k, v in values.items() if k not in SCHEDULE_KEYS}
    if "scenario" in fields:  # from the file or the flag: a name, names, or "suite"
        named = fields["scenario"]
        fields["scenario"] = _scenarios([named] if isinstance(named, str) else list(named))
    config = TrainConfig(**fields)
    schedule = RunSchedule(
        values.get("eval_every", args.eval_every),
        values.get("checkpoint_every", DEFAULT_CHECKPOINT_EVERY),
    )
    seeds = values.get("eval_num_seeds", args.eval_num_seeds)
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise ValueError(f"eval_num_seeds must be an integer >= 1, got {seeds!r}.")
    return config, schedule, seeds


def _resumed(
    args: argparse.Namespace, given: set[str]
) -> tuple[TrainConfig, RunSchedule, int, int | None]:
    """Configuration, schedule and evaluation settings of the run in ``--out``.

    Raises:
        ValueError: Options other than ``RESUME_OPTIONS``, or no run to resume.
    """
    from agents.training.run_folder import read_run_record

    extra = sorted(given - RESUME_OPTIONS)
    if extra:
        flags = ", ".join("--" + name.replace("_", "-") for name in extra)
        raise ValueError(
            f"--resume continues the run with its own settings (run.json); drop {flags} "
            "(only -n may change)."
        )
    config, schedule, evaluation = read_run_record(Path(args.out))
    if "timesteps" in given:
        config = dataclasses.replace(config, timesteps=args.timesteps)
    seeds = int((evaluation or {}).get("num_seeds", DEFAULT_EVAL_NUM_SEEDS))
    # "steps": a run written before the horizon was named max_steps
    max_steps = (evaluation or {}).get("max_steps", (evaluation or {}).get("steps"))
    return config, schedule, seeds, max_steps


def _hyperparameters(config: TrainConfig, schedule: RunSchedule, seeds: int) -> str:
    """The resolved ``hyperparameters.toml`` of a run."""
    return hyperparameters_toml(
        config.to_json(),
        {
            "eval_every": schedule.eval_every,
            "eval_num_seeds": seeds,
            "checkpoint_every": schedule.checkpoint_every,
        },
    )


def train_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-train``: see ``cpf-train --help``."""
    parser = _parser()
    args = parser.parse_args(argv)
    from agents.training.device import torch_device
    from agents.training.schedule import TrainingInterrupted
    from agents.training.trainer import train
    from cpf_env.infra.atomic import FolderLockedError

    given = _given(parser, argv)
    try:
        if args.resume:
            config, schedule, seeds, max_steps = _resumed(args, given)
        else:
            config, schedule, seeds = _resolve(args, given)
            max_steps = None
        for name in config.scenarios:
            check_training(name, range(config.seed, config.seed + config.fleets))
        torch_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    evaluate = ValidationEvaluator(config.scenarios, seeds, max_steps)
    out = Path(args.out)
    replacing = args.force and not args.resume and out.is_dir() and any(out.iterdir())
    try:
        folder = train(
            config,
            args.out,
            progress=not args.quiet,
            overwrite=args.force,
            evaluate=evaluate if schedule.eval_every > 0 else None,
            schedule=schedule,
            resume=args.resume,
            tensorboard_log=args.tensorboard_log,
            run_files={HYPERPARAMETERS: _hyperparameters(config, schedule, seeds)},
            device=args.device,
            init_from=args.init_from,
        )
    except TrainingInterrupted as stop:
        print(
            f"cpf-train: stopped by Ctrl-C at {stop.timesteps:,} vessel-steps; the agent so far "
            f"is in {args.out}/ and its checkpoint in {args.out}/checkpoint/. Continue with: "
            f"cpf-train --resume --out {args.out}",
            file=sys.stderr,
        )
        return 130
    except KeyboardInterrupt:
        if replacing:  # the new run was built beside the old one, and is gone
            print(
                f"cpf-train: aborted; --force replaces {args.out} only once the new agent is "
                "written, so it holds the earlier run as it was.",
                file=sys.stderr,
            )
            return 130
        print(
            f"cpf-train: aborted; the last periodic checkpoint (if any) is in "
            f"{args.out}/checkpoint/: cpf-train --resume --out {args.out}",
            file=sys.stderr,
        )
        return 130
    except (FileExistsError, ValueError, FolderLockedError) as error:
        parser.error(str(error))
    except OSError as error:  # disk full: the last checkpoint stays
        parser.error(f"could not write the run to {args.out}: {error}")
    record = json.loads((folder / "config.json").read_text())
    rounded = (
        ""
        if record["timesteps_done"] == config.timesteps
        else f" (-n {config.timesteps:,} rounded up to whole rollouts)"
    )
    best = (
        f"; best held-out evaluation in {folder}/best/ (evaluations.csv)"
        if (folder / "best").is_dir()
        else ""
    )
    print(
        f"trained {config.algo} on {' + '.join(config.scenarios)} (base "
        f"{config.base_policy}) for "
        f"{record['timesteps_done']:,} vessel-steps{rounded} in {record['train_seconds']} s "
        f"({record['vessel_steps_per_second']:,} vessel-steps/s; held-out evaluations took "
        f"{record['evaluation_seconds']} s more); saved to {folder}/{best}\n"
        f"evaluate: cpf-bench --policies "
        f"{config.base_policy if config.base_policy != 'none' else 'nn_dsc'} "
        f"{folder} --scenarios {' '.join(config.scenarios)} --split test"
    )
    return 0


if __name__ == "__main__":
    sys.exit(train_main())
