"""Compiled parts of the receding-horizon policies (``baselines.mpc``): feedback and rollouts.

Both members of ``baselines.mpc`` plan offsets on top of one stateless
tracking feedback (``tracking_feedback``) and score a plan by rolling it
out over the horizon on a prediction model with the benchmark's own stage
cost (``cpf_env.sim.reward.step_reward``, the terms and weights the bench
scores). They differ only in the prediction model and in what the feedback
is told:

* ``oracle`` (``fleet_rollouts``): copies of the simulator's fleets, so the
  true model, the true disturbances of the coming steps (counter-based
  draws: a copy sees the same future), true neighbours' path variables and
  the true v0; the fleet's cost, centralized;
* ``mpc`` (``local_rollouts``): per vessel, the nominal model plus a
  disturbance-observer estimate of the lumped uncertainty held over the
  horizon, neighbours' path variables predicted at their communicated
  speed, the estimated v0; the vessel's own cost.

The feedback (Wang et al. 2014's kinematic step with the analytic
derivative of the virtual control, Remark 1, and a kinetic step that
cancels the lumped force it is told)::

    theta_dot = sat(v - k s + k_mu mu),        mu = z1 . t1,  k = min(k_sync, 1 / (dt d))
    alpha     = -K1 z1 + t1 theta_dot
    alpha'    = -K1 z1' + t1' theta_dot
    z1'       = -r S z1 + nu - t1 theta_dot,   t1' = -r S t1 + t2 theta_dot
    tau       = M (alpha' - K2 (nu - alpha)) + f

On hulls without a sway force the yaw component of z1 is taken against a
line-of-sight heading, z1_psi + atan(y_e / Delta) with y_e the cross-track
error in the path's frame (``RecedingHorizonGains.lookahead``): the hull turns
toward its path, as integral LOS guidance does (``baselines.ilos``), instead
of waiting for a sway force that never comes (its rate is left out of alpha').

with f the lumped force (M nu' = tau - f) and d the vessel's weighted
degree sum_j a_ij: capping the consensus gain at 1 / (dt d) keeps the
discrete-time consensus theta+ = theta - dt k L theta stable on any graph
(each row of I - dt K L is then non-negative and sums to one). Plans are piecewise constant
over knots of ``knot`` control steps: offsets (n, 4) on the force (N, N,
N m) and the path-variable rate (1/s) per knot; the command is clipped to
the force limits and the rate limit before it is applied.
"""

from __future__ import annotations

import math

import numba
import numpy as np

import baselines.kernels  # noqa: F401  (keys this package's cached kernels on their sources first)
from baselines.barrier import BARRIER_GAINS, barrier_filter
from cpf_env.evaluation.privileged import fleet_lumped_uncertainty
from cpf_env.model.paths import path_values
from cpf_env.model.plant import rk4_substep, substep_time_terms
from cpf_env.model.vessel import M11, M22, M23, M32, M33, hydrodynamic_forces
from cpf_env.sim.arrays import FleetArrays, KernelConstants
from cpf_env.sim.kernels import leader_speed, step_fleet, topology_index
from cpf_env.sim.observation import (
    NU,
    SLOT_AGE,
    SLOT_DTHETA,
    SLOT_MSG,
    SLOT_WEIGHT,
    SLOTS,
    THETA,
    Z1,
    frame_pose,
    path_frame,
)
from cpf_env.sim.reward import step_reward

__all__ = [
    "GAINS_SIZE",
    "LOCAL_STATE",
    "fleet_rollouts",
    "hydrodynamics",
    "local_commands",
    "local_rollouts",
    "local_start",
    "observe_residual",
    "oracle_actions",
    "oracle_rows",
    "ramped_speed",
    "tracking_feedback",
]

#: Layout of the feedback gains: K1 (3, 1/s), K2 (3, 1/s), k_sync (1/s), k_mu (1/s), the
#: oracle's reference-speed ramp (m/s^2; inf: v0 itself), the margin (m) its separation
#: barrier keeps outside the collision distance and the line-of-sight lookahead (m; 0:
#: the hulls have a sway force).
G_K1, G_K2, G_SYNC, G_MU, G_RAMP, G_BARRIER, G_LOOKAHEAD, GAINS_SIZE = 0, 3, 6, 7, 8, 9, 10, 11
#: Columns of a local rollout's start: x, y, psi, u, v, r, theta.
LOCAL_STATE = 7


