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
from numpy.typing import NDArray

from baselines.cooperative import CooperativeStep, LocalObservation, contract
from baselines.gains import BacksteppingGains
from baselines.policy import Array, Policy, virtual_control
from cpf_env.model.vessel import coriolis_matrix, damping_matrix

__all__ = ["BacksteppingPolicy", "alpha_derivative"]


def _apply_s(x: Array) -> Array:
    """S x for S = [[0, -1, 0], [1, 0, 0], [0, 0, 0]], x of shape (..., 3)."""
    return np.stack([-x[..., 1], x[..., 0], np.zeros_like(x[..., 0])], axis=-1)


def alpha_derivative(
    k1: Array,
    obs: LocalObservation,
    theta_dot: Array,
    vhat: Array,
    vhat_dot: Array,
) -> Array:
    """Analytic time derivative of the virtual control [15] along the closed loop.

    Args:
        k1: Diagonal of K_i1, shape (3,) (1/s).
        obs: Local observations (uses nu, z1, t1, t2), (B, n, 3) each.
        theta_dot: (B, n) commanded path-variable rate (1/s).
        vhat: (B, n) speed estimate (m/s).
        vhat_dot: (B, n) its rate (m/s^2).

    Returns:
        alpha_i', shape (B, n, 3) (m/s^2, m/s^2, rad/s^2).
    """
    r = obs.nu[..., 2:3]
    z1_dot = -r * _apply_s(obs.z1) + obs.nu - obs.t1 * theta_dot[..., None]  # [13]
    t1_dot = -r * _apply_s(obs.t1) + obs.t2 * theta_dot[..., None]  # [14]
    return -k1 * z1_dot + t1_dot * vhat[..., None] + obs.t1 * vhat_dot[..., None]


class BacksteppingPolicy(Policy):
    """Backstepping with the analytic alpha_dot and nominal-model cancellation (Remark 1).

    Args:
        env: A ParallelEnv, FleetSim, Scenario or scenario name.
        **options: Any field of ``BacksteppingGains`` (K1, K2, k3..k6).
    """

    name = "backstepping"
    gains_type = BacksteppingGains

    def __init__(self, env: object, **options: Any) -> None:
        super().__init__(env, **options)
        g = cast(BacksteppingGains, self.gains)
        self._k1, self._k2 = np.array(g.K1), np.array(g.K2)
        models = self.scenario.vessel_models
        self._mass = np.stack([model.mass_matrix() for model in models])  # (n, 3, 3)
        self._params = np.stack([model.to_params() for model in models])  # (n, P)

    def _kinetic_states(self) -> dict[str, tuple[int, ...]]:
        """No kinetic states: alpha_dot is analytic."""
        return {}

    def _kinetics(
        self,
        obs: LocalObservation,
        cooperation: CooperativeStep,
        states: dict[str, Array],
        started: NDArray[np.bool_],
    ) -> tuple[Array, dict[str, Array]]:
        """Command tau_i0 = M alpha' + C nu + D nu - K2 z2 - z1 (nominal model)."""
        del states, started
        alpha = virtual_control(self._k1, obs.z1, obs.t1, cooperation.vhat)  # [15]
        alpha_dot = alpha_derivative(
            self._k1, obs, cooperation.theta_dot, cooperation.vhat, cooperation.vhat_dot
        )
        params = np.broadcast_to(self._params, (*obs.nu.shape[:-1], self._params.shape[-1]))
        hydro = coriolis_matrix(params, obs.nu) + damping_matrix(params, obs.nu)
        model = contract(self._mass, alpha_dot[..., None, :])  # M alpha'
        model = model + contract(hydro, obs.nu[..., None, :])  # + C(nu) nu + D(nu) nu
        tau0 = model - self._k2 * (obs.nu - alpha) - obs.z1
        zeros = np.zeros_like(alpha)
        return tau0, {
            "nn_output": zeros,
            "nubar_dot": alpha_dot,
            "alpha": alpha,
            "aux_state": zeros,
        }
