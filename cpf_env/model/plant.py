"""The plant: right-hand side of a vessel's motion and its RK4 integration.

Wang, Wang & Peng (2014), eqs. [2]-[3], with the environment of
``cpf_env.model.disturbances``::

    d/dt eta = J(psi) nu
    M nu_r' + C(nu_r) nu_r + D(nu_r) nu_r + s Delta(nu_r) = tau + J^T f + s tau_w(t, nu_r)

where nu_r = nu - J(psi)^T [V_c, 0] is the velocity relative to an
irrotational current V_c held constant over a control period (Fossen 2011,
section 10.3), f the earth-frame wave and wind force, and s the scale of the
paper's unmodeled dynamics. The simulator's kernel and its diagnostics call
these functions, so the plant is written once.

A plant *load* is the tuple of inputs held over a control period:
``(tau_u, tau_v, tau_r, f_x, f_y, f_n, V_x, V_y)`` in N, N, N m, N, N, N m, m/s, m/s.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from cpf_env.model.disturbances import paper_disturbance_given, paper_time_term, paper_unmodeled
from cpf_env.model.vessel import hydrodynamic_forces, solve_mass

__all__ = ["plant_rhs", "plant_rhs_given", "rk4_period", "rk4_substep", "substep_time_terms"]


@numba.njit(cache=True, inline="always")
def plant_rhs_given(p: NDArray[np.float64], scale: float, time_term: float, psi: float, u: float,
                    v: float, r: float, load: tuple) -> tuple:  # fmt: skip
    """``plant_rhs`` with the time term of the paper's disturbance given instead of t.

    The arguments and the result are those of ``plant_rhs``, but for
    ``time_term``: ``paper_time_term(t)`` at the time of evaluation (N, N m),
    unused when ``scale == 0``. A fleet's vessels share it.
    """
    tx, ty, tn, fx, fy, fn, cx, cy = load
    c, s = math.cos(psi), math.sin(psi)
    uc, vc = c * cx + s * cy, -s * cx + c * cy  # current in the body frame
    ur, vr = u - uc, v - vc  # velocity relative to the water
    h0, h1, h2 = hydrodynamic_forces(p, ur, vr, r)
    f0 = tx + c * fx + s * fy - h0
    f1 = ty - s * fx + c * fy - h1
    f2 = tn + fn - h2
    if scale != 0.0:
        d0, d1, d2 = paper_unmodeled(ur, vr, r)
        w0, w1, w2 = paper_disturbance_given(time_term, ur, vr, r)
        f0 += scale * (w0 - d0)
        f1 += scale * (w1 - d1)
        f2 += scale * (w2 - d2)
    a0, a1, a2 = solve_mass(p, f0, f1, f2)
    # nu = nu_r + J^T V_c, and d/dt (J^T V_c) = (r vc, -r uc, 0) for a current held constant.
    return c * u - s * v, s * u + c * v, r, a0 + r * vc, a1 - r * uc, a2


@numba.njit(cache=True, inline="always")
def plant_rhs(p: NDArray[np.float64], scale: float, t: float, psi: float, u: float, v: float,
              r: float, load: tuple) -> tuple:  # fmt: skip
    """Right-hand side of the plant at one state.

    Args:
        p: True vessel parameters, shape (PARAM_SIZE,).
        scale: Factor on the paper's unmodeled dynamics and disturbance.
        t: Time (s).
        psi: Heading (rad).
        u: Surge velocity over ground, body frame (m/s).
        v: Sway velocity over ground, body frame (m/s).
        r: Yaw rate (rad/s).
        load: Held inputs, see the module docstring.

    Returns:
        (x', y', psi', u', v', r').
    """
    time_term = paper_time_term(t) if scale != 0.0 else 0.0
    return plant_rhs_given(p, scale, time_term, psi, u, v, r, load)


@numba.njit(cache=True, inline="always")
def substep_time_terms(scale: float, t: float, h: float) -> tuple:
    """The time terms an RK4 step from t to t + h evaluates: at t, t + h/2 and t + h.

    They depend on time only, so every vessel of a fleet shares them (zeros
    when ``scale == 0``, where they are not used).
    """
    if scale == 0.0:
        return 0.0, 0.0, 0.0
    return paper_time_term(t), paper_time_term(t + 0.5 * h), paper_time_term(t + h)


@numba.njit(cache=True, inline="always")
def rk4_substep(p: NDArray[np.float64], scale: float, h: float, time_terms: tuple, state: tuple,
                load: tuple) -> tuple:  # fmt: skip
    """One classical RK4 step of length h, the load held.

    Args:
        p: True vessel parameters, shape (PARAM_SIZE,).
        scale: Factor on the paper's unmodeled dynamics and disturbance.
        h: Step (s).
        time_terms: ``substep_time_terms(scale, t, h)`` for a step starting at t.
        state: (x, y, psi, u, v, r) at t.
        load: Held inputs, see the module docstring.

    Returns:
        (x, y, psi, u, v, r) at t + h.
    """
    x, y, psi, u, v, r = state
    start, middle, end = time_terms
    k1 = plant_rhs_given(p, scale, start, psi, u, v, r, load)
    k2 = plant_rhs_given(p, scale, middle, psi + 0.5 * h * k1[2], u + 0.5 * h * k1[3],
                         v + 0.5 * h * k1[4], r + 0.5 * h * k1[5], load)  # fmt: skip
    k3 = plant_rhs_given(p, scale, middle, psi + 0.5 * h * k2[2], u + 0.5 * h * k2[3],
                         v + 0.5 * h * k2[4], r + 0.5 * h * k2[5], load)  # fmt: skip
    k4 = plant_rhs_given(p, scale, end, psi + h * k3[2], u + h * k3[3], v + h * k3[4],
                         r + h * k3[5], load)  # fmt: skip
    w = h / 6.0
    x += w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
    y += w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
    psi += w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
    u += w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
    v += w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
    r += w * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
    return x, y, psi, u, v, r


@numba.njit(cache=True, inline="always")
def rk4_period(p: NDArray[np.float64], scale: float, t0: float, dt: float, substeps: int,
               state: tuple, load: tuple) -> tuple:  # fmt: skip
    """Integrate one control period with ``substeps`` classical RK4 steps, the load held.

    The simulator's kernel runs the same steps (``rk4_substep``) vessel by
    vessel inside each sub-step, so a fleet's vessels share the time terms.

    Args:
        p: True vessel parameters, shape (PARAM_SIZE,).
        scale: Factor on the paper's unmodeled dynamics and disturbance.
        t0: Time at the start of the period (s).
        dt: Control period (s).
        substeps: RK4 steps per period.
        state: (x, y, psi, u, v, r) at t0.
        load: Held inputs, see the module docstring.

    Returns:
        (x, y, psi, u, v, r) at t0 + dt.
    """
    h = dt / substeps
    for k in range(substeps):
        state = rk4_substep(p, scale, h, substep_time_terms(scale, t0 + k * h, h), state, load)
    return state