@numba.njit(cache=True)
def ramped_speed(c: KernelConstants, time: float, ramp: float) -> float:
    """The reference speed (m/s) at ``time`` (s): v0's schedule followed from 0 at ``ramp``.

    Starting from 0 at time 0, the speed moves toward each value of the
    piecewise-constant schedule at ``ramp`` (m/s^2) at most; ``inf`` gives
    ``leader_speed`` itself.
    """
    if ramp == math.inf:
        return leader_speed(c, time)
    speed, start = 0.0, 0.0
    count = c.v0_times.shape[0]
    for k in range(count):
        end = time if k + 1 == count else min(time, max(c.v0_times[k + 1], 0.0))
        reach = ramp * max(end - start, 0.0)
        gap = c.v0_values[k] - speed
        speed = c.v0_values[k] if abs(gap) <= reach else speed + math.copysign(reach, gap)
        start = max(start, end)
    return speed


@numba.njit(cache=True)
def tracking_feedback(
    nu: np.ndarray,
    z1: tuple,
    t1: tuple,
    t2: tuple,
    sync: float,
    degree: float,
    speed: float,
    lumped: np.ndarray,
    mass: np.ndarray,
    gains: np.ndarray,
    theta_dot_max: float,
    dt: float,
) -> tuple:
    """The stateless tracking feedback of one vessel (module docstring).

    Args:
        nu: Body velocity (3,) (m/s, m/s, rad/s).
        z1: Body-frame path error (m, m, rad).
        t1: J^T d eta_d / d theta.
        t2: J^T d2 eta_d / d theta2.
        sync: s_i = sum_j a_ij (theta_i - theta_j).
        degree: d_i = sum_j a_ij.
        speed: The reference speed v (m/s).
        lumped: The lumped force f (3,) with M nu' = tau - f (N, N, N m).
        mass: The mass matrix M (3, 3).
        gains: ``GAINS_SIZE`` gains.
        theta_dot_max: The rate limit (1/s).
        dt: The control period (s).

    Returns:
        (tau_u, tau_v, tau_r, theta_dot): force command (N, N, N m) before
        saturation and the path-variable rate within the limit.
    """
    mu = z1[0] * t1[0] + z1[1] * t1[1] + z1[2] * t1[2]
    k_sync = gains[G_SYNC]
    if degree > 0.0:
        k_sync = min(k_sync, 1.0 / (dt * degree))
    rate = speed - k_sync * sync + gains[G_MU] * mu
    rate = min(max(rate, -theta_dot_max), theta_dot_max)
    r = nu[2]
    z1_dot = (r * z1[1] + nu[0] - t1[0] * rate, -r * z1[0] + nu[1] - t1[1] * rate,
              nu[2] - t1[2] * rate)  # fmt: skip
    lookahead = gains[G_LOOKAHEAD]
    if lookahead > 0.0:  # no sway force: steer toward the path (line of sight)
        bearing = math.atan2(t1[1], t1[0])
        cross = -math.sin(bearing) * z1[0] + math.cos(bearing) * z1[1]
        z1 = (z1[0], z1[1], z1[2] + math.atan(cross / lookahead))
    t1_dot = (r * t1[1] + t2[0] * rate, -r * t1[0] + t2[1] * rate, t2[2] * rate)
    acc = np.empty(3)
    for k in range(3):
        alpha = -gains[G_K1 + k] * z1[k] + t1[k] * rate
        alpha_dot = -gains[G_K1 + k] * z1_dot[k] + t1_dot[k] * rate
        acc[k] = alpha_dot - gains[G_K2 + k] * (nu[k] - alpha)
    tau = np.empty(3)
    for q in range(3):
        tau[q] = lumped[q] + mass[q, 0] * acc[0] + mass[q, 1] * acc[1] + mass[q, 2] * acc[2]
    return tau[0], tau[1], tau[2], rate


