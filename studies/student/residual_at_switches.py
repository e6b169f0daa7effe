r"""What a residual student holds, and how its output jumps when the graph switches.

    python studies/student/residual_at_switches.py FOLDER
    python studies/student/residual_at_switches.py FOLDER --scenario bench_switching --num-seeds 1

``FOLDER``: an agent folder, e.g. ``runs/student/agents/student_mpc_tuned_yield_s0``.

Runs the agent folder on a switching-graph scenario (default
``bench_switching_shift``, whose graph switches every 100 control steps) and
prints, over the benchmark's final window (the last quarter of the episode):
the residual's mean per axis (surge N, sway N, yaw N m), the mean absolute
change of the yaw residual on the steps the graph switches and on the other
steps, and the final-window heading error (RMS, rad) of each episode, the
number ``cpf-bench`` reports. The residual is the student's correction in
physical units (``TrainedPolicy.diagnostics["residual"]``).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from agents import load_policy
from cpf_bench.rollout import rollout
from cpf_env.evaluation.fleet_metrics import WINDOW_FRACTION
from cpf_env.model.graph import SwitchingTopology
from cpf_env.scenarios import make_scenario


class _Residuals:
    """Keeps the policy's residual (B, n, 3) of every step."""

    def __init__(self) -> None:
        self.steps: list[np.ndarray] = []

    def before(self, sim: Any, actions: Any, policy: Any) -> None:
        self.steps.append(np.asarray(policy.diagnostics["residual"])[..., :3].copy())

    def after(self, sim: Any) -> None:
        """Nothing after the step."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="an agent folder")
    parser.add_argument("--scenario", default="bench_switching_shift")
    parser.add_argument("--num-seeds", type=int, default=2, help="episodes")
    parser.add_argument("--seed", type=int, default=10000, help="first episode's seed")
    parser.add_argument(
        "--max-steps", type=int, default=None, help="episode length (default: the scenario's)"
    )
    args = parser.parse_args()
    overrides = {} if args.max_steps is None else {"max_steps": args.max_steps}
    scenario = make_scenario(args.scenario, **overrides)
    if not isinstance(scenario.topology, SwitchingTopology):
        parser.error(
            f"{args.scenario} has a fixed graph; choose a switching one (bench_switching)."
        )
    policy = load_policy(args.folder, scenario=scenario)
    observer = _Residuals()
    seeds = list(range(args.seed, args.seed + args.num_seeds))
    metrics = rollout(policy, scenario, seeds, observer=observer)
    residual = np.stack(observer.steps)  # (T, B, n, 3)
    steps = residual.shape[0]
    window = np.arange(steps) >= steps - max(1, round(WINDOW_FRACTION * steps))
    topology = scenario.topology
    switching = np.isin(np.arange(steps) % topology.period, topology.switch_steps)
    change = np.abs(np.diff(residual[..., 2], axis=0))  # step t - 1 -> t, (T - 1, B, n)
    at_switch, between = (window & switching)[1:], (window & ~switching)[1:]
    mean = residual[window].mean(axis=(0, 1, 2))
    print(f"{policy.name} on {scenario.name}, seeds {seeds}, final {window.sum()} steps:")
    print(f"  mean residual: surge {mean[0]:+.3f} N, sway {mean[1]:+.3f} N, yaw {mean[2]:+.3f} N m")
    print(
        f"  mean |change| of the yaw residual: {change[at_switch].mean():.4f} N m on a switch, "
        f"{change[between].mean():.4f} N m between switches"
    )
    headings = ", ".join(f"{value:.2e}" for value in metrics["heading_error_rms_window"])
    print(f"  heading error (final-window RMS, rad): {headings}")


if __name__ == "__main__":
    main()
