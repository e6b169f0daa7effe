"""Command-line entry points (argparse only here, at the edge).

``cpf-run``: run a scenario with a policy (default: the paper's reproduction,
``wang2014_fine`` with ``nn_dsc`` under the integrating weight-law reading),
print the paper's claims with measured values where they apply (else the
run's own metrics), and write figures and metrics.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpf_commands.common.arguments import non_negative_int, positive_int
from cpf_commands.common.policies import policy_argument
from cpf_env import scenarios

if TYPE_CHECKING:
    from cpf_commands.run.video import VideoRecorder

__all__ = ["run_main"]

#: The scenario without --scenario and without an agent folder: the paper's reproduction.
DEFAULT_SCENARIO = "wang2014_fine"
#: Claims that need a part of the policy, and what it is.
_CLAIM_NEEDS = {2: "NN", 5: "speed estimator"}


def _run_parser(prog: str = "cpf-run") -> argparse.ArgumentParser:
    from baselines import POLICIES, PRIVILEGED
    from baselines.gains import LEAKAGE_LAWS
    from cpf_commands.run.video import FPS, FRAMES

    parser = argparse.ArgumentParser(
        prog=prog,
        allow_abbrev=False,
        description="Run a scenario with a policy; write Figs. 3-7, metrics.json and "
        "trajectory.npz; print the paper's claims with the measured values (on the paper's "
        "scenarios wang2014 and wang2014_fine), else the run's own metrics. Without "
        "arguments: the paper's reproduction, wang2014_fine with nn_dsc, leakage=plain.",
    )
    parser.add_argument(
        "--scenario",
        default=None,
        choices=scenarios.list_scenarios(),
        help=f"default: {DEFAULT_SCENARIO}, or a cpf-train --out folder's training scenario",
    )
    parser.add_argument(
        "--policy",
        default="nn_dsc",
        type=policy_argument,
        help=f"a baseline ({', '.join(sorted(POLICIES))}), a privileged reference "
        f"({', '.join(sorted(PRIVILEGED))}, not deployable), a policy an installed package "
        "registers, package.module:NAME of your own policy class or factory "
        "(docs/extending.md), a cpf-train --out folder or a cpf-export .onnx file",
    )
    parser.add_argument(
        "--leakage",
        default=None,
        choices=LEAKAGE_LAWS,
        help="reading of the NN weight law of nn_dsc and its ablations (default: plain on the "
        "0.01 s scenarios *_fine, gamma_scaled elsewhere); see docs/reproduction.md",
    )
    parser.add_argument(
        "--seed",
        type=non_negative_int,
        default=0,
        help="seed of the environment and the policy, an integer >= 0 (default: 0)",
    )
    parser.add_argument(
        "--max-steps",
        type=positive_int,
        default=None,
        help="control steps, >= 1 (default: the scenario's episode length)",
    )
    parser.add_argument(
        "--out",
        default="outputs",
        help="output directory; the run writes its subfolder <scenario>_<policy> whole at the "
        "end, a module:NAME policy's ':' written '+' (default: outputs)",
    )
    parser.add_argument(
        "--force", action="store_true", help="replace the results already in that subfolder"
    )
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument(
        "--video",
        metavar="FILE",
        default=None,
        help="also render the episode (fleet 0) to FILE: .mp4 (needs ffmpeg on PATH) or .gif",
    )
    parser.add_argument(
        "--video-every",
        type=positive_int,
        default=None,
        help=f"control steps between video frames (default: at most {FRAMES} frames, "
        f"played at {FPS} frames/s)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def _print_metrics(metrics: dict[str, Any]) -> None:
    """The run's own steady-state metrics, for runs the paper's claims do not cover."""
    settled = metrics["settling_time_s"]
    lines = [
        f"max path error {max(metrics['path_error_max']):.3g} m",
        f"max |theta_i - theta_j| {metrics['coordination_error_max']:.3g}",
    ]
    if "speed_estimate_error_max" in metrics:
        lines.append(f"max |vhat_i - v0| {max(metrics['speed_estimate_error_max']):.3g} m/s")
    print(f"Run metrics over the last quarter (from t = {metrics['window_start_s']:.1f} s):")
    print("  " + "; ".join(lines))
    within = "within" if metrics["force_within_limits"] else "OUTSIDE"
    settling = "not settled" if settled is None else f"settled (< 5 cm) from {settled:.1f} s"
    saturated = max(metrics["saturated_fraction"])
    print(
        f"  forces {within} the limits; saturated on {100 * saturated:.1f} % of the steps "
        f"(worst vessel); {settling}"
    )


def _default_scenario(policy: str) -> str:
    """The paper's scenario, or the training scenario of an agent folder (its first, if several).

    Raises:
        ValueError: A folder that is not an agent folder, or whose configuration is unreadable
            (``agents.folder.loading.read_config``'s message, naming the file and field); a MARL
            folder whose task overrides scenario fields (a name would leave them out).
    """
    if not Path(policy).is_dir():
        return DEFAULT_SCENARIO
    try:
        from agents.folder.loading import read_config, read_scenario_overrides
    except ImportError as error:
        raise ValueError(
            f"{policy!r} is a folder, but loading trained agents needs the learning extra: "
            "pip install -e '.[rl]'."
        ) from error
    names = read_config(policy).scenarios
    overrides = read_scenario_overrides(policy)
    if overrides:
        raise ValueError(
            f"{policy} was trained on {names[0]} with the scenario overrides {overrides}, "
            "which a registered scenario leaves out: choose one with --scenario (the run "
            f"is then without them), or evaluate in Python: agents.load_policy({policy!r}) "
            "runs on the training scenario with its overrides."
        )
    if len(names) > 1:
        print(
            f"cpf-run: the agent was trained on {len(names)} scenarios; running its first, "
            f"{names[0]} (choose another with --scenario)."
        )
    return names[0]


def _video_recorder(args: argparse.Namespace) -> VideoRecorder:
    """The recorder of ``--video``, its file checked before the episode runs."""
    from cpf_commands.run.video import VideoRecorder, check_video_path, frame_period
    from cpf_env.scenarios import make_scenario

    check_video_path(args.video)
    scenario = make_scenario(args.scenario)
    horizon = scenario.max_steps if args.max_steps is None else args.max_steps
    return VideoRecorder(scenario, args.video_every or frame_period(horizon))


def run_main(argv: Sequence[str] | None = None, prog: str = "cpf-run") -> int:
    """``cpf-run``: see ``cpf-run --help``; ``prog`` names the command in its help."""
    from cpf_commands.run.reproduce import PAPER_SCENARIOS, reproduce

    parser = _run_parser(prog)
    args = parser.parse_args(argv)
    try:
        args.scenario = args.scenario or _default_scenario(args.policy)
        video = None if args.video is None else _video_recorder(args)
    except ValueError as error:
        parser.error(str(error))
    if not args.quiet:
        print(
            "Loading the simulator kernels (numba compiles them on the first run: "
            "about a minute of CPU, docs/speed.md)..."
        )
        sys.stdout.flush()
    start = time.perf_counter()
    try:
        metrics, claims = reproduce(
            args.scenario,
            args.policy,
            seed=args.seed,
            max_steps=args.max_steps,
            out=args.out,
            figures=not args.no_figures,
            progress=not args.quiet,
            leakage=args.leakage,
            observer=video,
            force=args.force,
        )
        if video is not None:
            video.write(args.video)
    except ValueError as error:
        parser.error(str(error))
    except OSError as error:  # disk full while writing: the previous results are intact
        parser.error(f"could not write the results to {args.out}: {error}")
    elapsed = time.perf_counter() - start
    options = "".join(f", {k}={v}" for k, v in metrics["policy_options"].items())
    print(
        f"\n{args.scenario} with {args.policy}{options}, seed {args.seed}: "
        f"{metrics['steps']} steps ({metrics['duration_s']:.1f} s simulated) in {elapsed:.1f} s"
    )
    if args.scenario in PAPER_SCENARIOS:
        print(
            "Claims of Wang, Wang & Peng (2014), measured over the last quarter of the run "
            "(claim 4 over the whole run):"
        )
        for claim in claims:
            verdict = "holds" if claim.holds else "NOT MET"
            if claim.holds is None:
                verdict = f"not judged: {metrics['claims_not_judged']}"
            print(
                f"  {claim.number}. [{claim.figure}] {claim.statement}\n"
                f"     measured: {claim.measured} -> {verdict}"
            )
        shown = {claim.number for claim in claims}
        for number, part in _CLAIM_NEEDS.items():
            if number not in shown:
                print(f"  ({number}. does not apply: {args.policy} has no {part})")
    else:
        print(
            f"The paper's claims are stated for its scenarios {', '.join(PAPER_SCENARIOS)}; "
            f"{args.scenario} is not one of them."
        )
        _print_metrics(metrics)
    if video is not None:
        print(
            f"Video of fleet 0: {args.video} ({len(video.frames)} frames, one every "
            f"{video.every} steps = {video.seconds_per_frame:.2f} s simulated, at {video.fps} "
            "frames/s)"
        )
    if "output_directory" in metrics:
        written = "metrics.json and trajectory.npz"
        if not args.no_figures:
            written = "Figures, " + written
        print(f"{written} in {metrics['output_directory']}/")
    return 0


if __name__ == "__main__":
    sys.exit(run_main())
