"""The one rollout of the commands: policies on S fleets each, measured step by step.

``rollout_group`` runs P policies on one scenario for the same S seeds at
once: one ``FleetSim(num_fleets=P S)``, policy p acting on fleets
p S .. (p + 1) S - 1 (its ``act_batch`` on its S fleets every step), fleet
p S + k reset with seed k. A fleet's numbers do not depend on the other
fleets in the batch (the simulator, the analytic policies and the metrics
reduce per fleet), so each policy's results are those of a run of its own,
bit for bit; one batch costs one simulator step and one metrics record per
control step for all policies instead of one each. ``rollout`` is the group
of one policy. A privileged reference (``bind_simulator``) is bound to the
simulator and its fleets. Fleets are not reset when they
terminate: a fleet that leaves its path is masked from then on (its later
steps do not count, its actions are replaced by zeros so the simulator
stays finite) and its failure flag and step are recorded. The run stops
when every fleet of the batch has failed. Every step is measured by
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

__all__ = ["StepObserver", "rollout", "rollout_group"]


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
    return rollout_group([policy], scenario, seeds, steps, progress, observer, policy_seed)[0]


def rollout_group(
    policies: Sequence[BenchPolicy],
    scenario: Scenario,
    seeds: Sequence[int | None],
    steps: int | None = None,
    progress: tqdm | None = None,
    observer: StepObserver | None = None,
    policy_seed: int | None = None,
) -> list[dict[str, NDArray[np.float64]]]:
    """Run S episodes of each of P policies on ``scenario`` in one batch and measure each.

    Args:
        policies: Policies built for ``scenario`` (each reset here, with ``policy_seed``).
        scenario: The task.
        seeds: Reset seed of each policy's fleets, length S (the same for every policy).
        steps: Horizon in control steps (default: the scenario's ``max_steps``).
        progress: A progress bar advanced by one per step, or None.
        observer: Called before and after every step (one policy only), or None.
        policy_seed: Seed passed to each ``policy.reset``.

    Returns:
        Per policy, metric name (``fleet_metrics.METRICS``) -> values, shape (S,);
        ``speed_estimate_error_rms*`` are NaN for a policy without a
        ``speed_estimate`` diagnostic.

    Raises:
        ValueError: A horizon below one step, no policy, or an observer with several.
    """
    horizon = scenario.max_steps if steps is None else int(steps)
    if horizon < 1:
        raise ValueError(f"steps must be >= 1, got {steps}.")
    if not policies or (observer is not None and len(policies) > 1):
        raise ValueError("rollout_group needs at least one policy, and one only with an observer.")
    S = len(seeds)
    sim = FleetSim(scenario, num_fleets=len(policies) * S)
    obs = sim.reset(seeds=list(seeds) * len(policies))
    blocks = [slice(p * S, (p + 1) * S) for p in range(len(policies))]
    for policy, block in zip(policies, blocks, strict=True):
        policy.reset(seed=policy_seed)
        bind = getattr(policy, "bind_simulator", None)
        if bind is not None:
            bind(sim, np.arange(block.start, block.stop))
    a, B = sim.arrays, sim.num_fleets
    meter = FleetMetrics(sim, horizon)
    meter.start(a)
    alive = np.ones(B, dtype=bool)
    failed = np.zeros(B, dtype=bool)
    end = np.full(B, horizon)
    actions = np.zeros((B, sim.n, sim.act_dim))
    estimate = np.full((B, sim.n), np.nan)
    for t in range(horizon):
        for policy, block in zip(policies, blocks, strict=True):
            actions[block] = policy.act_batch(obs[block])
            found = policy.diagnostics.get("speed_estimate")
            if found is not None:
                estimate[block] = found
        v0 = sim.v0_at(t * scenario.dt)
        actions[~alive] = 0.0
        if observer is not None:
            observer.before(sim, actions, policies[0])
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
    metrics = meter.reduce(end, failed)
    return [{name: values[block] for name, values in metrics.items()} for block in blocks]
