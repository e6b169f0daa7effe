"""Delay-compensated consensus: neighbour path variables predicted forward by their age.

Under a lossy or delayed link, vessel i holds theta_j as it was sent
``age_ij`` control steps ago; the paper's consensus [34] uses it as if it
were current, so every stale packet reads as a lag of about
``age_ij dt theta_j'``. These policies advance each received value by its
age, using the speed estimate vhat_j that neighbour j communicated in the
same packet (its message, eq. [35]),

    (theta_j - theta_i)_compensated = (theta_j - theta_i)_received + age_ij dt vhat_j,

and otherwise run the unchanged controller (the compiled cooperative layer,
``baselines.kernels``, applies it when ``AnalyticPolicy.delay_compensation`` is set).
The information is the same
local observation (weight, theta difference, age and message of each slot);
nothing is learned. With no delay and no loss every age is 0 and the
policies act exactly as their uncompensated parents.

==============================  ===============================================
``nn_dsc_delay_comp``           ``nn_dsc`` with the compensated theta differences
``backstepping_delay_comp``     ``backstepping`` with the compensated theta differences
==============================  ===============================================
"""

from __future__ import annotations

from baselines.backstepping import BacksteppingPolicy
from baselines.nn_dsc import NNDSCPolicy

__all__ = ["BacksteppingDelayCompensated", "NNDSCDelayCompensated"]


class NNDSCDelayCompensated(NNDSCPolicy):
    """``nn_dsc`` with each neighbour's theta advanced by its packet age."""

    name = "nn_dsc_delay_comp"
    delay_compensation = True


class BacksteppingDelayCompensated(BacksteppingPolicy):
    """``backstepping`` with each neighbour's theta advanced by its packet age."""

    name = "backstepping_delay_comp"
    delay_compensation = True
