"""The per-step record the benchmark's metrics are computed from, and its compiled writer.

``FleetMetrics`` (``cpf_env.evaluation.fleet_metrics``) keeps the simulator arrays
of up to ``CHUNK`` steps in a ``StepRecord`` and turns them into its series
together. The record is filled either from Python, one step at a time
(``FleetMetrics.record``), or by a compiled loop that steps many control
periods per call (the analytic policies' evaluation path,
``baselines.closed_loop``), which calls ``record_fleet`` after each step of
each fleet. Both write the same values to the same places.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from cpf_env.sim.arrays import FleetArrays

__all__ = ["CHUNK", "RECORDED", "StepRecord", "new_record", "record_fleet"]

#: Steps recorded before they are turned into series together.
CHUNK = 64

#: ``FleetArrays`` fields a step's metrics are computed from, in ``StepRecord``'s order.
RECORDED = (
    "eta",
    "nu",
    "theta",
    "theta_dot",
    "errors",
    "reward",
    "reward_terms",
    "tau_applied",
    "tau_command",
)


class StepRecord(NamedTuple):
    """Up to ``CHUNK`` steps of B fleets; row k of every array is the state after one step.

    Each field but ``estimate`` is the ``FleetArrays`` field of that name with
    a leading axis of ``CHUNK`` rows, e.g. ``eta`` (CHUNK, B, n, 3).
    """

    eta: np.ndarray
    nu: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    errors: np.ndarray
    reward: np.ndarray
    reward_terms: np.ndarray
    tau_applied: np.ndarray
    tau_command: np.ndarray
    estimate: np.ndarray  # (CHUNK, B, n) the policy's speed estimate used at the step (m/s)


def new_record(a: FleetArrays, rows: int = CHUNK) -> StepRecord:
    """A zeroed record of ``rows`` steps for the arrays of ``a`` (0 rows: record nothing)."""
    fields = {name: np.zeros((rows, *np.shape(getattr(a, name)))) for name in RECORDED}
    return StepRecord(**fields, estimate=np.zeros((rows, *np.shape(a.theta))))


@numba.njit(cache=True)
def record_fleet(
    a: FleetArrays, record: StepRecord, row: int, b: int, estimate: np.ndarray
) -> None:
    """Copy fleet b's recorded arrays into ``row`` of ``record``; ``estimate`` (n,) m/s."""
    record.eta[row, b] = a.eta[b]
    record.nu[row, b] = a.nu[b]
    record.theta[row, b] = a.theta[b]
    record.theta_dot[row, b] = a.theta_dot[b]
    record.errors[row, b] = a.errors[b]
    record.reward[row, b] = a.reward[b]
    record.reward_terms[row, b] = a.reward_terms[b]
    record.tau_applied[row, b] = a.tau_applied[b]
    record.tau_command[row, b] = a.tau_command[b]
    record.estimate[row, b] = estimate
