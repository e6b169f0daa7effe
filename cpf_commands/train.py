"""``cpf-train``: train a residual (or from-scratch) agent with Stable-Baselines3.

Familiar to RL Baselines3 Zoo users: ``--algo``, ``--scenario`` (the env),
``--seed``, ``--timesteps`` (``-n``), an output folder with the network's
weights (safetensors), the normalization statistics and the exact
configuration (JSON), tied by a manifest of hashes (``agents.agent_folder``). The folder loads
with ``agents.load_policy(DIR)`` and is accepted wherever a policy name is
(``cpf-bench --policies nn_dsc DIR``, ``cpf-run --policy DIR``).

Example::

    cpf-train --scenario bench_lossy_links --seed 0 --out runs/ppo_lossy_s0
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence

from cpf_commands.common.arguments import positive_int
from cpf_env import scenarios
from cpf_env.scenarios.splits import SHIFT_SUFFIX, check_training
from cpf_env.scenarios.suite import SUITE

__all__ = ["train_main"]


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


def _reward_overrides(items: list[str]) -> dict[str, float]:
    """``--reward-weight NAME=VALUE`` items as a dict (values checked by ``TrainConfig``)."""
    overrides = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            overrides[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise ValueError(f"--reward-weight takes NAME=NUMBER (e.g. heading=1.0), got {item!r}.")
    return overrides


def _parser() -> argparse.ArgumentParser:
    from agents.training import TrainConfig
    from baselines import POLICIES
    from cpf_env.envs.residual import EXTRAS, RESIDUAL_MODES
    from cpf_env.scenarios.reward_weights import REWARD_FORMS

    defaults = TrainConfig()
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="cpf-train",
        description="Train PPO or SAC on FleetVecEnv (one slot per vessel, parameter sharing): "
        "a residual on top of an analytic policy, or from scratch (--base none). Writes "
        "the agent (policy.safetensors, normalization.json, config.json, manifest.json: data "
        "only), SB3's model.zip (to resume training) and progress.csv to --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--algo", default=defaults.algo, choices=["ppo", "sac"])
    parser.add_argument(
        "--scenario",
        nargs="+",
        default=[defaults.scenario],
        choices=[*training_scenarios(), "suite"],
        metavar="SCENARIO",
        help="training scenario; several (or 'suite', the benchmark suite) train one agent on "
        "their mixture. Choices: " + ", ".join([*training_scenarios(), "suite"]),
    )
    parser.add_argument(
        "--neighbour-slots",
        type=positive_int,
        default=None,
        help="neighbour slots of the agent's input (default: the training scenarios' largest "
        "degree); the agent then runs on every graph of degree <= this",
    )
    parser.add_argument(
        "--balance-rewards",
        action=argparse.BooleanOptionalAction,
        default=defaults.balance_rewards,
        help="in a mixture, divide each scenario's rewards by its running mean cost per step",
    )
    parser.add_argument(
        "--reward-weight",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="change a reward field for training only (repeatable), e.g. heading=1.0; "
        "the benchmark's cost is unchanged",
    )
    parser.add_argument(
        "--base",
        default=defaults.base,
        choices=[*sorted(POLICIES), "none"],
        help="base policy the agent corrects; none: the agent commands forces and rate",
    )
    parser.add_argument(
        "--fleets", type=positive_int, default=defaults.fleets, help="fleets simulated together"
    )
    parser.add_argument(
        "-n", "--timesteps", type=positive_int, default=defaults.timesteps, help="vessel-steps"
    )
    parser.add_argument("--seed", type=int, default=defaults.seed, help="training seed")
    parser.add_argument("--out", required=True, help="output folder (required)")
    parser.add_argument(
        "--mode", default=defaults.mode, choices=sorted(RESIDUAL_MODES), help="residual mode"
    )
    parser.add_argument(
        "--scale", type=float, default=defaults.scale, help="residual range, fraction of limits"
    )
    parser.add_argument(
        "--extras", nargs="*", default=list(defaults.extras), choices=sorted(EXTRAS),
        help="local inputs appended to the observation",
    )  # fmt: skip
    parser.add_argument(
        "--reward", default=None, choices=REWARD_FORMS, help="override the scenario's reward form"
    )
    parser.add_argument(
        "--log-std-init", type=float, default=defaults.log_std_init, help="initial exploration"
    )
    parser.add_argument(
        "--learning-rate", type=float, default=defaults.learning_rate, help="Adam step size"
    )
    parser.add_argument(
        "--n-steps", type=positive_int, default=defaults.n_steps, help="PPO rollout length per slot"
    )
    parser.add_argument(
        "--batch-size", type=positive_int, default=defaults.batch_size, help="minibatch size"
    )
    parser.add_argument(
        "--epochs", type=positive_int, default=defaults.n_epochs, help="PPO epochs per rollout"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--force", action="store_true", help="overwrite a trained model already in --out"
    )
    return parser


def train_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-train``: see ``cpf-train --help``."""
    parser = _parser()
    args = parser.parse_args(argv)
    from agents.training import TrainConfig, train
    from cpf_env.atomic import FolderLockedError

    try:
        config = TrainConfig(
            algo=args.algo,
            scenario=_scenarios(args.scenario),
            base=args.base,
            fleets=args.fleets,
            timesteps=args.timesteps,
            seed=args.seed,
            mode=args.mode,
            scale=args.scale,
            extras=tuple(args.extras),
            reward_form=args.reward,
            log_std_init=args.log_std_init,
            learning_rate=args.learning_rate,
            n_steps=args.n_steps,
            batch_size=args.batch_size,
            n_epochs=args.epochs,
            neighbour_slots=args.neighbour_slots,
            reward_overrides=_reward_overrides(args.reward_weight),
            balance_rewards=args.balance_rewards,
        )
        for name in config.scenarios:
            check_training(name, range(config.seed, config.seed + config.fleets))
    except ValueError as error:
        parser.error(str(error))
    try:
        folder = train(config, args.out, progress=not args.quiet, overwrite=args.force)
    except (FileExistsError, ValueError, FolderLockedError) as error:
        parser.error(str(error))
    except OSError as error:  # disk full: the staging folder is removed, --out is unchanged
        parser.error(f"could not write the agent to {args.out}: {error}")
    record = json.loads((folder / "config.json").read_text())
    print(
        f"trained {config.algo} on {' + '.join(config.scenarios)} (base {config.base}) for "
        f"{record['timesteps_done']:,} vessel-steps in {record['train_seconds']} s "
        f"({record['vessel_steps_per_second']:,} vessel-steps/s); saved to {folder}/\n"
        f"evaluate: cpf-bench --policies {config.base if config.base != 'none' else 'nn_dsc'} "
        f"{folder} --scenarios {' '.join(config.scenarios)} --split test"
    )
    return 0
