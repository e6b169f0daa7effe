"""Batched evaluation episodes and their per-episode metrics.

``run_episodes`` runs one policy on one scenario for S seeds at once: one
``FleetSim(num_fleets=S)``, fleet k reset with seed k, the policy's
``act_batch`` on all fleets every step. Fleets are not reset when they
terminate: a fleet that leaves its path is masked from then on (its later
steps do not count, its actions are replaced by zeros so the simulator stays
finite) and its failure flag and step are recorded.

Per-episode metrics (``METRICS``), over the steps the episode lasted and
again over the final window (the last quarter of the horizon; suffix
``_window``; an episode that ended before the window is measured at its
last step), with e_i the path error (m), psi~_i the heading error (rad),
spread = max_ij |theta_i - theta_j| and averages over vessels and steps:

=============================  ==================================================
``return``                     sum over steps of the fleet-mean reward
``cost``                       -return; ``cost_<term>`` its split by reward term
``path_error_rms`` / ``_max``  RMS / max of e_i (m)
``heading_error_rms``          RMS of psi~_i (rad)
``coordination_error_rms``     RMS of the spread; ``coordination_error_end`` at the last step
``speed_error_rms``            RMS of theta_dot_i - v0 (m/s)
``speed_estimate_error_rms``   RMS of vhat_i - v0 (m/s), policies with ``speed_estimate``
``control_energy``             integral of ||tau_i / tau_scale||^2 dt, mean over vessels (s)
``saturated_fraction``         fraction of vessel-steps with a saturated force axis
``terminated`` / ``steps``     1 if the fleet left its path / steps the episode lasted
=============================  ==================================================
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from cpf_commands.common.policies import BenchPolicy
from cpf_env.scenarios import Scenario
from cpf_env.scenarios.reward_weights import REWARD_TERMS
from cpf_env.sim import arrays
from cpf_env.sim.fleet import FleetSim

__all__ = ["METRICS", "WINDOW_FRACTION", "run_episodes"]

#: Fraction of the horizon, at its end, that the ``_window`` metrics use.
WINDOW_FRACTION = 0.25

_TERM_COSTS = tuple(f"cost_{term}" for term in REWARD_TERMS)
_MEASURES = (
    "return",
    "cost",
    *_TERM_COSTS,
    "path_error_rms",
    "path_error_max",
    "heading_error_rms",
    "coordination_error_rms",
    "speed_error_rms",
    "speed_estimate_error_rms",
    "control_energy",
    "saturated_fraction",
)
#: Every per-episode metric, in the column order of ``episodes.csv``.
METRICS: tuple[str, ...] = (
    *_MEASURES,
    "coordination_error_end",
    *(f"{name}_window" for name in _MEASURES),
    "terminated",
    "steps",
)

Array = NDArray[np.float64]


def _reduce(series: dict[str, Array], mask: NDArray[np.bool_], dt: float) -> dict[str, Array]:
    """Metrics over the steps in ``mask`` (S, T) of per-step series of shape (S, T).

    Every reduction runs along the contiguous last axis, so fleet k's numbers
    do not depend on how many fleets ran beside it.
    """
    count = np.maximum(mask.sum(axis=1), 1)

    def total(x: Array) -> Array:
        return np.where(mask, x, 0.0).sum(axis=1)

    def rms(x: Array) -> Array:
        return np.sqrt(total(x**2) / count)

    return {
        "return": total(series["reward"]),
        "cost": -total(series["reward"]),
        **{name: -total(series[name]) for name in _TERM_COSTS},
        "path_error_rms": np.sqrt(total(series["path_error_sq"]) / count),
        "path_error_max": np.where(mask, series["path_error_max"], 0.0).max(axis=1),
        "heading_error_rms": np.sqrt(total(series["heading_error_sq"]) / count),
        "coordination_error_rms": rms(series["spread"]),
        "speed_error_rms": np.sqrt(total(series["speed_error_sq"]) / count),
        "speed_estimate_error_rms": np.sqrt(total(series["estimate_error_sq"]) / count),
        "control_energy": dt * total(series["energy"]),
        "saturated_fraction": total(series["saturated"]) / count,
    }


#: Per-step series recorded for every fleet, each (S, T).
_SERIES = (
    "reward",
    *_TERM_COSTS,
    "path_error_sq",
    "path_error_max",
    "heading_error_sq",
    "speed_error_sq",
    "estimate_error_sq",
    "spread",
    "energy",
    "saturated",
)


def _record(
    series: dict[str, Array], t: int, sim: FleetSim, estimate: Array | None, v0: float
) -> None:
    """Write step t's fleet means (over vessels) into column t of every series."""
    a = sim.arrays
    errors = a.errors
    series["reward"][:, t] = a.reward.mean(axis=1)
    for k, name in enumerate(_TERM_COSTS):
        series[name][:, t] = a.reward_terms[:, :, k].mean(axis=1)
    series["path_error_sq"][:, t] = (errors[..., arrays.ERR_PATH] ** 2).mean(axis=1)
    series["path_error_max"][:, t] = errors[..., arrays.ERR_PATH].max(axis=1)
    series["heading_error_sq"][:, t] = (errors[..., arrays.ERR_HEADING] ** 2).mean(axis=1)
    series["speed_error_sq"][:, t] = (errors[..., arrays.ERR_SPEED] ** 2).mean(axis=1)
    series["spread"][:, t] = a.theta.max(axis=1) - a.theta.min(axis=1)
    force = a.tau_applied / sim.constants.tau_scale
    series["energy"][:, t] = (force**2).sum(axis=2).mean(axis=1)
    series["saturated"][:, t] = (a.tau_command != a.tau_applied).any(axis=2).mean(axis=1)
    if estimate is not None:
        series["estimate_error_sq"][:, t] = ((np.asarray(estimate) - v0) ** 2).mean(axis=1)


