"""The compiled fleet step: plant, paths, links, observations and rewards, fused.

One call advances B fleets x n vessels by one control period:

1. saturate the force command per axis (and, with thruster dynamics, let the
   applied force follow it with a lag and a slew limit: ``cpf_env.model.actuators``),
   and clip the path-variable rate and the message (``docs/model.md``, "Input
   saturation");
2. integrate the plant (``cpf_env.model.plant``) with ``substeps`` RK4 steps, the
   command and the environmental forces held over the control period
   (``docs/model.md``, "Time discretization");
3. advance theta by the commanded rate (exact for a held rate);
4. advance the Gauss-Markov disturbance states exactly;
5. send each vessel's packet (theta, message) and deliver, through the active
   topology, the packets sent ``delay`` steps ago that are not lost;
6. take the sensors' pose fixes (``cpf_env.model.sensors``; the true pose by
   default) and write observations, rewards, error metrics and termination flags.

Arrays come in two named tuples (``cpf_env.sim.arrays``) built by
``cpf_env.sim.fleet``: ``FleetArrays`` (mutable state, leading axis B) and
``KernelConstants`` (scenario constants); the entry kernels at the bottom take
them as plain tuples and check the step's inputs before changing anything.
Everything per vessel is scalar code so numba compiles one fused loop; the
outer loop over fleets runs in parallel and fleets never interact, so fleet k
computes the same bits whatever B is. Within a fleet the plant advances sub-step
by sub-step over the vessels, which share the disturbance's time terms; each
vessel's arithmetic is that of ``cpf_env.model.plant.rk4_period``. The helpers
are inlined into ``step_fleet``: a call that passes the two named tuples costs
an atomic reference count per array.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import prange

from cpf_env.model import counter_rng
from cpf_env.model.disturbances import (
    D_CURRENT_MEAN,
    D_CURRENT_STD,
    D_CURRENT_TC,
    D_SCALE,
    D_WAVE_MEAN,
    D_WAVE_STD,
    D_WAVE_TC,
    D_WIND_MEAN,
    D_WIND_STD,
    D_WIND_TC,
    gauss_markov_drift,
    gauss_markov_factors,
    gauss_markov_needs_noise,
    gauss_markov_update,
)
from cpf_env.model.paths import path_values
from cpf_env.model.plant import plant_rhs, rk4_substep, substep_time_terms
from cpf_env.sim.arrays import (
    ERR_HEADING,
    ERR_PATH,
    ERR_SPEED,
    ERR_SYNC,
    FleetArrays,
    KernelConstants,
)
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
    THETA,
    V0,
    Z1,
    path_frame,
)
from cpf_env.sim.reward import failure_penalty, separation_term, step_reward


@numba.njit(cache=True, inline="always")
def _clip(x: float, low: float, high: float) -> float:
    return min(max(x, low), high)


@numba.njit(cache=True, inline="always")
def topology_index(c: KernelConstants, step: int) -> int:
    """Index of the topology member active at control ``step``."""
    local = step % c.switch_period if c.switch_period > 0 else step
    index = 0
    for t in range(c.switch_steps.shape[0]):
        if c.switch_steps[t] <= local:
            index = t
    return index


@numba.njit(cache=True, inline="always")
def leader_speed(c: KernelConstants, time: float) -> float:
    """v0 (m/s) of the piecewise-constant schedule at ``time`` (s)."""
    value = c.v0_values[0]
    for k in range(c.v0_times.shape[0]):
        if c.v0_times[k] <= time:
            value = c.v0_values[k]
    return value


@numba.njit(cache=True, inline="always")
def _load(a: FleetArrays, b: int, i: int, tau: np.ndarray) -> tuple:
    """The plant's held inputs for vessel i of fleet b under applied force ``tau`` (3,)."""
    return (
        tau[0], tau[1], tau[2],
        a.waves[b, i, 0] + a.wind[b, i, 0],
        a.waves[b, i, 1] + a.wind[b, i, 1],
        a.waves[b, i, 2] + a.wind[b, i, 2],
        a.current[b, 0], a.current[b, 1],
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _integrate_fleet(a: FleetArrays, c: KernelConstants, b: int, t0: float) -> None:
    """RK4 over one control period for every vessel of fleet b, forces held.

    Sub-step by sub-step, each vessel in turn: the vessels share the time
    terms of the paper's disturbance (one sine per fleet and time instead of
    one per vessel), and each vessel's state passes through ``rk4_substep``
    exactly as in ``cpf_env.model.plant.rk4_period``.
    """
    scale, h = c.disturbances[D_SCALE], c.dt / c.substeps
    for k in range(c.substeps):
        time_terms = substep_time_terms(scale, t0 + k * h, h)
        for i in range(a.eta.shape[1]):
            state = (a.eta[b, i, 0], a.eta[b, i, 1], a.eta[b, i, 2],
                     a.nu[b, i, 0], a.nu[b, i, 1], a.nu[b, i, 2])  # fmt: skip
            x, y, psi, u, v, r = rk4_substep(
                a.params[b, i], scale, h, time_terms, state, _load(a, b, i, a.tau_applied[b, i])
            )
            a.eta[b, i, 0], a.eta[b, i, 1], a.eta[b, i, 2] = x, y, psi
            a.nu[b, i, 0], a.nu[b, i, 1], a.nu[b, i, 2] = u, v, r


@numba.njit(cache=True)
def vessel_acceleration(
    a: FleetArrays, c: KernelConstants, b: int, i: int, tau: np.ndarray
) -> tuple[float, float, float]:
    """True body acceleration nu' of vessel i of fleet b at its current state under ``tau`` (3,).

    Uses the same right-hand side as the integrator, with the environmental
    forces and current of the current step; for diagnostics (e.g. the true
    lumped uncertainty the paper's NN learns), not used by the step itself.
    """
    rhs = plant_rhs(a.params[b, i], c.disturbances[D_SCALE], a.step[b] * c.dt, a.eta[b, i, 2],
                    a.nu[b, i, 0], a.nu[b, i, 1], a.nu[b, i, 2], _load(a, b, i, tau))  # fmt: skip
    return rhs[3], rhs[4], rhs[5]


@numba.njit(cache=True)
def plant_accelerations(
    a: FleetArrays, c: KernelConstants, tau: np.ndarray, out: np.ndarray
) -> None:
    """True body accelerations nu' (B, n, 3) under force ``tau`` (B, n, 3), per vessel as above."""
    for b in range(a.eta.shape[0]):
        for i in range(a.eta.shape[1]):
            out[b, i, 0], out[b, i, 1], out[b, i, 2] = vessel_acceleration(a, c, b, i, tau[b, i])


@numba.njit(cache=True, inline="always")
def _apply_action(a: FleetArrays, c: KernelConstants, actions: np.ndarray, b: int, i: int) -> None:
    """Store the command, saturate it per axis (through the thrusters) and clip rate and message."""
    for k in range(3):
        command = actions[b, i, k]
        a.tau_command[b, i, k] = command
        target = _clip(command, c.tau_min[i, k], c.tau_max[i, k])
        if c.instant_thrusters:
            a.tau_applied[b, i, k] = target
        else:  # cpf_env.model.actuators: the exact lag step, then the slew limit
            last = a.tau_applied[b, i, k]
            lagged = c.thruster_decay * last + (1.0 - c.thruster_decay) * target
            slew = c.thruster_slew[k]
            a.tau_applied[b, i, k] = last + _clip(lagged - last, -slew, slew)
    a.theta_dot[b, i] = _clip(actions[b, i, 3], -c.theta_dot_max, c.theta_dot_max)
    for q in range(a.message.shape[2]):
        a.message[b, i, q] = _clip(actions[b, i, 4 + q], -c.message_max, c.message_max)


@numba.njit(cache=True, inline="always")
def _gauss_markov(x: float, mean: float, a: float, spread: float, key: np.uint64, step: int,
                  stream: int, index: int) -> float:  # fmt: skip
    """One exact Gauss-Markov step; the normal is drawn only when it can change the result."""
    drift = gauss_markov_drift(x, mean, a)
    if not gauss_markov_needs_noise(drift, spread):
        return drift
    return gauss_markov_update(drift, spread, counter_rng.normal(key, step, stream, index))


@numba.njit(cache=True, inline="always")
def _advance_disturbances(a: FleetArrays, c: KernelConstants, b: int, step: int) -> None:
    """Advance wave, wind and current Gauss-Markov states by one control period.

    Draws are counter-based (a pure function of key, step, stream and index),
    so a draw skipped because it cannot change the state changes no other draw.
    """
    d, key = c.disturbances, a.key[b]
    wave_a, wave_root = gauss_markov_factors(d[D_WAVE_TC], c.dt)
    wind_a, wind_root = gauss_markov_factors(d[D_WIND_TC], c.dt)
    current_a, current_root = gauss_markov_factors(d[D_CURRENT_TC], c.dt)
    # Vessels outer, components inner, as the draws were written: a loop over
    # vessels inside would be vectorized, and with Intel's SVML installed numba
    # maps vector logarithms and cosines to SVML, whose last bits differ from libm's.
    for i in range(a.eta.shape[1]):
        for k in range(3):
            index = 3 * i + k
            a.waves[b, i, k] = _gauss_markov(a.waves[b, i, k], d[D_WAVE_MEAN + k], wave_a,
                                             d[D_WAVE_STD + k] * wave_root, key, step,
                                             counter_rng.STREAM_WAVES, index)  # fmt: skip
            a.wind[b, i, k] = _gauss_markov(a.wind[b, i, k], d[D_WIND_MEAN + k], wind_a,
                                            d[D_WIND_STD + k] * wind_root, key, step,
                                            counter_rng.STREAM_WIND, index)  # fmt: skip
    current_spread = d[D_CURRENT_STD] * current_root
    for k in range(2):
        a.current[b, k] = _gauss_markov(a.current[b, k], d[D_CURRENT_MEAN + k], current_a,
                                        current_spread, key, step,
                                        counter_rng.STREAM_CURRENT, k)  # fmt: skip


@numba.njit(cache=True, inline="always")
def _exchange_messages(a: FleetArrays, c: KernelConstants, b: int, step: int) -> None:
    """Send this step's packets and deliver those sent ``delay`` steps ago.

    ``step`` is the index of the step being completed; packets carry theta
    after it and are stamped ``step + 1`` (the observation time).
    """
    n, depth = a.eta.shape[1], a.history.shape[1]
    m = a.message.shape[2]
    write = step % depth
    for i in range(n):
        a.history[b, write, i, 0] = a.theta[b, i]
        for q in range(m):
            a.history[b, write, i, 1 + q] = a.message[b, i, q]
    sent = step - c.delay
    if sent < 0:
        return
    read = sent % depth
    member = topology_index(c, step + 1)
    for i in range(n):
        for k in range(c.slots.shape[1]):
            j = c.slots[i, k]
            if j < 0 or c.slot_weights[member, i, k] == 0.0:
                continue
            if c.loss_probability > 0.0:
                draw = counter_rng.uniform(
                    a.key[b], step, counter_rng.STREAM_LOSS, i * c.slots.shape[1] + k
                )
                if draw < c.loss_probability:
                    continue
            a.recv_theta[b, i, k] = a.history[b, read, j, 0]
            for q in range(m):
                a.recv_message[b, i, k, q] = a.history[b, read, j, 1 + q]
            a.recv_step[b, i, k] = sent + 1


@numba.njit(cache=True, inline="always")
def _take_fix(a: FleetArrays, c: KernelConstants, b: int, i: int, step: int) -> None:
    """Vessel i's pose fix at ``step``, if one is scheduled and not lost; else the held one.

    A fix is scheduled every ``fix_period`` steps from the reset (step 0, never
    lost); it is the true pose plus independent normal noise on x, y and psi.
    """
    if step % c.fix_period != 0:
        return
    if step > 0 and c.fix_dropout > 0.0:
        if counter_rng.uniform(a.key[b], step, counter_rng.STREAM_DROPOUT, i) < c.fix_dropout:
            return
    for k in range(3):
        noise = 0.0
        if c.fix_noise[k] > 0.0:
            noise = c.fix_noise[k] * counter_rng.normal(a.key[b], step, counter_rng.STREAM_FIX,
                                                        3 * i + k)  # fmt: skip
        a.fix[b, i, k] = a.eta[b, i, k] + noise


@numba.njit(cache=True, inline="always")
def observe_fleet(a: FleetArrays, c: KernelConstants, b: int, speed_reference: float) -> None:
    """Write observations, errors, rewards and flags of fleet b at its current step.

    Args:
        a: Fleet arrays.
        c: Constants.
        b: Fleet index.
        speed_reference: v0 (m/s) the last step's rate is scored against.
    """
    n, n_slots = a.eta.shape[1], c.slots.shape[1]
    m = a.message.shape[2]
    step = a.step[b]
    member = topology_index(c, step)
    v0 = leader_speed(c, step * c.dt)
    terminated = False
    finite = True
    total = 0.0
    for i in range(n):
        obs = a.obs[b, i]
        point = path_values(c.path_kinds[i], c.path_params[i], a.theta[b, i])
        z1, t1, t2 = path_frame(a.eta[b, i, 0], a.eta[b, i, 1], a.eta[b, i, 2], point)
        if c.ideal_sensors:
            seen_z1, seen_t1, seen_t2 = z1, t1, t2
            for k in range(3):
                a.fix[b, i, k] = a.eta[b, i, k]
        else:  # cpf_env.model.sensors: the observation is the held fix's
            _take_fix(a, c, b, i, step)
            seen_z1, seen_t1, seen_t2 = path_frame(
                a.fix[b, i, 0], a.fix[b, i, 1], a.fix[b, i, 2], point
            )
        for k in range(3):
            obs[NU + k] = a.nu[b, i, k] if c.velocity_measured else 0.0
            obs[Z1 + k] = seen_z1[k]
            obs[T1 + k] = seen_t1[k]
            obs[T2 + k] = seen_t2[k]
            obs[TAU + k] = a.tau_applied[b, i, k]
            finite = finite and math.isfinite(a.eta[b, i, k]) and math.isfinite(a.nu[b, i, k])
        obs[THETA] = a.theta[b, i]
        heard = c.leaders[member, i]
        obs[LEADER] = heard
        obs[V0] = v0 if heard > 0.0 else 0.0
        sync = 0.0
        for k in range(n_slots):
            base = SLOTS + k * (SLOT_MSG + m)
            weight = c.slot_weights[member, i, k]
            j = c.slots[i, k]
            if weight == 0.0:
                for q in range(SLOT_MSG + m):
                    obs[base + q] = 0.0
                continue
            sync += weight * (a.theta[b, i] - a.theta[b, j])
            obs[base + SLOT_WEIGHT] = weight
            obs[base + SLOT_DTHETA] = a.recv_theta[b, i, k] - a.theta[b, i]
            obs[base + SLOT_AGE] = step - a.recv_step[b, i, k]
            for q in range(m):
                obs[base + SLOT_MSG + q] = a.recv_message[b, i, k, q]
        path_error = math.sqrt(z1[0] ** 2 + z1[1] ** 2)
        speed_error = a.theta_dot[b, i] - speed_reference
        a.errors[b, i, ERR_PATH] = path_error
        a.errors[b, i, ERR_HEADING] = z1[2]
        a.errors[b, i, ERR_SYNC] = sync
        a.errors[b, i, ERR_SPEED] = speed_error
        reward = step_reward(
            c.reward_params,
            c.dt,
            z1,
            sync,
            speed_error,
            a.tau_applied[b, i],
            c.tau_scale[i],
            a.reward_terms[b, i],
        )
        collided = False
        if c.separation[0] > 0.0:  # cpf_env.model.separation
            term, collided = separation_term(c.separation, c.dt, a.eta[b], i)
            a.reward_terms[b, i, 6] = term
            reward += term
        else:
            a.reward_terms[b, i, 6] = 0.0
        a.reward[b, i] = reward
        total += reward
        terminated = terminated or path_error > c.max_path_error or collided
    if terminated and not a.terminated[b]:  # the step the fleet leaves its path
        remaining = max(c.max_steps - step, 0) * c.dt
        penalty = failure_penalty(c.reward_params, remaining, c.max_path_error)
        for i in range(n):
            a.reward_terms[b, i, 5] = penalty
            a.reward[b, i] += penalty
            total += penalty
    if c.team_reward:
        for i in range(n):
            a.reward[b, i] = total / n
    a.terminated[b] = a.terminated[b] or terminated  # latched; reset clears it
    a.nonfinite[b] = not finite


@numba.njit(cache=True)
def step_fleet(a: FleetArrays, c: KernelConstants, actions: np.ndarray, b: int) -> None:
    """Advance fleet b by one control period (see module docstring)."""
    step = a.step[b]
    t0 = step * c.dt
    v0 = leader_speed(c, t0)
    for i in range(a.eta.shape[1]):
        _apply_action(a, c, actions, b, i)
        a.theta[b, i] += c.dt * a.theta_dot[b, i]
    _integrate_fleet(a, c, b, t0)
    _advance_disturbances(a, c, b, step)
    _exchange_messages(a, c, b, step)
    a.step[b] = step + 1
    observe_fleet(a, c, b, v0)


@numba.njit(cache=True)
def reset_observation(a: FleetArrays, c: KernelConstants, b: int) -> None:
    """Observe fleet b right after a reset; its reward and reward terms are zero."""
    observe_fleet(a, c, b, leader_speed(c, a.step[b] * c.dt))
    for i in range(a.eta.shape[1]):
        a.reward[b, i] = 0.0
        for k in range(a.reward_terms.shape[2]):
            a.reward_terms[b, i, k] = 0.0


# The loops over fleets only dispatch: numba's parfor pass can drop writes made
# to named-tuple fields directly in a prange body, so every write lives in a
# callee. Each comes serial (small B: no thread start-up, no waiting for a busy
# core) and parallel; a fleet computes the same bits in either. They take the
# fields of ``FleetArrays`` and ``KernelConstants`` as plain tuples and rebuild
# the named tuples inside: numba types a named tuple argument on a slow Python
# path (about 4 us a call more than a tuple of the same arrays).

#: What an entry step kernel did: stepped every fleet; stepped nothing because a
#: fleet had diverged before; stepped nothing because an action is not finite;
#: stepped every fleet and the plant of at least one diverged.
STEPPED, DIVERGED_BEFORE, NONFINITE_ACTION, DIVERGED = 0, 1, 2, 3


@numba.njit(cache=True)
def _step_refusal(a: FleetArrays, actions: np.ndarray) -> int:
    """Why the step may not run (``DIVERGED_BEFORE``, ``NONFINITE_ACTION``) or ``STEPPED``."""
    for b in range(a.nonfinite.shape[0]):
        if a.nonfinite[b]:
            return DIVERGED_BEFORE
    for b in range(actions.shape[0]):
        for i in range(actions.shape[1]):
            for k in range(actions.shape[2]):
                if not math.isfinite(actions[b, i, k]):
                    return NONFINITE_ACTION
    return STEPPED


@numba.njit(cache=True)
def _step_outcome(a: FleetArrays) -> int:
    """``DIVERGED`` if a fleet's state became non-finite in the step just made, else ``STEPPED``."""
    for b in range(a.nonfinite.shape[0]):
        if a.nonfinite[b]:
            return DIVERGED
    return STEPPED


@numba.njit(cache=True)
def step_fleets_serial(arrays: tuple, constants: tuple, actions: np.ndarray) -> int:
    """Advance every fleet by one control period, one after the other.

    Args:
        arrays: ``tuple(FleetArrays)``, the state (written).
        constants: ``tuple(KernelConstants)``, the scenario.
        actions: (B, n, 4 + m) float64, C-contiguous.

    Returns:
        ``STEPPED``, ``DIVERGED_BEFORE``, ``NONFINITE_ACTION`` (nothing changed) or ``DIVERGED``.
    """
    a, c = FleetArrays(*arrays), KernelConstants(*constants)
    refusal = _step_refusal(a, actions)
    if refusal != STEPPED:
        return refusal
    for b in range(a.eta.shape[0]):
        step_fleet(a, c, actions, b)
    return _step_outcome(a)


@numba.njit(cache=True, parallel=True)
def step_fleets_parallel(arrays: tuple, constants: tuple, actions: np.ndarray) -> int:
    """``step_fleets_serial`` with the fleets in parallel threads (the checks stay serial)."""
    a, c = FleetArrays(*arrays), KernelConstants(*constants)
    refusal = _step_refusal(a, actions)
    if refusal != STEPPED:
        return refusal
    for index in prange(a.eta.shape[0]):
        # int64 as the serial loop's index: prange's is uint64, which would compile
        # ``step_fleet`` a second time
        step_fleet(a, c, actions, int(np.int64(index)))
    return _step_outcome(a)


@numba.njit(cache=True)
def observe_fleets_serial(arrays: tuple, constants: tuple, fleets: np.ndarray) -> None:
    """Observe the listed fleets (int64 indices) after a reset, one after the other."""
    a, c = FleetArrays(*arrays), KernelConstants(*constants)
    for index in range(fleets.shape[0]):
        reset_observation(a, c, fleets[index])


@numba.njit(cache=True, parallel=True)
def observe_fleets_parallel(arrays: tuple, constants: tuple, fleets: np.ndarray) -> None:
    """Observe the listed fleets (int64 indices) after a reset, in parallel threads."""
    a, c = FleetArrays(*arrays), KernelConstants(*constants)
    for index in prange(fleets.shape[0]):
        reset_observation(a, c, fleets[index])
