"""The one rollout of the commands: a policy on S fleets, measured step by step.

``rollout`` runs one policy on one scenario for S seeds at once: one
``FleetSim(num_fleets=S)``, fleet k reset with seed k, the policy's
``act_batch`` on all fleets every step. Fleets are not reset when they
terminate: a fleet that leaves its path is masked from then on (its later
steps do not count, its actions are replaced by zeros so the simulator
stays finite) and its failure flag and step are recorded. The run stops
when every fleet has failed. Every step is measured by
``cpf_env.sim.fleet_metrics.FleetMetrics`` after the step; an optional
``observer`` sees the simulator before and after each step (``cpf-run``
records its trajectory that way). ``cpf-bench`` and ``cpf-run`` both step
through here, so their metrics are the same numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from cpf_commands.common.policies import BenchPolicy
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.fleet_metrics import FleetMetrics

__all__ = ["StepObserver", "rollout"]


class StepObserver(Protocol):
    """Sees every step of a rollout (e.g. to record a trajectory)."""

    def before(self, sim: FleetSim, actions: NDArray[np.float64], policy: BenchPolicy) -> None:
        """Called with the state at t_k and the actions the policy chose for it."""

    def after(self, sim: FleetSim) -> None:
        """Called with the state after the step."""


def rollout(
    policy: BenchPolicy,
    scenario: Scenario,
    seeds: Sequence[int | None],
    steps: int | None = None,
    progress: tqdm | None = None,
    observer: StepObserver | None = None,
    policy_seed: int | None = None,
) -> dict[str, NDArray[np.float64]]:
    """Run S episodes of ``policy`` on ``scenario`` in one batch and measure each.

    Args:
        policy: A policy built for ``scenario`` (reset here, with ``policy_seed``).
        scenario: The task.
        seeds: Reset seed of each fleet, length S.
        steps: Horizon in control steps (default: the scenario's ``max_steps``).
        progress: A progress bar advanced by one per step, or None.
        observer: Called before and after every step, or None.
        policy_seed: Seed passed to ``policy.reset``.

    Returns:
        Metric name (``fleet_metrics.METRICS``) -> values, shape (S,);
        ``speed_estimate_error_rms*`` are NaN for a policy without a
        ``speed_estimate`` diagnostic.

    Raises:
        ValueError: A horizon below one step.
    """
    horizon = scenario.max_steps if steps is None else int(steps)
    if horizon < 1:
        raise ValueError(f"steps must be >= 1, got {steps}.")
    sim = FleetSim(scenario, num_fleets=len(seeds))
    policy.reset(seed=policy_seed)
    obs = sim.reset(seeds=list(seeds))
    a, S = sim.arrays, sim.num_fleets
    meter = FleetMetrics(sim, horizon)
    meter.start(a)
    alive = np.ones(S, dtype=bool)
    failed = np.zeros(S, dtype=bool)
    end = np.full(S, horizon)
    for t in range(horizon):
        actions = np.array(policy.act_batch(obs), dtype=np.float64)
        estimate = policy.diagnostics.get("speed_estimate")
        v0 = sim.v0_at(t * scenario.dt)
        actions[~alive] = 0.0
        if observer is not None:
            observer.before(sim, actions, policy)
        obs = sim.step(actions)
        if observer is not None:
            observer.after(sim)
        meter.record(t, a, v0, estimate)
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
    return meter.reduce(end, failed)
