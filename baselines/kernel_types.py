"""The types the analytic policies' compiled step reads and writes (``baselines.kernels``).

Named tuples of plain arrays and scalars, the form numba compiles: the gains
(``PolicyConstants``), the internal states of B fleets (``PolicyStates``),
what a privileged reference is told (``KnownDynamics``) and the outputs of
one call (``PolicyOutputs``, ``CooperativeOutputs``). Every policy builds
fields of the same dtypes and dimensions, so one compilation serves them all.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "KINETICS_BACKSTEPPING",
    "KINETICS_NN_DSC",
    "KINETICS_PYTHON",
    "NO_KNOWLEDGE",
    "CooperativeOutputs",
    "KnownDynamics",
    "PolicyConstants",
    "PolicyOutputs",
    "PolicyStates",
]

#: ``PolicyConstants.kinetics``: the kinetic part given in Python, the NN-based DSC, backstepping.
KINETICS_PYTHON, KINETICS_NN_DSC, KINETICS_BACKSTEPPING = 0, 1, 2


class PolicyConstants(NamedTuple):
    """Gains and fixed coefficients of one policy (see ``baselines.gains`` for the meaning).

    The exponential-Euler coefficients (e^{-a dt}, (1 - e^{-a dt}) / a) of the
    constant-rate linear parts are computed once in Python
    (``cooperative.exponential_euler``).
    """

    kinetics: int  # KINETICS_*
    use_nn: bool  # NN term What^T sigma(xi) in tau0, What adapted
    use_aux: bool  # saturation auxiliary system (else e2 = z2)
    global_speed: bool  # vhat = v0(t) from the schedule (ablation), no estimator
    delay_compensation: bool  # theta_j - theta_i advanced by age dt vhat_j
    privileged: bool  # the true lumped uncertainty is given (KnownDynamics), not estimated
    n_slots: int  # K neighbour slots
    slot_size: int  # 3 + m floats per slot
    msg_size: int  # m
    dt: float  # control period (s)
    k1: np.ndarray  # (3,) K1 diagonal (1/s)
    k2: np.ndarray  # (3,) K2 diagonal
    k3: float
    k5: float
    k6: float
    gamma_decay: float  # e^{-k4 dt}
    gamma_gain: float  # (1 - e^{-k4 dt}) / k4
    rho: float  # DSC filter time constant (s)
    filter_decay: float  # e^{-dt / rho}
    aux_decay: np.ndarray  # (3,) e^{-K_pi dt}
    aux_gain: np.ndarray  # (3,) (1 - e^{-K_pi dt}) / K_pi
    leak_decay: float  # e^{-leakage rate dt}
    adapt_gain: float  # Gamma_W (1 - e^{-leakage rate dt}) / leakage rate
    input_weights: np.ndarray  # (l, 7) fixed NN input weights v_l
    mass: np.ndarray  # (n, 3, 3) nominal mass matrices (backstepping)
    hydro_params: np.ndarray  # (n, PARAM_SIZE) nominal parameters (backstepping)
    v0_times: np.ndarray  # (S,) s, schedule of the global-v0 ablation
    v0_values: np.ndarray  # (S,) m/s


class PolicyStates(NamedTuple):
    """Internal states of B fleets x n vessels, advanced in place by ``act_rows``."""

    vhat: np.ndarray  # (B, n) speed estimate (m/s)
    gamma: np.ndarray  # (B, n) auxiliary state of [34] (1/s)
    nubar: np.ndarray  # (B, n, 3) DSC filter state
    pi: np.ndarray  # (B, n, 3) saturation auxiliary state
    weights: np.ndarray  # (B, n, l, 3) NN weights What
    tau0: np.ndarray  # (B, n, 3) last command (N, N, N m)
    started: np.ndarray  # (B,) bool: acted since the last reset
    steps: np.ndarray  # (B,) int64 control steps since the last reset


class KnownDynamics(NamedTuple):
    """What a privileged reference is told per acting row (``cpf_env.evaluation.privileged``).

    Read only when ``PolicyConstants.privileged``; the deployable policies get
    ``NO_KNOWLEDGE`` (no rows).
    """

    lumped: np.ndarray  # (R, n, 3) f with M nu' = tau - f, true model (N, N, N m)
    mass: np.ndarray  # (R, n, 3, 3) true mass matrices (kg, kg m, kg m^2)


#: The knowledge of a deployable policy: none.
NO_KNOWLEDGE = KnownDynamics(np.zeros((0, 0, 3)), np.zeros((0, 0, 3, 3)))


class PolicyOutputs(NamedTuple):
    """What one call of ``act_rows`` writes for its R acting fleets (leading axes (R, n))."""

    actions: np.ndarray  # (R, n, 4 + m): tau0, theta_dot, [vhat_next, 0 ...]
    nn_output: np.ndarray  # (R, n, 3)
    nubar_dot: np.ndarray  # (R, n, 3) (alpha_dot for backstepping)
    alpha: np.ndarray  # (R, n, 3)
    speed_estimate: np.ndarray  # (R, n)
    aux_state: np.ndarray  # (R, n, 3)
    tau_command: np.ndarray  # (R, n, 3)
    omega_s: np.ndarray  # (R, n)
    gamma: np.ndarray  # (R, n)


class CooperativeOutputs(NamedTuple):
    """The cooperative layer's signals of one step, (R, n) each.

    What ``cooperative_rows`` writes, and what a kinetic part written in Python
    (``AnalyticPolicy._kinetics``) receives as ``cooperation``.
    """

    vhat: np.ndarray  # speed estimate vhat_i used at this step (m/s)
    vhat_dot: np.ndarray  # its rate, the right-hand side of [35] (m/s^2); 0 with a global v0
    vhat_next: np.ndarray  # estimate at the next step, the vessel's message (m/s)
    sync: np.ndarray  # s_i = sum_j a_ij (theta_i - theta_j)
    mu: np.ndarray  # mu_i = z_i1^T t_i1
    omega_s: np.ndarray  # omega_is, [34] (1/s)
    gamma: np.ndarray  # auxiliary state gamma_i used at this step (1/s)
    gamma_next: np.ndarray  # gamma_i at the next step
    theta_dot: np.ndarray  # commanded path-variable rate vhat_i + omega_is, [12] (1/s)
