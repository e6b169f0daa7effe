"""``cpf-bench``: the command around ``cpf_commands.bench.run``.

It checks the output folder before anything runs (``--force``, a lock,
writable, not a link, disk, and memory for policies x seeds x series), runs
``run_bench`` and prints its answer (``cpf_commands.bench.ranking``: per
scenario and over the suite, the policies ranked by mean cost with their ratio
to the reference, normalized score and verdict, and the best deployable policy
named); ``cpf-bench --help`` lists the flags.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from collections.abc import Sequence

from cpf_bench.episodes import METRICS
from cpf_bench.report import summarize
from cpf_bench.stats import REPLICATES
from cpf_bench.verdict import COST_MARGIN, check_margin
from cpf_commands.bench import ranking
from cpf_commands.bench.marl_eval import write_marl_eval
from cpf_commands.bench.run import (
    BASE_SEED,
    OUTPUT_FILES,
    default_policies,
    labelled_policies,
    reference_label,
    run_bench,
)
from cpf_commands.common.arguments import add_scenarios_argument, non_negative_int
from cpf_commands.common.outputs import claim_output_folder
from cpf_commands.common.policies import policy_argument
from cpf_commands.common.ray_runtime import add_address_argument
from cpf_env.infra import atomic
from cpf_env.scenarios import make_scenario
from cpf_env.scenarios.splits import SPLITS
from cpf_env.scenarios.suite import TRACKS, is_deterministic, list_suite

__all__ = ["bench_main"]

#: Memory per fleet and step of a batch's recorded series and their reduction (measured
#: 256 B on bench_large_fleet: 15 float64 series and the temporaries of their reduction).
SERIES_BYTES_PER_STEP = 256
#: Memory per vessel of a fleet's simulator, policy and step-record state (measured about
#: 24 KiB on bench_large_fleet, rounded up).
STATE_BYTES_PER_VESSEL = 32 * 1024
#: Memory per metric, bootstrap replicate and seed of a cell's summary: the resampled
#: metrics and their sorted copy for the IQM (measured 2.5 x 8 B, rounded up).
BOOTSTRAP_BYTES = 3 * 8
#: Disk space per episode of the outputs (a row of episodes.csv, generous).
OUTPUT_BYTES_PER_EPISODE = 1024


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cpf-bench",
        allow_abbrev=False,
        description="Run policies x scenarios x paired seeds in batched simulators; print, per "
        "scenario and over the suite, the policies ranked by mean cost with their ratio to "
        "the reference, normalized score and verdict, and the best deployable policy; write "
        "episodes.csv, summary.csv, summary.md, report.html and figures: means and "
        "interquartile means with 95 % bootstrap intervals, failures counted, scores relative "
        "to nn_dsc.",
    )
    parser.add_argument(
        "--policies",
        nargs="+",
        default=None,
        type=policy_argument,
        metavar="POLICY",
        help="baseline names, policies installed packages register, package.module:NAME of "
        "your own policy class or factory (docs/extending.md), cpf-train --out folders or "
        "cpf-export .onnx files, each once (default: every deployable baseline, with the "
        "navigation-filtered and safety-filtered designs on the hard track, and the headroom "
        "bound oracle, which plans on copies of the simulator: not deployable)",
    )
    add_scenarios_argument(
        parser,
        "registered scenario names (default: the scenarios of --track)",
        default=None,
    )
    parser.add_argument(
        "--track",
        choices=sorted(TRACKS),
        default=None,
        help="the benchmark track to run when --scenarios is not given: core, the suite "
        "bench_* (the default); hard, the tasks under sensing, hulls without sway, "
        "thruster dynamics and crossing traffic, hard_* (cpf_env.scenarios.hard)",
    )
    parser.add_argument(
        "--num-seeds", type=int, default=10, help="episodes per policy and scenario (default: 10)"
    )
    parser.add_argument(
        "--seed",
        type=non_negative_int,
        default=BASE_SEED,
        help=f"seed of episode 0; episode k uses seed + k (default: {BASE_SEED})",
    )
    parser.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help="horizon in control steps, for quick runs (default: each scenario's max_steps)",
    )
    parser.add_argument(
        "--out", default="outputs/bench", help="output folder (default: outputs/bench)"
    )
    parser.add_argument("--force", action="store_true", help="replace the results already in --out")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument(
        "--ray",
        action="store_true",
        help="run the (policy, scenario) cells as Ray tasks, on local Ray or at --address "
        "(giving --address implies --ray; results identical to a local run; needs the ray "
        "extra)",
    )
    parser.add_argument(
        "--split",
        choices=SPLITS,
        default="test",
        help="test: the scenarios on the evaluation seeds; shift: each suite scenario's "
        "_shift variant, outside its training ranges (default: test)",
    )
    parser.add_argument(
        "--reference",
        default=None,
        metavar="POLICY",
        help="the policy the others are compared with, one of --policies (default: nn_dsc "
        "if it runs, else the first policy)",
    )
    parser.add_argument(
        "--cost-margin",
        type=float,
        default=COST_MARGIN,
        metavar="FRACTION",
        help="practical-equivalence margin of the verdict: a cost difference whose 95 %% "
        "interval lies within +-FRACTION x the reference's mean cost is 'equivalent' "
        f"(default: {COST_MARGIN:g}, i.e. {100 * COST_MARGIN:g}%%; 0 turns it off)",
    )
    parser.add_argument(
        "--marl-eval",
        default=None,
        metavar="FILE",
        help="also write the episodes in marl-eval's JSON format to FILE (for marl-eval and "
        "BenchMARL plots)",
    )
    add_address_argument(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def _command(args: argparse.Namespace) -> str:
    """The command line that regenerates a run's files (the output folder left out)."""
    parts = ["cpf-bench", "--policies", *args.policies, "--scenarios", *args.scenarios]
    parts += ["--num-seeds", str(args.num_seeds)]
    if args.split != "test":
        parts += ["--split", args.split]
    if args.reference is not None:
        parts += ["--reference", args.reference]
    if args.cost_margin != COST_MARGIN:
        parts += ["--cost-margin", repr(args.cost_margin)]
    if args.seed != BASE_SEED:
        parts += ["--seed", str(args.seed)]
    if args.max_steps is not None:
        parts += ["--max-steps", str(args.max_steps)]
    return shlex.join(parts)


