"""Traditional backstepping with the analytic derivative of the virtual control.

The design the paper's Remark 1 compares against: no DSC filter; the
derivative of the virtual control alpha_i = -K1 z_i1 + t_i1 vhat_i [15] is
computed analytically,

    alpha_i' = -K1 z_i1' + t_i1' vhat_i + t_i1 vhat_i'
    z_i1'    = -r_i S z_i1 + nu_i - t_i1 theta_i'       [13]
    t_i1'    = -r_i S t_i1 + t_i2 theta_i'              (from d/dt J^T = -r S J^T, [14])

with S = [[0, -1, 0], [1, 0, 0], [0, 0, 0]], t_i2 = J^T eta_di^theta2,
theta_i' the commanded rate and vhat_i' the estimator's rate [35], and the
force cancels the NOMINAL model (``Scenario.vessel_models``):

    z_i2 = nu_i - alpha_i
    tau_i0 = M alpha_i' + C(nu_i) nu_i + D(nu_i) nu_i - K2 z_i2 - z_i1

No NN, no auxiliary system; the cooperative layer is the paper's. The
unmodeled dynamics and disturbances are left to the feedback.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from baselines.gains import BacksteppingGains
from baselines.kernel_types import KINETICS_BACKSTEPPING
from baselines.policy import AnalyticPolicy

__all__ = ["BacksteppingPolicy"]


class BacksteppingPolicy(AnalyticPolicy):
    """Backstepping with the analytic alpha_dot and nominal-model cancellation (Remark 1).

    The equations above run compiled (``baselines.kernels``); the
    diagnostic "nubar_dot" holds alpha_dot (there is no filter).

    Args:
        env: A ParallelEnv, FleetSim, Scenario or scenario name.
        **options: Any field of ``BacksteppingGains`` (K1, K2, k3..k6).
    """

    name = "backstepping"
    gains_type = BacksteppingGains
    kinetics = KINETICS_BACKSTEPPING

    def _kinetic_constants(self) -> dict[str, Any]:
        """K1, K2 and the nominal models (mass matrices, hydrodynamic parameters)."""
        g = cast(BacksteppingGains, self.gains)
        models = self.scenario.vessel_models
        return {
            "k1": np.array(g.K1),
            "k2": np.array(g.K2),
            "mass": np.stack([model.mass_matrix() for model in models]),  # (n, 3, 3)
            "hydro_params": np.stack([model.to_params() for model in models]),  # (n, P)
        }
