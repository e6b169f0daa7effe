"""Analytic policies and the simulator stepped together in one compiled loop.

``ClosedLoop(policies, sim)`` binds P compiled analytic policies to a
simulator of P x S fleets, policy p acting on fleets p S .. (p + 1) S - 1
(a single policy acts on every fleet). ``run(steps)`` then advances every
fleet by ``steps`` control periods with one compiled call per policy: per
fleet and step, its policy acts on the fleet's observation
(``baselines.kernels``) and the simulator steps the fleet
(``cpf_env.sim.kernels.step_fleet``). These are the functions the per-step
path ``sim.step(policy.act_batch(obs))`` runs, on the same numbers, so the
trajectories, the policies' states and their outputs are the same bit for
bit (tested); what goes is the Python between the steps: validation,
allocation, the kernel dispatches of every policy and simulator step, and
the threads' wake-up at every one of them. Each fleet runs all its steps on
one thread; a call spreads the S fleets of its policy over numba's threads
once S x steps reaches ``PARALLEL_MIN_FLEETS`` (S > 1).

For evaluation (``cpf-bench``, ``cpf_bench.rollout``) a run can
also

* hold a fleet that has left its path (``terminated``) at zero actions from
  the step after, noting the step it left at (``ended``), and
* write every step into a ``cpf_env.evaluation.recording.StepRecord``, row k for
  step k of the call, as ``FleetMetrics.record`` does from Python.

Only policies whose whole step is compiled qualify (``supports``): those with
a compiled kinetic part that act on their observation alone, and the
privileged references of ``baselines.privileged``, whose ideal-link
observations and true lumped uncertainty the loop reads from the simulator
with the compiled functions of ``cpf_env.evaluation.privileged``. A kinetic part
written in Python or a trained agent take the per-step path.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from numba import prange
from numpy.typing import NDArray

from baselines.kernel_types import (
    KINETICS_PYTHON,
    NO_KNOWLEDGE,
    KnownDynamics,
    PolicyConstants,
    PolicyOutputs,
    PolicyStates,
)
from baselines.kernels import WORK_ROWS, _act_fleet
from baselines.policy import DIAGNOSTICS, AnalyticPolicy
from baselines.privileged import PrivilegedPolicy
from cpf_env.envs.policy import FleetPolicy
from cpf_env.evaluation.privileged import fleet_ideal_observations, fleet_lumped_uncertainty
from cpf_env.evaluation.recording import CHUNK, StepRecord, new_record, record_fleet
from cpf_env.sim.arrays import FleetArrays, KernelConstants
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.kernels import step_fleet
from cpf_env.sim.threads import PARALLEL_MIN_FLEETS

__all__ = ["ClosedLoop"]


@numba.njit(cache=True)
def _run_fleet(
    a: FleetArrays,
    c: KernelConstants,
    pc: PolicyConstants,
    ps: PolicyStates,
    out: PolicyOutputs,
    obs: np.ndarray,
    known: KnownDynamics,
    actions: np.ndarray,
    rows: np.ndarray,
    b: int,
    r: int,
    steps: int,
    hold_ended: bool,
    ended: np.ndarray,
    record: StepRecord,
) -> None:
    """Fleet b, row r of the policy (``pc``, ``ps``, ``out``, ``obs``): ``steps`` closed-loop steps.

    ``rows`` is 0 .. S - 1; ``known`` has S rows for a privileged reference.
    Stops early when the fleet's plant diverges (``a.nonfinite``); ``ended[b]``
    is the step fleet b left its path at, -1 while it has not.
    """
    work = np.empty((WORK_ROWS, 3))
    sigma = np.empty(pc.input_weights.shape[0])
    recording = record.eta.shape[0] > 0
    for k in range(steps):
        if pc.privileged:  # told the truth, as PrivilegedPolicy reads it from the simulator
            fleet_ideal_observations(a, c, b, obs[r])
            fleet_lumped_uncertainty(a, c, b, known.lumped[r], known.mass[r])
        else:
            for i in range(obs.shape[1]):
                for q in range(obs.shape[2]):
                    obs[r, i, q] = a.obs[b, i, q]  # float32 -> float64, as act_batch converts
        _act_fleet(pc, ps, obs, rows, known, out, r, work, sigma)
        held = hold_ended and ended[b] >= 0
        for i in range(actions.shape[1]):
            for q in range(actions.shape[2]):
                actions[b, i, q] = 0.0 if held else out.actions[r, i, q]
        step_fleet(a, c, actions, b)
        if a.nonfinite[b]:
            return
        if recording:
            record_fleet(a, record, k, b, out.speed_estimate[r])
        if ended[b] < 0 and a.terminated[b]:
            ended[b] = a.step[b]


@numba.njit(cache=True, parallel=True)
def _run_parallel(
    a: FleetArrays,
    c: KernelConstants,
    pc: PolicyConstants,
    ps: PolicyStates,
    out: PolicyOutputs,
    obs: np.ndarray,
    known: KnownDynamics,
    actions: np.ndarray,
    rows: np.ndarray,
    first: int,
    steps: int,
    hold_ended: bool,
    ended: np.ndarray,
    record: StepRecord,
) -> None:
    """``_run_fleet`` for fleets ``first`` .. ``first + S - 1`` of one policy, on numba's threads.

    The same bits as one fleet after the other (``_run``). The loop index is made
    int64, as ``_run``'s: prange's is uint64, which would compile ``_run_fleet`` (the
    largest kernel of the package) a second time for that type alone.
    """
    for index in prange(rows.shape[0]):
        r = int(np.int64(index))  # int() alone would keep the uint64
        _run_fleet(
            a, c, pc, ps, out, obs, known, actions, rows, first + r, r, steps, hold_ended, ended,
            record,
        )  # fmt: skip


@numba.njit(cache=True)
def _run(
    a: tuple,
    c: tuple,
    pc: tuple,
    ps: tuple,
    out: tuple,
    obs: np.ndarray,
    known: tuple,
    actions: np.ndarray,
    rows: np.ndarray,
    first: int,
    steps: int,
    hold_ended: bool,
    ended: np.ndarray,
    record: tuple,
    threaded: bool,
) -> None:
    """``_run_fleet`` for the S fleets of one policy, on numba's threads if ``threaded``.

    The arguments are ``_run_parallel``'s, the named tuples as plain tuples of their
    fields: numba's dispatcher types plain tuples of arrays on a fast path and named
    tuples field by field in Python (``baselines.kernels.act_rows``); the
    named tuples are rebuilt here, in compiled code.
    """
    fa, fc = FleetArrays(*a), KernelConstants(*c)
    qc, qs, qo = PolicyConstants(*pc), PolicyStates(*ps), PolicyOutputs(*out)
    qk, qr = KnownDynamics(*known), StepRecord(*record)
    if threaded:
        _run_parallel(
            fa, fc, qc, qs, qo, obs, qk, actions, rows, first, steps, hold_ended, ended, qr
        )
        return
    for r in range(rows.shape[0]):
        _run_fleet(
            fa, fc, qc, qs, qo, obs, qk, actions, rows, first + r, r, steps, hold_ended, ended, qr
        )


class ClosedLoop:
    """Compiled analytic policies acting on equal blocks of a simulator's fleets, in one call.

    With P policies on B = P S fleets, policy p acts on fleets
    p S .. (p + 1) S - 1 and holds internal states for S fleets (its rows).
    Reset the simulator and the policies (``policy.reset()``) before the first
    run, as for the per-step path.

    Args:
        policies: One policy, or a sequence of them, for each of which
            ``ClosedLoop.supports`` holds, built for the simulator's scenario.
        sim: The simulator; its number of fleets a multiple of P.

    Attributes:
        ended: (B,) int64, the step at which each fleet left its path, -1 while it
            has not (``run`` updates it).

    Raises:
        ValueError: A policy that does not qualify or does not fit the scenario, or
            a number of fleets that is not a multiple of P.
    """

    def __init__(self, policies: FleetPolicy | Sequence[FleetPolicy], sim: FleetSim) -> None:
        given = [policies] if isinstance(policies, FleetPolicy) else list(policies)
        if not given:
            raise ValueError("ClosedLoop needs at least one policy.")
        for policy in given:
            if not self.supports(policy):
                raise ValueError(
                    "ClosedLoop runs analytic policies whose whole step is compiled; "
                    f"{type(policy).__name__} is not one (a kinetic part in Python, a "
                    "privileged reference or another kind of policy): step it with "
                    "sim.step(policy.act_batch(obs))."
                )
        members = [
            policy for policy in given if isinstance(policy, AnalyticPolicy)
        ]  # all, by supports
        for policy in members:
            if policy.scenario.n != sim.n or policy.obs_dim != sim.obs_dim:
                raise ValueError(
                    f"policy {policy.name!r} was built for scenario {policy.scenario.name!r}, "
                    f"which does not fit the simulator's {sim.scenario.name!r} (vessels or "
                    "observation layout differ)."
                )
        if len({id(policy) for policy in members}) < len(members):
            raise ValueError(
                "a policy object appears twice; build one per block (its internal states "
                "belong to one block of fleets)."
            )
        if sim.num_fleets % len(members):
            raise ValueError(
                f"{len(members)} policies need a number of fleets divisible by "
                f"{len(members)}; the simulator has {sim.num_fleets}."
            )
        self.policies, self.sim = members, sim
        S = sim.num_fleets // len(members)
        self.ended = np.full(sim.num_fleets, -1, dtype=np.int64)
        self._rows = np.arange(S, dtype=np.int64)
        self._observations = tuple(np.zeros((S, sim.n, sim.obs_dim)) for _ in members)
        self._knowledge = tuple(
            KnownDynamics(np.zeros((S, sim.n, 3)), np.zeros((S, sim.n, 3, 3)))
            if policy.privileged
            else NO_KNOWLEDGE
            for policy in members
        )
        self._actions = np.zeros((sim.num_fleets, sim.n, sim.act_dim))
        self._no_record = new_record(sim.arrays, rows=0)

    @staticmethod
    def supports(policy: object) -> bool:
        """True for a compiled ``AnalyticPolicy`` acting on its observation alone, or privileged."""
        if not isinstance(policy, AnalyticPolicy) or policy.kinetics == KINETICS_PYTHON:
            return False
        if isinstance(policy, PrivilegedPolicy):  # the kernel reads what it is told itself
            return True
        return (
            not policy.privileged
            and type(policy)._observations is AnalyticPolicy._observations
            and type(policy)._knowledge is AnalyticPolicy._knowledge
        )

    @property
    def live(self) -> NDArray[np.bool_]:
        """(B,) True for the fleets that have not left their path."""
        return self.ended < 0

    def run(self, steps: int, hold_ended: bool = False, record: StepRecord | None = None) -> None:
        """Advance every fleet by ``steps`` control periods, policies and simulator alike.

        Args:
            steps: Control periods (>= 1; at most ``CHUNK`` with a record).
            hold_ended: Give a fleet zero actions from the step after it left its
                path (``ended``), as ``cpf-bench`` does; its policy still acts.
            record: Where step k of this call goes (row k, every fleet), or None.

        Afterwards each policy's ``diagnostics`` are those of the last step.

        Raises:
            ValueError: ``steps`` out of range.
            RuntimeError: Running before ``sim.reset()``, or the plant diverged (the
                simulator's message names fleet, vessel and quantity).
        """
        steps = int(steps)
        if steps < 1 or (record is not None and steps > CHUNK):
            raise ValueError(f"steps must be >= 1 (at most {CHUNK} with a record), got {steps}.")
        sim = self.sim
        if not sim.started:
            raise RuntimeError("call sim.reset() before ClosedLoop.run().")
        if sim.arrays.nonfinite.any():
            raise RuntimeError(sim.divergence_message())
        S = self._rows.shape[0]
        threaded = S > 1 and S * steps >= PARALLEL_MIN_FLEETS
        fields = tuple(sim.arrays), tuple(sim.constants)
        written = tuple(self._no_record if record is None else record)
        for p, policy in enumerate(self.policies):
            out = policy._new_outputs(S)
            _run(
                *fields, tuple(policy._constants), tuple(policy._states_for(S)), tuple(out),
                self._observations[p], tuple(self._knowledge[p]), self._actions, self._rows,
                p * S, steps, bool(hold_ended), self.ended, written, threaded,
            )  # fmt: skip
            policy.diagnostics = {name: getattr(out, name) for name in DIAGNOSTICS}
        if sim.arrays.nonfinite.any():
            raise RuntimeError(sim.divergence_message())
