"""Episode recordings and the paper-claim metrics computed from them.

A ``Trajectory`` holds what one fleet did over an episode, sampled once per
control step; ``episode_metrics`` reduces it to the numbers the paper's
claims and the benchmark are stated in, over a final window of the episode
(by default its last quarter, where the paper's claims are about steady
state). These are per-vessel maxima for checking the paper's claims; the
benchmark's metrics, which ``cpf-run`` also reports (``Trajectory.fleet_metrics``),
are defined once in ``cpf_env.evaluation.fleet_metrics``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["Trajectory", "episode_metrics", "final_window"]


@dataclass
class Trajectory:
    """One fleet's episode, T samples (one per control step, after the step).

    Attributes:
        time: (T,) s.
        eta: (T, n, 3) poses (m, m, rad).
        eta_desired: (T, n, 3) virtual targets eta_d(theta_i).
        nu: (T, n, 3) body velocities.
        theta: (T, n) path variables.
        theta_dot: (T, n) commanded path-variable rates (1/s).
        tau_command: (T, n, 3) force commands (N, N, N m).
        tau_applied: (T, n, 3) saturated forces.
        errors: (T, n, 4) path, heading, sync, speed error (``kernels.ERR_*``).
        reward: (T, n).
        v0: (T,) leader speed (m/s).
        tau_min: (n, 3) lower force limits.
        tau_max: (n, 3) upper force limits.
        extras: Policy diagnostics and derived series, name -> (T, n, ...) array.
        fleet_metrics: The benchmark's metrics of the episode
            (``cpf_env.evaluation.fleet_metrics.METRICS``), name -> value.
    """

    time: NDArray[np.float64]
    eta: NDArray[np.float64]
    eta_desired: NDArray[np.float64]
    nu: NDArray[np.float64]
    theta: NDArray[np.float64]
    theta_dot: NDArray[np.float64]
    tau_command: NDArray[np.float64]
    tau_applied: NDArray[np.float64]
    errors: NDArray[np.float64]
    reward: NDArray[np.float64]
    v0: NDArray[np.float64]
    tau_min: NDArray[np.float64]
    tau_max: NDArray[np.float64]
    extras: dict[str, NDArray[np.float64]]
    fleet_metrics: dict[str, float] = field(default_factory=dict)

    def save(self, path: str) -> None:
        """Write every series to a compressed ``.npz`` file."""
        mappings = ("extras", "fleet_metrics")
        arrays = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in mappings}
        arrays.update({f"extra_{k}": v for k, v in self.extras.items()})
        arrays.update({f"metric_{k}": np.array(v) for k, v in self.fleet_metrics.items()})
        np.savez_compressed(path, **arrays)


def final_window(trajectory: Trajectory, fraction: float = 0.25) -> slice:
    """Slice of the last ``fraction`` of a trajectory's samples (at least one)."""
    steps = trajectory.time.shape[0]
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"window fraction must be in (0, 1], got {fraction}.")
    return slice(steps - max(1, round(fraction * steps)), steps)


def episode_metrics(trajectory: Trajectory, window: float = 0.25) -> dict[str, Any]:
    """Steady-state and whole-episode metrics of a recorded episode.

    Args:
        trajectory: The recording.
        window: Fraction of the episode, at its end, that steady-state metrics use.

    Returns:
        A JSON-ready dict. Per-vessel lists have length n. ``*_max`` are maxima
        over the window; ``coordination_error_max`` is max |theta_i - theta_j|
        over all pairs; ``speed_estimate_error_max`` needs the policy's
        ``speed_estimate`` diagnostic (else absent).
    """
    w = final_window(trajectory, window)
    theta = trajectory.theta[w]
    spread = theta.max(axis=1) - theta.min(axis=1)
    tau = trajectory.tau_applied
    saturated = trajectory.tau_command != trajectory.tau_applied
    path_error = trajectory.errors[..., 0]
    metrics: dict[str, Any] = {
        "window_start_s": float(trajectory.time[w][0]),
        "duration_s": float(trajectory.time[-1]),
        "path_error_max": path_error[w].max(axis=0).tolist(),
        "path_error_rms": np.sqrt((path_error[w] ** 2).mean(axis=0)).tolist(),
        "heading_error_max": np.abs(trajectory.errors[w, :, 1]).max(axis=0).tolist(),
        "coordination_error_max": float(spread.max()),
        "sync_error_max": float(np.abs(trajectory.errors[w, :, 2]).max()),
        "rate_error_max": np.abs(trajectory.theta_dot[w] - trajectory.v0[w, None])
        .max(axis=0)
        .tolist(),
        "force_max_abs": np.abs(tau).max(axis=0).tolist(),
        "force_within_limits": bool(
            np.all(tau >= trajectory.tau_min - 1e-12) and np.all(tau <= trajectory.tau_max + 1e-12)
        ),
        "saturated_fraction": saturated.any(axis=2).mean(axis=0).tolist(),
        "saturated_fraction_window": saturated[w].any(axis=2).mean(axis=0).tolist(),
        "return_mean": float(trajectory.reward.sum(axis=0).mean()),
        "steps": int(trajectory.time.shape[0]),
    }
    if "speed_estimate" in trajectory.extras:
        estimate = trajectory.extras["speed_estimate"][w]
        metrics["speed_estimate_error_max"] = (
            np.abs(estimate - trajectory.v0[w, None]).max(axis=0).tolist()
        )
    return metrics
