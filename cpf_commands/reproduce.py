"""Reproduce the paper's simulation: run, measure the five claims, write figures and metrics.

The claims are those of the paper's section 4 (docs/reproduction.md), each checked over the last
quarter of the episode with the thresholds of the project's acceptance
criteria. Claim 2 (the NN tracks the lumped uncertainty) has no threshold in
the paper; it is reported as the relative RMS error of the NN output per axis,
and judged "tracks" only below ``NN_TRACKING_TOLERANCE``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpf_commands.experiment import run_episode
from cpf_commands.figures import write_figures
from cpf_env.metrics import Trajectory, episode_metrics, final_window
from cpf_env.scenarios import Scenario

__all__ = ["NN_TRACKING_TOLERANCE", "Claim", "evaluate_claims", "reproduce"]

#: Thresholds over the last quarter (m; path-variable units; m/s).
PATH_TOLERANCE, COORDINATION_TOLERANCE, SPEED_TOLERANCE = 0.01, 0.01, 1e-4
#: Relative RMS error below which the NN is said to track f_i.
NN_TRACKING_TOLERANCE = 0.2


@dataclass(frozen=True)
class Claim:
    """One claim of the paper with its measured value.

    Attributes:
        number: 1..5 as in docs/reproduction.md.
        figure: The paper's figure.
        statement: What the paper claims.
        measured: What this run measured, in words with numbers.
        holds: Whether the measured value meets the stated threshold.
    """

    number: int
    figure: str
    statement: str
    measured: str
    holds: bool


def _nn_relative_error(trajectory: Trajectory, vessel: int) -> np.ndarray | None:
    """RMS(nn - f) / RMS(f) per axis over the last quarter, or None without an NN."""
    nn, true = trajectory.extras.get("nn_output"), trajectory.extras.get("lumped_true")
    if nn is None or true is None or not np.any(nn):
        return None
    window = final_window(trajectory)
    error = nn[window, vessel] - true[window, vessel]
    scale = np.sqrt((true[window, vessel] ** 2).mean(axis=0))
    return np.sqrt((error**2).mean(axis=0)) / np.maximum(scale, 1e-12)


def evaluate_claims(trajectory: Trajectory, metrics: dict[str, Any]) -> list[Claim]:
    """Check the paper's five claims (docs/reproduction.md) on a recorded run."""
    n = trajectory.eta.shape[1]
    nn_vessel, force_vessel = min(1, n - 1), min(2, n - 1)
    path = max(metrics["path_error_max"])
    coordination = metrics["coordination_error_max"]
    tau = np.abs(trajectory.tau_applied[:, force_vessel]).max(axis=0)
    limits = np.maximum(
        np.abs(trajectory.tau_min[force_vessel]), np.abs(trajectory.tau_max[force_vessel])
    )
    nn_error = _nn_relative_error(trajectory, nn_vessel)
    speed = metrics.get("speed_estimate_error_max")
    claims = [
        Claim(
            1,
            "Fig. 3",
            "every vessel converges to a small neighbourhood of its path",
            f"max path error over last quarter {path:.3g} m (threshold {PATH_TOLERANCE} m)",
            path < PATH_TOLERANCE,
        ),
        Claim(
            2,
            "Fig. 4",
            f"the NN output tracks the lumped uncertainty f of vessel {nn_vessel + 1}",
            "no NN in this policy"
            if nn_error is None
            else "relative RMS error (surge, sway, yaw) over last quarter "
            + ", ".join(f"{e:.2f}" for e in nn_error)
            + f" (tracks if < {NN_TRACKING_TOLERANCE})",
            nn_error is not None and bool(np.all(nn_error < NN_TRACKING_TOLERANCE)),
        ),
        Claim(
            3,
            "Fig. 5",
            "coordination errors theta_i - theta_j converge near 0",
            f"max |theta_i - theta_j| over last quarter {coordination:.3g} "
            f"(threshold {COORDINATION_TOLERANCE})",
            coordination < COORDINATION_TOLERANCE,
        ),
        Claim(
            4,
            "Fig. 6",
            f"forces of vessel {force_vessel + 1} stay within the limits",
            "max |tau| ("
            + ", ".join(f"{t:.3g}" for t in tau)
            + ") vs limits ("
            + ", ".join(f"{t:.3g}" for t in limits)
            + ")",
            bool(np.all(tau <= limits + 1e-12)) and metrics["force_within_limits"],
        ),
        Claim(
            5,
            "Fig. 7",
            "every speed estimate converges to v0, also where b_i = 0",
            "no speed estimate in this policy"
            if speed is None
            else f"max |vhat_i - v0| over last quarter {max(speed):.3g} m/s "
            f"(threshold {SPEED_TOLERANCE})",
            speed is not None and max(speed) < SPEED_TOLERANCE,
        ),
    ]
    return claims


def reproduce(
    scenario: str | Scenario = "wang2014",
    policy: str = "nn_dsc",
    seed: int = 0,
    steps: int | None = None,
    out: str | Path | None = "outputs",
    figures: bool = True,
    progress: bool = False,
) -> tuple[dict[str, Any], list[Claim]]:
    """Run the reproduction and write ``metrics.json``, ``trajectory.npz`` and figures.

    Args:
        scenario: Scenario name or object.
        policy: A baseline name or a ``cpf-train --out`` folder (``resolve_policy``).
        seed: Seed of environment and policy.
        steps: Control steps (default: the scenario's episode length).
        out: Output directory; a subdirectory ``<scenario>_<policy>`` is written.
            None writes nothing.
        figures: Write the PNG figures.
        progress: Show a progress bar.

    Returns:
        (metrics, claims).
    """
    trajectory = run_episode(scenario, policy, seed=seed, steps=steps, progress=progress)
    metrics = episode_metrics(trajectory)
    claims = evaluate_claims(trajectory, metrics)
    name = scenario if isinstance(scenario, str) else scenario.name
    metrics.update(
        scenario=name, policy=policy, seed=seed, claims=[asdict(claim) for claim in claims]
    )
    if out is not None:
        directory = Path(out) / f"{name}_{Path(policy).name}"
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "metrics.json").write_text(json.dumps(metrics, indent=2))
        trajectory.save(str(directory / "trajectory.npz"))
        if figures:
            write_figures(trajectory, directory)
        metrics["output_directory"] = str(directory)
    return metrics, claims
