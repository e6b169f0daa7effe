"""The one rollout of the commands: policies on S fleets each, measured step by step.

``rollout_group`` runs P policies on one scenario for the same S seeds at
once, policy p on its own block of S fleets, fleet k of every block reset
with seed k. The policies go into at most two batched simulators:

* the compiled ones (``baselines.closed_loop.ClosedLoop.supports``: the
  analytic baselines and the privileged references) into one
  ``FleetSim`` stepped by ``ClosedLoop.run``, ``CHUNK`` control steps per
  compiled call, every step written to the metrics' record in compiled code;
* all others (trained agents, kinetic parts written in Python, and every
  policy when an ``observer`` watches) into one ``FleetSim`` stepped from
  Python: each policy's ``act_batch`` on its block, one simulator step and
  one metrics record per control step for all of them. A privileged
  reference stepped here (``bind_simulator``) is bound to its simulator and
  fleets.

A fleet's numbers do not depend on the other fleets in the batch nor on the
simulator it runs in (the simulator, the analytic policies and the metrics
work per fleet, and the compiled loop calls the functions the Python path
calls), so each policy's results are those of a run of its own, bit for bit.
``rollout`` is the group of one policy. Fleets are not reset when they
terminate: a fleet that leaves its path is masked from then on (its later
steps do not count, its actions are replaced by zeros so the simulator
stays finite) and its failure flag and step are recorded. A simulator stops
once all its fleets have failed. Every step is measured by
``cpf_env.evaluation.fleet_metrics.FleetMetrics`` after the step; an optional
``observer`` sees the simulator before and after each step (``cpf-run``
records its trajectory that way). ``cpf-bench`` and ``cpf-run`` both step
through here, so their metrics are the same numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, cast

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from baselines.closed_loop import ClosedLoop
from baselines.policy import AnalyticPolicy
from cpf_env.envs.policy import FleetPolicy
from cpf_env.evaluation.fleet_metrics import FleetMetrics
from cpf_env.evaluation.recording import CHUNK
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

__all__ = ["StepObserver", "rollout", "rollout_group"]


class StepObserver(Protocol):
    """Sees every step of a rollout (e.g. to record a trajectory)."""

    def before(self, sim: FleetSim, actions: NDArray[np.float64], policy: FleetPolicy) -> None:
        """Called with the state at t_k and the actions the policy chose for it."""

    def after(self, sim: FleetSim) -> None:
        """Called with the state after the step."""


def rollout(
    policy: FleetPolicy,
    scenario: Scenario,
    seeds: Sequence[int | None],
    max_steps: int | None = None,
    progress: tqdm | None = None,
    observer: StepObserver | None = None,
    policy_seed: int | None = None,
) -> dict[str, NDArray[np.float64]]:
    """Run S episodes of ``policy`` on ``scenario`` in one batch and measure each.

    Args:
        policy: A policy built for ``scenario`` (reset here, with ``policy_seed``).
        scenario: The task.
        seeds: Reset seed of each fleet, length S.
        max_steps: Horizon in control steps (default: the scenario's ``max_steps``).
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
    return rollout_group([policy], scenario, seeds, max_steps, progress, observer, policy_seed)[0]


def rollout_group(
    policies: Sequence[FleetPolicy],
    scenario: Scenario,
    seeds: Sequence[int | None],
    max_steps: int | None = None,
    progress: tqdm | None = None,
    observer: StepObserver | None = None,
    policy_seed: int | None = None,
) -> list[dict[str, NDArray[np.float64]]]:
    """Run S episodes of each of P policies on ``scenario`` in one batch and measure each.

    Args:
        policies: Policies built for ``scenario`` (each reset here, with ``policy_seed``).
        scenario: The task.
        seeds: Reset seed of each policy's fleets, length S (the same for every policy).
        max_steps: Horizon in control steps (default: the scenario's ``max_steps``).
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
    horizon = scenario.max_steps if max_steps is None else int(max_steps)
    if horizon < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}.")
    if not policies or (observer is not None and len(policies) > 1):
        raise ValueError("rollout_group needs at least one policy, and one only with an observer.")
    compiled = [observer is None and ClosedLoop.supports(policy) for policy in policies]
    setup = (scenario, seeds, horizon, policy_seed)
    batches = {
        wanted: kind([p for p, c in zip(policies, compiled, strict=True) if c == wanted], *setup)
        for kind, wanted in ((_CompiledBatch, True), (_SteppedBatch, False))
        if wanted in compiled
    }
    t = 0
    while t < horizon and any(batch.alive.any() for batch in batches.values()):
        rows = min(CHUNK, horizon - t)
        for batch in batches.values():
            if batch.alive.any():
                batch.advance(t, rows, observer)
        t += rows
        if progress is not None:
            progress.update(rows)
    if progress is not None and t < horizon:
        progress.update(horizon - t)
    measured = {wanted: iter(batch.metrics()) for wanted, batch in batches.items()}
    return [next(measured[wanted]) for wanted in compiled]


class _Batch:
    """P policies on S fleets each in one simulator, measured step by step.

    AnalyticPolicy p acts on fleets p S .. (p + 1) S - 1; fleet p S + k is reset with
    seed k. ``ended`` holds the step at which each fleet left its path, -1
    while it has not.
    """

    def __init__(
        self,
        policies: Sequence[FleetPolicy],
        scenario: Scenario,
        seeds: Sequence[int | None],
        horizon: int,
        policy_seed: int | None,
    ) -> None:
        S = len(seeds)
        self.policies = list(policies)
        self.horizon = horizon
        self.sim = FleetSim(scenario, num_fleets=len(policies) * S)
        self.sim.reset(seeds=list(seeds) * len(policies))
        self.blocks = [slice(p * S, (p + 1) * S) for p in range(len(policies))]
        for policy in policies:
            policy.reset(seed=policy_seed)
        self.meter = FleetMetrics(self.sim, horizon)
        self.meter.start(self.sim.arrays)
        self.ended = np.full(self.sim.num_fleets, -1, dtype=np.int64)
        self._prepare()

    def _prepare(self) -> None:
        """Bind the policies to the simulator (after their reset)."""

    @property
    def alive(self) -> NDArray[np.bool_]:
        """(P S,) fleets that have not left their path."""
        return self.ended < 0

    def advance(self, t: int, rows: int, observer: StepObserver | None) -> None:
        """Steps t .. t + rows - 1 of every fleet (a batch whose fleets all ended may stop)."""
        raise NotImplementedError

    def metrics(self) -> list[dict[str, NDArray[np.float64]]]:
        """Per policy, metric name -> values (S,)."""
        failed = self.ended >= 0
        end = np.where(failed, self.ended, self.horizon)
        measured = self.meter.reduce(end, failed)
        return [{name: values[block] for name, values in measured.items()} for block in self.blocks]


class _SteppedBatch(_Batch):
    """Any policies, stepped from Python: ``act_batch`` of each, then one simulator step."""

    def _prepare(self) -> None:
        for policy, block in zip(self.policies, self.blocks, strict=True):
            bind = getattr(policy, "bind_simulator", None)
            if bind is not None:
                bind(self.sim, np.arange(block.start, block.stop))
        self._actions = np.zeros((self.sim.num_fleets, self.sim.n, self.sim.act_dim))
        self._estimate = np.full((self.sim.num_fleets, self.sim.n), np.nan)

    def advance(self, t: int, rows: int, observer: StepObserver | None) -> None:
        sim, a, actions = self.sim, self.sim.arrays, self._actions
        for step in range(t, t + rows):
            for policy, block in zip(self.policies, self.blocks, strict=True):
                actions[block] = policy.act_batch(a.obs[block])
                found = policy.diagnostics.get("speed_estimate")
                if found is not None:
                    self._estimate[block] = found
            actions[~self.alive] = 0.0
            if observer is not None:
                observer.before(sim, actions, self.policies[0])
            sim.step(actions)
            if observer is not None:
                observer.after(sim)
            self.meter.record(step, a, sim.v0_at(step * sim.scenario.dt), self._estimate)
            self.ended[self.alive & a.terminated] = step + 1
            if not self.alive.any():
                return


class _CompiledBatch(_Batch):
    """Compiled analytic policies (``ClosedLoop.supports``): ``rows`` steps of all in one call."""

    def _prepare(self) -> None:
        self.loop = ClosedLoop(cast("list[AnalyticPolicy]", self.policies), self.sim)
        self.ended = self.loop.ended

    def advance(self, t: int, rows: int, observer: StepObserver | None) -> None:
        del observer  # a rollout with an observer steps from Python
        self.loop.run(rows, hold_ended=True, record=self.meter.buffer(self.sim.arrays))
        dt = self.sim.scenario.dt
        self.meter.commit(t, np.array([self.sim.v0_at(k * dt) for k in range(t, t + rows)]))