@numba.njit(cache=True, inline="always")
def _clipped(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


@numba.njit(cache=True)
def oracle_actions(
    a: FleetArrays,
    c: KernelConstants,
    b: int,
    gains: np.ndarray,
    offsets: np.ndarray,
    lumped: np.ndarray,
    mass: np.ndarray,
    out: np.ndarray,
) -> None:
    """The oracle's command for fleet b at its current state into ``out`` (n, 4 + m).

    Told the truth: true state, true lumped force and mass matrix, true
    synchronization errors, the true v0 (taken up at ``gains[G_RAMP]``,
    ``ramped_speed``). Where the scenario has a separation, every vessel's
    force then keeps the true position of every other at the collision
    distance plus ``gains[G_BARRIER]`` (``baselines.barrier``, on its true
    model). ``offsets`` (n, 4) is the plan's
    current knot; ``lumped`` (n, 3) and ``mass`` (n, 3, 3) are scratch.
    The message sent is v0 (no vessel needs it: the oracle is centralized).
    """
    fleet_lumped_uncertainty(a, c, b, lumped, mass)
    step = a.step[b]
    member = topology_index(c, step)
    v0 = ramped_speed(c, step * c.dt, gains[G_RAMP])
    for i in range(a.eta.shape[1]):
        sync, degree = 0.0, 0.0
        for k in range(c.slots.shape[1]):
            j = c.slots[i, k]
            weight = c.slot_weights[member, i, k]
            if j >= 0 and weight != 0.0:
                sync += weight * (a.theta[b, i] - a.theta[b, j])
                degree += weight
        point = path_values(c.path_kinds[i], c.path_params[i], a.theta[b, i])
        z1, t1, t2 = path_frame(a.eta[b, i, 0], a.eta[b, i, 1], a.eta[b, i, 2], point)
        command = tracking_feedback(
            a.nu[b, i],
            z1,
            t1,
            t2,
            sync,
            degree,
            v0,
            lumped[i],
            mass[i],
            gains,
            c.theta_dot_max,
            c.dt,
        )
        for q in range(3):
            out[i, q] = _clipped(command[q] + offsets[i, q], c.tau_min[i, q], c.tau_max[i, q])
        out[i, 3] = _clipped(command[3] + offsets[i, 3], -c.theta_dot_max, c.theta_dot_max)
        for q in range(4, out.shape[1]):
            out[i, q] = _clipped(v0, -c.message_max, c.message_max)
    if c.separation[0] > 0.0:  # every vessel kept clear of every other (baselines.barrier)
        others = np.empty((a.eta.shape[1], 4))
        for i in range(a.eta.shape[1]):
            count = 0
            for j in range(a.eta.shape[1]):
                if j != i:
                    cj, sj = math.cos(a.eta[b, j, 2]), math.sin(a.eta[b, j, 2])
                    others[count, 0], others[count, 1] = a.eta[b, j, 0], a.eta[b, j, 1]
                    others[count, 2] = cj * a.nu[b, j, 0] - sj * a.nu[b, j, 1]
                    others[count, 3] = sj * a.nu[b, j, 0] + cj * a.nu[b, j, 1]
                    count += 1
            barrier_filter(out[i, :3], a.eta[b, i, 0], a.eta[b, i, 1], a.eta[b, i, 2],
                           a.nu[b, i], a.params[b, i], others, count,
                           c.separation[1] + gains[G_BARRIER], BARRIER_GAINS[0],
                           BARRIER_GAINS[1], c.tau_min[i], c.tau_max[i])  # fmt: skip


@numba.njit(cache=True)
def oracle_rows(
    arrays: tuple, constants: tuple, fleets: np.ndarray, gains: np.ndarray,
    offsets: np.ndarray, out: np.ndarray,
) -> None:  # fmt: skip
    """``oracle_actions`` of the listed fleets: row r of ``out`` (R, n, 4 + m) for ``fleets[r]``.

    ``offsets`` (R, n, 4) is each fleet's current knot.
    """
    a, c = FleetArrays(*arrays), KernelConstants(*constants)
    n = a.eta.shape[1]
    lumped, mass = np.empty((n, 3)), np.empty((n, 3, 3))
    for r in range(fleets.shape[0]):
        oracle_actions(a, c, fleets[r], gains, offsets[r], lumped, mass, out[r])


@numba.njit(cache=True)
def _fleet_rollouts(
    a: FleetArrays,
    c: KernelConstants,
    gains: np.ndarray,
    plans: np.ndarray,
    knot: int,
    costs: np.ndarray,
) -> None:
    n = a.eta.shape[1]
    lumped, mass = np.empty((n, 3)), np.empty((n, 3, 3))
    actions = np.zeros((a.eta.shape[0], n, 4 + a.message.shape[2]))
    for b in range(a.eta.shape[0]):
        total = 0.0
        for h in range(plans.shape[1] * knot):
            oracle_actions(a, c, b, gains, plans[b, h // knot], lumped, mass, actions[b])
            step_fleet(a, c, actions, b)
            if a.nonfinite[b]:
                total = math.inf
                break
            for i in range(n):
                total -= a.reward[b, i]
            if a.terminated[b]:  # the failure term charged the rest of the episode
                break
        costs[b] = total / n


@numba.njit(cache=True)
def fleet_rollouts(
    arrays: tuple, constants: tuple, gains: np.ndarray, plans: np.ndarray, knot: int,
    costs: np.ndarray,
) -> None:  # fmt: skip
    """Roll every fleet of a (copied) simulator out under its plan; its cost into ``costs``.

    Args:
        arrays: ``tuple(FleetArrays)`` of the copies (B fleets; advanced in place).
        constants: ``tuple(KernelConstants)``.
        gains: The feedback's gains (``GAINS_SIZE``,).
        plans: (B, knots, n, 4) offsets, knot k held for ``knot`` steps.
        knot: Control steps per knot.
        costs: (B,) out: the bench's cost over the horizon, sum over steps of the
            mean over vessels of -reward (failure term included; inf if diverged).
    """
    _fleet_rollouts(FleetArrays(*arrays), KernelConstants(*constants), gains, plans, knot, costs)


@numba.njit(cache=True)
def _local_command(
    c: KernelConstants,
    i: int,
    state: np.ndarray,
    sync: float,
    degree: float,
    speed: float,
    lumped: np.ndarray,
    mass: np.ndarray,
    gains: np.ndarray,
    offsets: np.ndarray,
    nominal: np.ndarray,
) -> tuple:
    """Path frame and clipped command of vessel i at ``state`` (x, y, psi, u, v, r, theta)."""
    point = path_values(c.path_kinds[i], c.path_params[i], state[6])
    z1, t1, t2 = path_frame(state[0], state[1], state[2], point)
    h = hydrodynamic_forces(nominal, state[3], state[4], state[5])
    for q in range(3):
        lumped[q] = h[q] + offsets[4 + q]  # nominal C nu + D nu, plus the estimated residual
    command = tracking_feedback(
        state[3:6], z1, t1, t2, sync, degree, speed, lumped, mass, gains, c.theta_dot_max, c.dt
    )
    tau = (
        _clipped(command[0] + offsets[0], c.tau_min[i, 0], c.tau_max[i, 0]),
        _clipped(command[1] + offsets[1], c.tau_min[i, 1], c.tau_max[i, 1]),
        _clipped(command[2] + offsets[2], c.tau_min[i, 2], c.tau_max[i, 2]),
    )
    rate = _clipped(command[3] + offsets[3], -c.theta_dot_max, c.theta_dot_max)
    return tau, rate


@numba.njit(cache=True)
def _mass(p: np.ndarray) -> np.ndarray:
    mass = np.zeros((3, 3))
    mass[0, 0] = p[M11]
    mass[1, 1], mass[1, 2] = p[M22], p[M23]
    mass[2, 1], mass[2, 2] = p[M32], p[M33]
    return mass


@numba.njit(cache=True)
def _local_rollouts(
    c: KernelConstants,
    vessel: np.ndarray,
    start: np.ndarray,
    neighbours: np.ndarray,
    speed: np.ndarray,
    residual: np.ndarray,
    nominal: np.ndarray,
    gains: np.ndarray,
    plans: np.ndarray,
    knot: int,
    costs: np.ndarray,
) -> None:
    substeps, dt = c.substeps, c.dt
    h = dt / substeps
    time_terms = substep_time_terms(0.0, 0.0, h)
    terms = np.empty(6)
    lumped = np.empty(3)
    offsets = np.empty(7)
    state = np.empty(LOCAL_STATE)
    for row in range(start.shape[0]):
        i = vessel[row]
        p = nominal[row]
        mass = _mass(p)
        state[:] = start[row]
        for q in range(3):
            offsets[4 + q] = residual[row, q]
        total = 0.0
        for step in range(plans.shape[1] * knot):
            offsets[:4] = plans[row, step // knot]
            sync, degree = 0.0, 0.0
            for k in range(neighbours.shape[1]):  # weight, theta_j now, rate_j
                theta_j = neighbours[row, k, 1] + step * dt * neighbours[row, k, 2]
                sync += neighbours[row, k, 0] * (state[6] - theta_j)
                degree += neighbours[row, k, 0]
            tau, rate = _local_command(
                c, i, state, sync, degree, speed[row], lumped, mass, gains, offsets, p
            )
            state[6] += dt * rate
            load = (tau[0] - residual[row, 0], tau[1] - residual[row, 1],
                    tau[2] - residual[row, 2], 0.0, 0.0, 0.0, 0.0, 0.0)  # fmt: skip
            x = (state[0], state[1], state[2], state[3], state[4], state[5])
            for _ in range(substeps):
                x = rk4_substep(p, 0.0, h, time_terms, x, load)
            for q in range(6):
                state[q] = x[q]
            point = path_values(c.path_kinds[i], c.path_params[i], state[6])
            z1, _, _ = path_frame(state[0], state[1], state[2], point)
            sync_after = 0.0
            for k in range(neighbours.shape[1]):
                theta_j = neighbours[row, k, 1] + (step + 1) * dt * neighbours[row, k, 2]
                sync_after += neighbours[row, k, 0] * (state[6] - theta_j)
            reward = step_reward(c.reward_params, dt, z1, sync_after, rate - speed[row],
                                 np.array(tau), c.tau_scale[i], terms)  # fmt: skip
            total -= reward
            if not math.isfinite(total):
                total = math.inf
                break
        costs[row] = total


@numba.njit(cache=True)
def local_rollouts(
    constants: tuple,
    vessel: np.ndarray,
    start: np.ndarray,
    neighbours: np.ndarray,
    speed: np.ndarray,
    residual: np.ndarray,
    nominal: np.ndarray,
    gains: np.ndarray,
    plans: np.ndarray,
    knot: int,
    costs: np.ndarray,
) -> None:
    """Roll R single-vessel prediction models out under their plans; each one's cost into ``costs``.

    The nominal model (no unmodeled dynamics, no environment) plus the
    estimated residual force held over the horizon; neighbours move at
    their communicated speed from their predicted present path variable.

    Args:
        constants: ``tuple(KernelConstants)`` of the scenario (paths, limits, reward, dt).
        vessel: (R,) int64 vessel index of each row.
        start: (R, ``LOCAL_STATE``) x, y, psi, u, v, r, theta now.
        neighbours: (R, K, 3) per slot: a_ij, theta_j predicted now, its rate (1/s).
        speed: (R,) v0 estimate (m/s).
        residual: (R, 3) residual force estimate (N, N, N m).
        nominal: (R, PARAM_SIZE) the model's vessel parameters per row.
        gains: The feedback's gains.
        plans: (R, knots, 4) offsets.
        knot: Control steps per knot.
        costs: (R,) out: the vessel's own cost over the horizon (-sum of rewards).
    """
    _local_rollouts(KernelConstants(*constants), vessel, start, neighbours, speed, residual,
                    nominal, gains, plans, knot, costs)  # fmt: skip


@numba.njit(cache=True)
def local_start(
    constants: tuple, obs: np.ndarray, start: np.ndarray, neighbours: np.ndarray
) -> None:
    """Each vessel's state from its observation, and its neighbours' predicted present theta.

    The pose follows from the path (a known constant of the mission), theta and
    z1; a neighbour's path variable is the one received, advanced by its packet
    age at its communicated speed (the slot's first message).

    Args:
        constants: ``tuple(KernelConstants)`` (the paths, dt).
        obs: (B, n, obs_dim) local observations.
        start: (B, n, ``LOCAL_STATE``) out: x, y, psi, u, v, r, theta.
        neighbours: (B, n, K, 3) out: per slot a_ij, theta_j now, its speed (1/s).
    """
    c = KernelConstants(*constants)
    slots = neighbours.shape[2]
    width = (obs.shape[2] - SLOTS) // max(slots, 1)
    for b in range(obs.shape[0]):
        for i in range(obs.shape[1]):
            o = obs[b, i]
            theta = o[THETA]
            target = path_values(c.path_kinds[i], c.path_params[i], theta)[0]
            start[b, i, 0], start[b, i, 1], start[b, i, 2] = frame_pose(
                target, o[Z1], o[Z1 + 1], o[Z1 + 2]
            )
            for q in range(3):
                start[b, i, 3 + q] = o[NU + q]
            start[b, i, 6] = theta
            for k in range(slots):
                base = SLOTS + k * width
                rate = o[base + SLOT_MSG]
                age = o[base + SLOT_AGE]
                neighbours[b, i, k, 0] = o[base + SLOT_WEIGHT]
                neighbours[b, i, k, 1] = theta + o[base + SLOT_DTHETA] + age * c.dt * rate
                neighbours[b, i, k, 2] = rate


@numba.njit(cache=True)
def local_commands(
    constants: tuple,
    start: np.ndarray,
    neighbours: np.ndarray,
    speed: np.ndarray,
    residual: np.ndarray,
    nominal: np.ndarray,
    gains: np.ndarray,
    offsets: np.ndarray,
    out: np.ndarray,
) -> None:
    """``mpc``'s commands (B, n, 4 + m) into ``out``: the first step of ``local_rollouts``.

    Args:
        constants: ``tuple(KernelConstants)``.
        start: (B, n, ``LOCAL_STATE``) from ``local_start``.
        neighbours: (B, n, K, 3) from ``local_start``.
        speed: (B, n) v0 estimates; also the message's entry 0 (the others are left as
            they are: zeros from the caller).
        residual: (B, n, 3) residual force estimates.
        nominal: (B, n, PARAM_SIZE) the model's vessel parameters.
        gains: The feedback's gains.
        offsets: (B, n, 4) the plans' current knots.
        out: (B, n, 4 + m) the actions.
    """
    c = KernelConstants(*constants)
    merged = np.empty(7)
    lumped = np.empty(3)
    for b in range(start.shape[0]):
        for i in range(start.shape[1]):
            sync, degree = 0.0, 0.0
            for k in range(neighbours.shape[2]):
                sync += neighbours[b, i, k, 0] * (start[b, i, 6] - neighbours[b, i, k, 1])
                degree += neighbours[b, i, k, 0]
            merged[:4] = offsets[b, i]
            merged[4:] = residual[b, i]
            p = nominal[b, i]
            tau, rate = _local_command(
                c, i, start[b, i], sync, degree, speed[b, i], lumped, _mass(p), gains, merged, p
            )
            for q in range(3):
                out[b, i, q] = tau[q]
            out[b, i, 3] = rate
            if out.shape[2] > 4:  # the message: the estimate in entry 0, the rest untouched
                out[b, i, 4] = _clipped(speed[b, i], -c.message_max, c.message_max)


@numba.njit(cache=True)
def observe_residual(
    nominal: np.ndarray, nu: np.ndarray, previous: np.ndarray, tau: np.ndarray, dt: float,
    gain: float, residual: np.ndarray,
) -> None:  # fmt: skip
    """One step of the disturbance observer of the residual force, per vessel.

    raw = tau - (C nu + D nu)(nu_mid) - M (nu - nu_prev) / dt on the nominal
    model (nu_mid the mean of the two velocities, tau the force applied in
    between), low-passed: residual += gain (raw - residual).

    Args:
        nominal: (B, n, PARAM_SIZE) the model's parameters.
        nu: (B, n, 3) velocity now.
        previous: (B, n, 3) velocity one step before.
        tau: (B, n, 3) the force applied over the step.
        dt: Control period (s).
        gain: Filter gain in (0, 1].
        residual: (B, n, 3) the estimate, updated in place.
    """
    for b in range(nu.shape[0]):
        for i in range(nu.shape[1]):
            p = nominal[b, i]
            mass = _mass(p)
            h = hydrodynamic_forces(
                p, 0.5 * (nu[b, i, 0] + previous[b, i, 0]), 0.5 * (nu[b, i, 1] + previous[b, i, 1]),
                0.5 * (nu[b, i, 2] + previous[b, i, 2]),
            )  # fmt: skip
            for q in range(3):
                inertia = 0.0
                for k in range(3):
                    inertia += mass[q, k] * (nu[b, i, k] - previous[b, i, k]) / dt
                raw = tau[b, i, q] - h[q] - inertia
                residual[b, i, q] += gain * (raw - residual[b, i, q])


@numba.njit(cache=True)
def hydrodynamics(params: np.ndarray, nu: np.ndarray, out: np.ndarray) -> None:
    """C(nu) nu + D(nu) nu (B, n, 3) into ``out``; parameters (B, n, PARAM_SIZE), nu (B, n, 3)."""
    for b in range(nu.shape[0]):
        for i in range(nu.shape[1]):
            h = hydrodynamic_forces(params[b, i], nu[b, i, 0], nu[b, i, 1], nu[b, i, 2])
            for q in range(3):
                out[b, i, q] = h[q]
