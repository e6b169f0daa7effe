"""The residual-RL experiment: learned corrections on top of nn_dsc, against the analytic policies.

Two phases, each resumable (a finished training run is not repeated):

1. ``train``: for each scenario and training seed, residual PPO on top of
   ``nn_dsc`` and PPO from scratch (``cpf-train`` with the same settings as
   ``TrainConfig`` plus the budget below), one folder per run in ``--runs``;
2. ``evaluate``: ``cpf-bench`` of ``nn_dsc``, ``backstepping`` and every trained
   run on evaluation seeds never used in training (10,000 and up; training
   fleets use seeds 0 .. fleets + 2), under the scenario's training reward
   and under the quadratic reward, written to ``--results``.

Scenarios: ``bench_saturation`` (sustained saturation: ``backstepping`` is far
more accurate than ``nn_dsc`` there, so the reference is measurably
imperfect) and ``bench_lossy_links`` (a 5-step delay leaves every analytic
policy at centimetres; the observation's ``age`` field could let a learner
compensate), both with random starts so seeds matter.

Usage::

    python examples/train_residual_ppo.py train --timesteps 1500000
    python examples/train_residual_ppo.py evaluate --eval-num-seeds 20
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

SCENARIOS = ("bench_saturation", "bench_lossy_links")
#: Agents by name: ``TrainConfig`` fields that differ from the experiment's common settings.
AGENTS: dict[str, dict[str, object]] = {
    "residual_ppo": {"base_policy": "nn_dsc"},
    "scratch_ppo": {"base_policy": "none", "log_std_init": -0.5},
    "residual_ppo_extras": {
        "base_policy": "nn_dsc",
        "residual": {"extras": ("base_action", "base_signals", "multiscale_errors")},
    },
    "residual_ppo_kinematic": {
        "base_policy": "nn_dsc",
        "residual": {"mode": "kinematic", "extras": ("multiscale_errors",)},
    },
    "residual_ppo_rate": {"base_policy": "nn_dsc", "residual": {"mode": "force_and_rate"}},
    "residual_ppo_quadratic": {"base_policy": "nn_dsc", "reward_form": "quadratic"},
    "residual_sac": {
        "algo": "sac",
        "base_policy": "nn_dsc",
        "batch_size": 1024,
        "net_arch": (64, 64),
    },
}


def train_runs(
    runs: Path,
    timesteps: int,
    seeds: Sequence[int],
    fleets: int,
    scenarios: Sequence[str],
    agents: Sequence[str],
) -> list[Path]:
    """Train every (scenario, agent, seed) not trained yet; return all run folders."""
    from agents.training.config import TrainConfig
    from agents.training.trainer import train

    folders = []
    for seed in seeds:  # seed outermost: an interrupted sweep still covers every cell
        for scenario in scenarios:
            for agent in agents:
                folder = runs / f"{agent}_{scenario}_s{seed}"
                folders.append(folder)
                if (folder / "config.json").is_file():
                    continue
                settings: dict[str, object] = {
                    "batch_size": 2560,
                    "torch_threads": 1,
                    **AGENTS[agent],
                }
                config = TrainConfig(
                    scenario=scenario,
                    fleets=fleets,
                    timesteps=timesteps,
                    seed=seed,
                    **settings,  # type: ignore[arg-type]
                )
                print(f"training {folder.name} ...", flush=True)
                train(config, folder, progress=False, overwrite=True)  # redo a killed run
    return folders


def evaluate(
    runs: Path,
    results: Path,
    num_seeds: int,
    scenarios: Sequence[str],
    max_steps: int | None = None,
) -> None:
    """Bench the analytic policies and the trained runs on unseen seeds, two rewards.

    ``max_steps`` shortens the episodes (None: each scenario's own length).
    """
    from cpf_commands.bench.run import run_bench
    from cpf_env import scenarios as registry
    from cpf_env.scenarios.reward_weights import RewardWeights

    for scenario in scenarios:
        trained = sorted(p for p in runs.glob(f"*_{scenario}_s*") if (p / "config.json").is_file())
        policies: dict[str, object] = {"nn_dsc": "nn_dsc", "backstepping": "backstepping"}
        policies.update({folder.name: str(folder) for folder in trained})
        task = registry.get(scenario)
        quadratic = task.replace(
            name=f"{scenario}_quadratic", reward=RewardWeights(form="quadratic")
        )
        for variant, label in ((task, "training_reward"), (quadratic, "quadratic_reward")):
            out = results / f"{scenario}_{label}"
            command = _evaluate_command(runs, results, num_seeds, max_steps)
            run_bench(
                policies,  # type: ignore[arg-type]
                [variant],
                num_seeds=num_seeds,
                max_steps=max_steps,
                out=out,
                command=command,
            )
            print(f"wrote {out}/summary.md", flush=True)
    (results / "summary.md").write_text(report(results, scenarios, num_seeds, runs, max_steps))
    meta = {
        "runs": {
            p.name: json.loads((p / "config.json").read_text())
            for p in sorted(runs.glob("*_s*"))
            if (p / "config.json").is_file()
        }
    }
    (results / "training_runs.json").write_text(json.dumps(meta, indent=2) + "\n")


#: Columns of the report: (metric in summary.csv, reward variant, header, format).
_COLUMNS = (
    ("cost", "training_reward", "cost (log reward)", "value"),
    ("cost", "training_reward", "/ nn_dsc", "ratio"),
    ("cost", "training_reward", "P(cost < nn_dsc)", "p"),
    ("cost", "quadratic_reward", "cost / nn_dsc (quadratic reward)", "ratio"),
    ("path_error_rms_window", "training_reward", "path error RMS, last quarter (m)", "value"),
    ("path_error_max_window", "training_reward", "path error max, last quarter (m)", "value"),
    ("theta_spread_end", "training_reward", "path-variable spread at the end", "value"),
    (
        "theta_rate_error_rms_window",
        "training_reward",
        "path-rate error RMS, last quarter (1/s)",
        "value",
    ),
    ("cost", "training_reward", "failures", "failures"),
)


def _evaluate_command(runs: Path, results: Path, num_seeds: int, max_steps: int | None) -> str:
    """The command line of the evaluate phase with these folders."""
    return (
        f"python examples/train_residual_ppo.py evaluate --runs {runs} --results {results} "
        f"--eval-num-seeds {num_seeds}" + (f" --eval-max-steps {max_steps}" if max_steps else "")
    )


def report(
    results: Path,
    scenarios: Sequence[str],
    num_seeds: int,
    runs: Path,
    max_steps: int | None = None,
) -> str:
    """A markdown table per scenario from the bench's summary.csv files: mean [95 % CI]."""
    import csv

    lines = [
        "# Residual RL: trained agents against the analytic policies",
        "",
        f"Regenerate: `{_evaluate_command(runs, results, num_seeds, max_steps)}` (after the "
        "`train` phase; the training commands are in `results/README.md`). Every policy runs "
        "the same evaluation seeds (10,000 and up, never used in training). Mean over episodes "
        "with its 95 % stratified-bootstrap interval; "
        "`P(cost < nn_dsc)`: probability of a lower cost than nn_dsc on the same seed. One row "
        "per training run (`_s<seed>`: training seed). Full tables: the `*/summary.md` files.",
    ]
    for scenario in scenarios:
        rows: dict[tuple[str, str, str], dict[str, str]] = {}
        for variant in ("training_reward", "quadratic_reward"):
            with open(results / f"{scenario}_{variant}" / "summary.csv") as handle:
                for row in csv.DictReader(handle):
                    rows[(row["policy"], variant, row["metric"])] = row
        policies = list(dict.fromkeys(policy for policy, _, _ in rows))
        lines += ["", f"## {scenario} ({num_seeds} evaluation episodes)", ""]
        lines.append("| policy | " + " | ".join(c[2] for c in _COLUMNS) + " |")
        lines.append("|---" * (len(_COLUMNS) + 1) + "|")
        for policy in policies:
            cells = []
            for metric, variant, _, kind in _COLUMNS:
                cells.append(_cell(rows.get((policy, variant, metric)), kind))
            lines.append(f"| {policy} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _cell(row: dict[str, str] | None, kind: str) -> str:
    """One table cell of a summary.csv row."""
    if row is None:
        return ""
    if kind == "failures":
        return f"{row['failures']}/{row['n_episodes']}"
    if kind == "p":
        if not row["p_beats_reference"]:
            return ""
        return f"{float(row['p_beats_reference']):.2f}"
    if kind == "ratio":
        return f"{float(row['normalized']):.3g}"
    return f"{float(row['mean']):.3g} [{float(row['ci_low']):.3g}, {float(row['ci_high']):.3g}]"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="train_residual_ppo.py",
        description="Residual PPO vs PPO from scratch vs nn_dsc and backstepping.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "phase",
        choices=["train", "evaluate", "report"],
        help="train; evaluate (bench + report); report (summary.md from the bench's CSVs)",
    )
    parser.add_argument("--runs", default="runs/residual_rl", help="training run folders")
    parser.add_argument(
        "--results", default="runs/residual_rl_evaluation", help="evaluation output"
    )
    parser.add_argument("--timesteps", type=int, default=1_500_000, help="per training run")
    parser.add_argument("--num-seeds", type=int, default=3, help="training seeds per agent")
    parser.add_argument("--seed", type=int, default=0, help="first training seed")
    parser.add_argument("--fleets", type=int, default=64, help="fleets per training run")
    parser.add_argument("--eval-num-seeds", type=int, default=20, help="evaluation episodes")
    parser.add_argument(
        "--eval-max-steps", type=int, default=None, help="evaluation episode length (scenario's)"
    )
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), help="scenarios")
    parser.add_argument(
        "--agents",
        nargs="+",
        default=["residual_ppo", "scratch_ppo"],
        choices=sorted(AGENTS),
        help="agents to train",
    )
    args = parser.parse_args(argv)
    runs, results = Path(args.runs), Path(args.results)
    if args.phase == "train":
        seeds = range(args.seed, args.seed + args.num_seeds)
        train_runs(runs, args.timesteps, seeds, args.fleets, args.scenarios, args.agents)
    elif args.phase == "evaluate":
        evaluate(runs, results, args.eval_num_seeds, args.scenarios, args.eval_max_steps)
    else:
        (results / "summary.md").write_text(
            report(results, args.scenarios, args.eval_num_seeds, runs, args.eval_max_steps)
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
