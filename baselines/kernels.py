"""The analytic policies' step, compiled: one call acts for R fleets x n vessels.

Every analytic policy of this package runs through ``act_rows_serial`` (or
``act_rows_parallel``, the same per fleet, for large batches): the
cooperative layer (``baselines.cooperative``'s equations [12], [34], [35])
followed by the kinetic part of the policy (the NN-based DSC of
``baselines.nn_dsc`` with its ablations, or the backstepping of
``baselines.backstepping``). It reads each vessel's local observation from
the float64 observation array by the layout of ``cpf_env.sim.observation``,
advances the policy's internal states in place and writes the action and
the diagnostics of every acting vessel. The classes in those modules hold
the gains and the state bookkeeping; the equations live here once, written
as scalar code per vessel, in the order of the operations of their
docstrings, so that:

- a fleet's numbers never depend on how many fleets act in the same call
  (every sum runs left to right over its terms, from 0.0);
- the stiff linear parts (DSC filter, auxiliary system, weight leakage, gamma
  and the speed estimate) are advanced by their exact exponential-Euler
  step with the inputs held over the control period.

``cooperative_rows`` runs the cooperative layer alone, for policies whose
kinetic part is written in Python (``AnalyticPolicy._kinetics``, see
``docs/extending.md``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numba
import numpy as np
from numba import prange

from baselines.kernel_types import (
    KINETICS_NN_DSC,
    CooperativeOutputs,
    KnownDynamics,
    PolicyConstants,
    PolicyOutputs,
    PolicyStates,
)
from cpf_env.infra import kernel_cache
from cpf_env.model.vessel import coriolis_coefficients, damping_coefficients
from cpf_env.sim.observation import (
    LEADER,
    NU,
    SLOT_AGE,
    SLOT_DTHETA,
    SLOT_MSG,
    SLOT_WEIGHT,
    SLOTS,
    T1,
    T2,
    TAU,
    V0,
    Z1,
)

__all__ = [
    "WORK_ROWS",
    "act_rows",
    "act_rows_parallel",
    "act_rows_serial",
    "cooperative_rows",
]

# The cached kernels of this package (here, in closed_loop.py and mpc_kernels.py) inline
# cpf_env's helpers and read the types of kernel_types.py: key them on those sources and files.
kernel_cache.stamp_package(
    Path(__file__).parent,
    tuple(
        Path(__file__).with_name(name)
        for name in ("kernels.py", "kernel_types.py", "closed_loop.py", "mpc_kernels.py")
    ),
)


@numba.njit(cache=True, inline="always")
def _scheduled_speed(c: PolicyConstants, steps: int) -> float:
    """v0 of the schedule at steps * dt (the last breakpoint at or before it)."""
    time = steps * c.dt
    index = int(np.searchsorted(c.v0_times, time, side="right")) - 1
    return float(c.v0_values[max(index, 0)])


@numba.njit(cache=True, inline="always")
def _cooperate(
    c: PolicyConstants, obs: np.ndarray, vhat: float, gamma: float, steps: int
) -> tuple[float, float, float, float, float, float, float, float]:
    """Eqs. [34], [35], [12] of one vessel from its observation row ``obs`` (obs_dim,).

    Returns:
        vhat, vhat_dot, vhat_next, sync, mu, omega_s, gamma_next, theta_dot.
    """
    sync = 0.0  # sum_j a_ij (theta_j - theta_i) as received, negated below
    degree = 0.0  # sum_j a_ij
    neighbours = 0.0  # sum_j a_ij vhat_j
    for k in range(c.n_slots):
        slot = SLOTS + k * c.slot_size
        weight = obs[slot + SLOT_WEIGHT]
        message = obs[slot + SLOT_MSG] if c.msg_size > 0 else 0.0
        dtheta = obs[slot + SLOT_DTHETA]
        if c.delay_compensation:
            dtheta = dtheta + obs[slot + SLOT_AGE] * c.dt * message
        sync = sync + weight * dtheta
        degree = degree + weight * 1.0
        neighbours = neighbours + weight * message
    sync = -sync
    mu = 0.0
    for q in range(3):
        mu = mu + obs[Z1 + q] * obs[T1 + q]
    error = sync - mu
    omega_s = -c.k3 * error - gamma  # [34]
    gamma_next = c.gamma_decay * gamma + c.gamma_gain * error  # [34], exact
    if c.global_speed:
        vhat = _scheduled_speed(c, steps)
        vhat_next = _scheduled_speed(c, steps + 1)
        vhat_dot = 0.0
    else:
        leader = c.k6 * obs[LEADER]
        v0 = obs[V0]
        vhat_dot = -c.k5 * (degree * vhat - neighbours) - leader * (vhat - v0)  # [35]
        rate = c.k5 * degree + leader
        decay = math.exp(-rate * c.dt)
        gain = -math.expm1(-rate * c.dt) / rate if rate > 0.0 else c.dt
        vhat_next = decay * vhat + gain * (c.k5 * neighbours + leader * v0)  # [35], exact
    theta_dot = vhat + omega_s  # [12]
    return vhat, vhat_dot, vhat_next, sync, mu, omega_s, gamma_next, theta_dot


@numba.njit(cache=True, inline="always")
def _nn_dsc(
    c: PolicyConstants,
    s: PolicyStates,
    known: KnownDynamics,
    out: PolicyOutputs,
    obs: np.ndarray,
    b: int,
    r: int,
    i: int,
    first: bool,
    vhat: float,
    work: np.ndarray,
    sigma: np.ndarray,
) -> None:
    """Command [29] of one vessel; advances nubar, pi, What and the kept tau0 to k + 1.

    A privileged reference replaces the NN's estimate by the true
    f + M nubar' of [26] (``known``, row r). ``work`` (>= 4, 3) and ``sigma``
    (l,) are scratch space.
    """
    alpha, nubar, nubar_dot, e2 = work[0], work[1], work[2], work[3]
    for q in range(3):
        alpha[q] = -c.k1[q] * obs[Z1 + q] + obs[T1 + q] * vhat  # [15]
        nubar[q] = alpha[q] if first else s.nubar[b, i, q]  # [18], nubar(0) = alpha(0)
        nubar_dot[q] = (alpha[q] - nubar[q]) / c.rho  # [18]
        z2 = obs[NU + q] - nubar[q]
        pi = 0.0
        if c.use_aux:
            tau_tilde = 0.0 if first else obs[TAU + q] - s.tau0[b, i, q]
            pi = c.aux_decay[q] * s.pi[b, i, q] + c.aux_gain[q] * tau_tilde  # [21], exact
        e2[q] = z2 - pi
        out.aux_state[r, i, q] = pi
        out.alpha[r, i, q] = alpha[q]
        out.nubar_dot[r, i, q] = nubar_dot[q]
        out.nn_output[r, i, q] = 0.0
    if c.use_nn:  # [28], [30]: sigma(xi), What^T sigma, the exact weight step
        hidden = c.input_weights.shape[0]
        for h in range(hidden):
            total = 0.0
            total = total + 1.0 * c.input_weights[h, 0]
            for q in range(3):
                total = total + obs[NU + q] * c.input_weights[h, 1 + q]
            for q in range(3):
                total = total + nubar_dot[q] * c.input_weights[h, 4 + q]
            sigma[h] = math.tanh(total)
        for q in range(3):
            total = 0.0
            for h in range(hidden):
                total = total + s.weights[b, i, h, q] * sigma[h]
            out.nn_output[r, i, q] = total
        for h in range(hidden):
            for q in range(3):
                s.weights[b, i, h, q] = c.leak_decay * s.weights[b, i, h, q] - c.adapt_gain * (
                    sigma[h] * e2[q]
                )
    if c.privileged:  # [26] told, not learned: f + M nubar'
        for q in range(3):
            told = known.lumped[r, i, q]
            for p in range(3):
                told = told + known.mass[r, i, q, p] * nubar_dot[p]
            out.nn_output[r, i, q] = told
    for q in range(3):
        tau0 = -c.k2[q] * e2[q] - obs[Z1 + q] + out.nn_output[r, i, q]  # [29]
        out.tau_command[r, i, q] = tau0
        s.tau0[b, i, q] = tau0
        s.pi[b, i, q] = out.aux_state[r, i, q]
        s.nubar[b, i, q] = c.filter_decay * nubar[q] + (1.0 - c.filter_decay) * alpha[q]


@numba.njit(cache=True, inline="always")
def _backstepping(
    c: PolicyConstants,
    known: KnownDynamics,
    out: PolicyOutputs,
    obs: np.ndarray,
    r: int,
    i: int,
    vhat: float,
    vhat_dot: float,
    theta_dot: float,
    work: np.ndarray,
) -> None:
    """tau0 = M alpha' + C(nu) nu + D(nu) nu - K2 (nu - alpha) - z1 with the analytic alpha'.

    Nominal M, C, D; a privileged reference uses the true M and the true
    lumped f in place of C(nu) nu + D(nu) nu (``known``, row r). ``work``
    (>= 11, 3) is scratch space.
    """
    u, v, yaw_rate = obs[NU], obs[NU + 1], obs[NU + 2]
    s_z1 = (-obs[Z1 + 1], obs[Z1], 0.0)  # S z1, S = [[0, -1, 0], [1, 0, 0], [0, 0, 0]]
    s_t1 = (-obs[T1 + 1], obs[T1], 0.0)
    alpha, alpha_dot = work[0], work[1]
    for q in range(3):
        alpha[q] = -c.k1[q] * obs[Z1 + q] + obs[T1 + q] * vhat  # [15]
        z1_dot = -yaw_rate * s_z1[q] + obs[NU + q] - obs[T1 + q] * theta_dot  # [13]
        t1_dot = -yaw_rate * s_t1[q] + obs[T2 + q] * theta_dot  # [14]
        alpha_dot[q] = -c.k1[q] * z1_dot + t1_dot * vhat + obs[T1 + q] * vhat_dot
    coriolis, damping, hydro = work[2:5], work[5:8], work[8:11]  # (3, 3) each
    coriolis[:] = 0.0  # C(nu) and D(nu) of the nominal model (cpf_env.model.vessel)
    damping[:] = 0.0
    p = c.hydro_params[i]
    c13, c23 = coriolis_coefficients(p, u, v, yaw_rate)
    d11, d22, d23, d32, d33 = damping_coefficients(p, u, v, yaw_rate)
    coriolis[0, 2], coriolis[1, 2], coriolis[2, 0], coriolis[2, 1] = c13, c23, -c13, -c23
    damping[0, 0], damping[1, 1], damping[1, 2], damping[2, 1], damping[2, 2] = (
        d11,
        d22,
        d23,
        d32,
        d33,
    )
    for row in range(3):
        for q in range(3):
            hydro[row, q] = coriolis[row, q] + damping[row, q]
    for row in range(3):
        model = 0.0
        hydrodynamic = 0.0
        if c.privileged:
            for q in range(3):
                model = model + known.mass[r, i, row, q] * alpha_dot[q]  # M alpha', true M
            hydrodynamic = known.lumped[r, i, row]
        else:
            for q in range(3):
                model = model + c.mass[i, row, q] * alpha_dot[q]  # M alpha'
            for q in range(3):
                hydrodynamic = hydrodynamic + hydro[row, q] * obs[NU + q]
        tau0 = (model + hydrodynamic) - c.k2[row] * (obs[NU + row] - alpha[row]) - obs[Z1 + row]
        out.tau_command[r, i, row] = tau0
        out.alpha[r, i, row] = alpha[row]
        out.nubar_dot[r, i, row] = alpha_dot[row]
        out.nn_output[r, i, row] = 0.0
        out.aux_state[r, i, row] = 0.0


#: Scratch rows of 3 floats per acting fleet (``_nn_dsc`` uses 4, ``_backstepping`` 11).
WORK_ROWS = 11


@numba.njit(cache=True)
def _act_fleet(
    c: PolicyConstants,
    s: PolicyStates,
    obs: np.ndarray,
    fleets: np.ndarray,
    known: KnownDynamics,
    out: PolicyOutputs,
    r: int,
    work: np.ndarray,
    sigma: np.ndarray,
) -> None:
    """Row r: act for fleet ``fleets[r]`` and advance its states from step k to k + 1."""
    b = fleets[r]
    first = not s.started[b]
    act_dim = out.actions.shape[2]
    for i in range(obs.shape[1]):
        row = obs[r, i]
        gamma = s.gamma[b, i]
        vhat, vhat_dot, vhat_next, _, _, omega_s, gamma_next, theta_dot = _cooperate(
            c, row, s.vhat[b, i], gamma, s.steps[b]
        )
        if c.kinetics == KINETICS_NN_DSC:
            _nn_dsc(c, s, known, out, row, b, r, i, first, vhat, work, sigma)
        else:
            _backstepping(c, known, out, row, r, i, vhat, vhat_dot, theta_dot, work)
        s.vhat[b, i] = vhat_next
        s.gamma[b, i] = gamma_next
        for q in range(3):
            out.actions[r, i, q] = out.tau_command[r, i, q]
        out.actions[r, i, 3] = theta_dot
        if act_dim > 4:
            out.actions[r, i, 4] = vhat_next
        for q in range(5, act_dim):
            out.actions[r, i, q] = 0.0
        out.speed_estimate[r, i] = vhat
        out.omega_s[r, i] = omega_s
        out.gamma[r, i] = gamma
    s.started[b] = True
    s.steps[b] += 1


@numba.njit(cache=True)
def act_rows_serial(
    c: PolicyConstants,
    s: PolicyStates,
    obs: np.ndarray,
    fleets: np.ndarray,
    known: KnownDynamics,
    out: PolicyOutputs,
) -> None:
    """Act for the fleets ``fleets`` (R,) from their observations ``obs`` (R, n, obs_dim).

    Row r of ``obs``, ``known`` and ``out`` belongs to fleet ``fleets[r]`` of ``s``
    (distinct indices); that fleet's states are read at step k and left at step k + 1.
    """
    work = np.empty((WORK_ROWS, 3))
    sigma = np.empty(c.input_weights.shape[0])
    for r in range(obs.shape[0]):
        _act_fleet(c, s, obs, fleets, known, out, r, work, sigma)


@numba.njit(cache=True, parallel=True)
def act_rows_parallel(
    c: PolicyConstants,
    s: PolicyStates,
    obs: np.ndarray,
    fleets: np.ndarray,
    known: KnownDynamics,
    out: PolicyOutputs,
) -> None:
    """``act_rows_serial`` with the fleets spread over numba's threads (same bits).

    Each fleet runs in a call of its own (``_act_fleet`` is not inlined), so its
    scratch arrays are its own and parfors never reorders inside a fleet. The row
    index is made int64, as ``act_rows_serial``'s, so that ``_act_fleet`` compiles once
    (prange's index is uint64).
    """
    hidden = c.input_weights.shape[0]
    for index in prange(obs.shape[0]):
        r = int(np.int64(index))  # int() alone would keep the uint64
        _act_fleet(c, s, obs, fleets, known, out, r, np.empty((WORK_ROWS, 3)), np.empty(hidden))


@numba.njit(cache=True)
def act_rows(
    constants: tuple,
    states: tuple,
    obs: np.ndarray,
    fleets: np.ndarray,
    known: tuple,
    out: tuple,
    threaded: bool,
) -> None:
    """``act_rows_serial`` (or ``_parallel`` if ``threaded``) given plain tuples of the fields.

    ``constants`` is ``tuple(PolicyConstants(...))``, and so on. numba's
    dispatcher types a plain tuple of arrays on a fast path and a named
    tuple field by field in Python, which made the dispatch of the four
    named tuples most of the cost of a call for one fleet; the named tuples
    are rebuilt here, in compiled code, at no cost.
    """
    c, s = PolicyConstants(*constants), PolicyStates(*states)
    k, o = KnownDynamics(*known), PolicyOutputs(*out)
    if threaded:
        act_rows_parallel(c, s, obs, fleets, k, o)
    else:
        act_rows_serial(c, s, obs, fleets, k, o)


@numba.njit(cache=True)
def cooperative_rows(
    c: PolicyConstants,
    s: PolicyStates,
    obs: np.ndarray,
    fleets: np.ndarray,
    out: CooperativeOutputs,
) -> None:
    """The cooperative layer alone for the fleets ``fleets``; the states are not advanced."""
    for r in range(obs.shape[0]):
        b = fleets[r]
        for i in range(obs.shape[1]):
            gamma = s.gamma[b, i]
            vhat, vhat_dot, vhat_next, sync, mu, omega_s, gamma_next, theta_dot = _cooperate(
                c, obs[r, i], s.vhat[b, i], gamma, s.steps[b]
            )
            out.vhat[r, i], out.vhat_dot[r, i], out.vhat_next[r, i] = vhat, vhat_dot, vhat_next
            out.sync[r, i], out.mu[r, i], out.omega_s[r, i] = sync, mu, omega_s
            out.gamma[r, i], out.gamma_next[r, i] = gamma, gamma_next
            out.theta_dot[r, i] = theta_dot
