"""Delay-compensated consensus: neighbour path variables predicted forward by their age.

Under a lossy or delayed link, vessel i holds theta_j as it was sent
``age_ij`` control steps ago; the paper's consensus [34] uses it as if it
were current, so every stale packet reads as a lag of about
``age_ij dt theta_j'``. These policies advance each received value by its
age, using the speed estimate vhat_j that neighbour j communicated in the
same packet (its message, eq. [35]),

    (theta_j - theta_i)_compensated = (theta_j - theta_i)_received + age_ij dt vhat_j,

and otherwise run the unchanged controller. The information is the same
local observation (weight, theta difference, age and message of each slot);
nothing is learned. With no delay and no loss every age is 0 and the
policies act exactly as their uncompensated parents.

==============================  ===============================================
``nn_dsc_delay_comp``           ``nn_dsc`` with the compensated theta differences
``backstepping_delay_comp``     ``backstepping`` with the compensated theta differences
==============================  ===============================================
"""

from __future__ import annotations

import dataclasses

from baselines.backstepping import BacksteppingPolicy
from baselines.cooperative import LocalObservation
from baselines.nn_dsc import NNDSCPolicy
from baselines.policy import Array, Policy

__all__ = ["BacksteppingDelayCompensated", "NNDSCDelayCompensated", "compensate_delay"]


def compensate_delay(local: LocalObservation, ages: Array, dt: float) -> LocalObservation:
    """Advance every received theta_j by its age times the neighbour's communicated speed.

    Args:
        local: The parsed local observations (B, n, ...).
        ages: (B, n, K) steps since each slot's value was sent.
        dt: Control period (s).

    Returns:
        A copy of ``local`` with ``dtheta`` (B, n, K) replaced by
        ``dtheta + ages * dt * message`` (message = vhat_j, m/s).
    """
    return dataclasses.replace(local, dtheta=local.dtheta + ages * dt * local.message)


class _DelayCompensation(Policy):
    """Mixin: the cooperative layer sees age-compensated theta differences."""

    def _local(self, batch: Array) -> LocalObservation:
        local = super()._local(batch)
        return compensate_delay(local, self.layout.slot_ages(batch), self.dt)


class NNDSCDelayCompensated(_DelayCompensation, NNDSCPolicy):
    """``nn_dsc`` with each neighbour's theta advanced by its packet age (``compensate_delay``)."""

    name = "nn_dsc_delay_comp"


class BacksteppingDelayCompensated(_DelayCompensation, BacksteppingPolicy):
    """``backstepping`` with each neighbour's theta advanced by its packet age."""

    name = "backstepping_delay_comp"