def _memory_needed(args: argparse.Namespace) -> tuple[int, int]:
    """Bytes of memory the run's largest batch and its summary hold (generous estimates).

    A local run steps every policy on a scenario in one simulator of
    policies x seeds fleets, each recording its series over the horizon; the
    scenarios run one after another. With Ray each (policy, scenario) cell is a
    task of its own, at most one per CPU at a time. The summary then
    bootstraps every metric of one cell at a time over its seeds.

    Returns:
        (largest batch, summary) in bytes; the run needs the larger of the two.
    """
    batches, episodes = [], []
    for name in args.scenarios:
        scenario = make_scenario(name)
        seeds = 1 if is_deterministic(scenario) else args.num_seeds
        horizon = args.max_steps or scenario.max_steps
        batches.append(
            seeds * (horizon * SERIES_BYTES_PER_STEP + scenario.n * STATE_BYTES_PER_VESSEL)
        )
        episodes.append(seeds)
    policies = len(args.policies)
    if args.ray or args.address is not None:
        batch = max(batches) * min(policies * len(batches), os.cpu_count() or 1)
    else:
        batch = max(batches) * policies
    return batch, max(episodes) * len(METRICS) * REPLICATES * BOOTSTRAP_BYTES


def _claim_output(args: argparse.Namespace) -> atomic.FolderLock:
    """Refuse a run whose flags, memory or output folder would fail it; lock --out."""
    if args.num_seeds < 1:
        raise ValueError(f"--num-seeds must be >= 1, got {args.num_seeds}.")
    labelled_policies(args.policies)  # a policy listed twice
    check_margin(args.cost_margin)
    batch, summary = _memory_needed(args)
    available = _available_memory()
    if available is not None and max(batch, summary) > available:
        raise ValueError(
            f"{len(args.policies)} policies x --num-seeds {args.num_seeds} need about "
            f"{max(batch, summary) / 2**30:.1f} GiB of memory ({batch / 2**30:.1f} GiB for the "
            f"largest batch, every policy's fleets on a scenario at once; "
            f"{summary / 2**30:.1f} GiB for the summary's bootstrap intervals), but "
            f"{available / 2**30:.1f} GiB are available; lower --num-seeds or --max-steps, or "
            "bench fewer policies at a time."
        )
    if args.marl_eval is not None:
        atomic.check_writable(args.marl_eval)
    return claim_output_folder(
        args.out,
        OUTPUT_FILES,
        args.force,
        "cpf-bench",
        needed_bytes=OUTPUT_BYTES_PER_EPISODE
        * args.num_seeds
        * len(args.policies)
        * len(args.scenarios),
    )


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux: MemAvailable), or None if unknown."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _count(number: int, one: str, many: str) -> str:
    """``number`` and the noun in its number: 1 scenario, 2 scenarios."""
    return f"{number} {one if number == 1 else many}"