def run_episodes(
    policy: BenchPolicy,
    scenario: Scenario,
    seeds: Sequence[int],
    steps: int | None = None,
    progress: tqdm | None = None,
) -> dict[str, Array]:
    """Run S episodes of ``policy`` on ``scenario`` in one batch and measure each.

    Args:
        policy: A policy built for ``scenario`` (reset here).
        scenario: The task.
        seeds: Reset seed of each fleet, length S.
        steps: Horizon in control steps (default: the scenario's ``max_steps``).
        progress: A progress bar advanced by one per step, or None.

    Returns:
        Metric name (``METRICS``) -> values, shape (S,); ``speed_estimate_error_rms*``
        are NaN for a policy without a ``speed_estimate`` diagnostic.
    """
    horizon = scenario.max_steps if steps is None else int(steps)
    if horizon < 1:
        raise ValueError(f"steps must be >= 1, got {steps}.")
    sim = FleetSim(scenario, num_fleets=len(seeds))
    policy.reset()
    obs = sim.reset(seeds=list(seeds))
    a, S = sim.arrays, sim.num_fleets
    series = {name: np.zeros((S, horizon)) for name in _SERIES}
    has_estimate = True
    alive = np.ones(S, dtype=bool)
    failed = np.zeros(S, dtype=bool)
    end = np.full(S, horizon)
    for t in range(horizon):
        actions = np.array(policy.act_batch(obs), dtype=np.float64)
        estimate = policy.diagnostics.get("speed_estimate")
        v0 = sim.v0_at(t * scenario.dt)
        actions[~alive] = 0.0
        obs = sim.step(actions)
        _record(series, t, sim, estimate, v0)
        has_estimate = has_estimate and estimate is not None
        now = alive & a.terminated
        failed |= now
        end[now] = t + 1
        alive &= ~now
        if progress is not None:
            progress.update(1)
        if not alive.any():
            if progress is not None:
                progress.update(horizon - t - 1)
            break
    time = np.arange(horizon)[None, :]
    counted = time < end[:, None]
    start = horizon - max(1, round(WINDOW_FRACTION * horizon))
    window = counted & (time >= np.minimum(start, end - 1)[:, None])
    metrics = _reduce(series, counted, scenario.dt)
    metrics.update({f"{k}_window": v for k, v in _reduce(series, window, scenario.dt).items()})
    metrics["coordination_error_end"] = series["spread"][np.arange(S), end - 1]
    if not has_estimate:
        for name in ("speed_estimate_error_rms", "speed_estimate_error_rms_window"):
            metrics[name] = np.full(S, np.nan)
    metrics["terminated"] = failed.astype(np.float64)
    metrics["steps"] = end.astype(np.float64)
    return {name: metrics[name] for name in METRICS}