def _arguments(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """The parsed arguments, ``scenarios`` resolved from ``--track`` when not given."""
    args = parser.parse_args(argv)
    if args.scenarios is not None and args.track is not None:
        parser.error(
            "--track and --scenarios both say which scenarios to run: give --track for a "
            "whole track, or --scenarios for a selection (from one track or several)."
        )
    if args.scenarios is None:
        args.scenarios = list_suite(args.track or "core")
    if args.policies is None:
        args.policies = default_policies(args.track or "core")
    return args


def bench_main(argv: Sequence[str] | None = None) -> int:
    """``cpf-bench``: see ``cpf-bench --help``."""
    parser = _parser()
    args = _arguments(parser, argv)
    start = time.perf_counter()
    try:
        lock = _claim_output(args)
    except ValueError as error:
        parser.error(str(error))
    try:
        cells = run_bench(
            args.policies,
            args.scenarios,
            num_seeds=args.num_seeds,
            seed=args.seed,
            max_steps=args.max_steps,
            out=args.out,
            command=_command(args),
            progress=not args.quiet,
            figures=not args.no_figures,
            distribute=args.ray or args.address is not None,
            address=args.address,
            reference=args.reference,
            split=args.split,
            cost_margin=args.cost_margin,
        )
        if args.marl_eval is not None:
            write_marl_eval(cells, args.marl_eval)
    except (ValueError, FileNotFoundError, ImportError, ConnectionError) as error:
        parser.error(str(error))
    except OSError as error:  # disk full while writing: the previous results are intact
        parser.error(f"could not write the results to {args.out}: {error}")
    finally:
        lock.release()
    elapsed = time.perf_counter() - start
    reference = reference_label(args.reference, labelled_policies(args.policies))
    answer = ranking.terminal_report(
        summarize(cells, reference), cells, reference, args.cost_margin
    )
    if answer:
        print(answer)
    requested = len(args.policies) * len(args.scenarios)
    if len(cells) < requested:
        print(
            f"cpf-bench: {requested - len(cells)} of {requested} (policy, scenario) cells did not "
            "run (the policy does not fit the scenario); summary.md lists them and why."
        )
    print(
        f"cpf-bench: {_count(len(args.policies), 'policy', 'policies')} x "
        f"{_count(len(args.scenarios), 'scenario', 'scenarios')} in "
        f"{elapsed:.0f} s; results in {args.out}/ (report.html, summary.md, summary.csv, "
        "episodes.csv)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(bench_main())
