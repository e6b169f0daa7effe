"""A navigation filter under any analytic policy: pose and velocity estimated from noisy fixes.

With ``Scenario.sensors`` set (``cpf_env.model.sensors``), a vessel's
observation carries the path frame of its last noisy pose fix, held between
fixes and over lost ones, and maybe no velocity. The classic answer is a
Kalman filter on the vessel model (Fossen 2011, ch. 13). Per vessel, an
extended Kalman filter with the state

    x = [x, y, psi, u, v, r, b_u, b_v, b_r]

(pose, earth frame; velocity, body frame; and a slowly varying body-frame
acceleration b that absorbs the model error, current and mean wave force, the
filter's disturbance observer):

* predict, every control step, by one RK4 step of dt of the nominal model
  (``Scenario.vessel_models``: what the designer knows) under the applied
  force the observation reports, eta' = J(psi) nu, nu' = nominal(nu, tau) + b,
  b' = 0, with the Jacobian by central differences and process noise
  ``Q = diag(q) dt``;
* correct when a new fix arrives: the fix (x, y, psi) is reconstructed from
  the observation's z1 and t1 and the vessel's own path point (its theta and
  path are known on board); a fix that did not move since the last one is a
  held one (lost, or between fixes) and corrects nothing; the measurement
  noise is the scenario's ``position_std`` and ``heading_std``;
* with a velocity sensor, correct with the observed velocity as well.

``Filtered`` runs the filter and hands its inner policy the observation
rebuilt from the estimate (``nu``, ``z1``, ``t1``, ``t2``), everything else
as observed. It is deployable: it uses only the vessel's observation and the
scenario's known constants. ``nn_dsc_ekf``, ``mpc_tuned_ekf`` and ``ilos_ekf``
are the filter under ``nn_dsc``, ``mpc_tuned`` and ``ilos``.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baselines.ilos import ILOSPolicy
from baselines.mpc_tuned import MPCTuned
from baselines.nn_dsc import NNDSCPolicy
from baselines.policy import resolve_scenario
from cpf_env.envs.policy import Array, FleetPolicy
from cpf_env.model.paths import encode_paths, path_values
from cpf_env.model.plant import plant_rhs_given
from cpf_env.sim.observation import NU, T1, T2, TAU, THETA, Z1, path_frame, wrap_angle

__all__ = ["FILTER_NOISE", "Filtered", "ILOSFiltered", "MPCTunedFiltered", "NNDSCFiltered"]

#: Process noise spectral densities of the nine states (per second): pose (m^2/s, rad^2/s),
#: velocity (m^2/s^3, rad^2/s^3), the acceleration bias (m^2/s^5, rad^2/s^5).
FILTER_NOISE = (1e-8, 1e-8, 1e-8, 4e-4, 4e-4, 4e-3, 2.5e-5, 2.5e-5, 2.5e-4)
#: Initial variances of velocity (m^2/s^2, rad^2/s^2) and bias when the first fix arrives.
INITIAL_VARIANCE = (0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-3)
#: A fix that moved less than this (m, rad) since the last is the held one (float32 observations).
HELD_TOLERANCE = (1e-5, 1e-6)
#: Variance floor of a measurement (a noiseless sensor would make the update singular).
MEASUREMENT_FLOOR = 1e-10
STATES = 9


@numba.njit(cache=True)
def _transition(p: np.ndarray, x: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
    """One RK4 step of dt of the filter's model from ``x`` (9,) under force ``tau`` (3,)."""
    load = (tau[0], tau[1], tau[2], 0.0, 0.0, 0.0, 0.0, 0.0)
    out = x.copy()
    k = np.zeros((4, 6))
    for stage in range(4):
        y = x[:6].copy()
        if stage > 0:
            weight = dt if stage == 3 else 0.5 * dt
            y += weight * k[stage - 1]
        rhs = plant_rhs_given(p, 0.0, 0.0, y[2], y[3], y[4], y[5], load)
        for j in range(6):
            k[stage, j] = rhs[j] + (x[6 + j - 3] if j >= 3 else 0.0)
    for j in range(6):
        out[j] = x[j] + dt / 6.0 * (k[0, j] + 2.0 * k[1, j] + 2.0 * k[2, j] + k[3, j])
    return out


@numba.njit(cache=True)
def _predict(p: np.ndarray, x: np.ndarray, cov: np.ndarray, tau: np.ndarray, dt: float,
             q: np.ndarray) -> None:  # fmt: skip
    """The EKF's time update in place: x <- f(x), P <- F P F^T + diag(q) dt."""
    jacobian = np.empty((STATES, STATES))
    for j in range(STATES):
        step = 1e-6 * max(1.0, abs(x[j]))
        up, down = x.copy(), x.copy()
        up[j] += step
        down[j] -= step
        column = (_transition(p, up, tau, dt) - _transition(p, down, tau, dt)) / (2.0 * step)
        jacobian[:, j] = column
    x[:] = _transition(p, x, tau, dt)
    cov[:, :] = jacobian @ cov @ jacobian.T
    for j in range(STATES):
        cov[j, j] += q[j] * dt


@numba.njit(cache=True)
def _correct(x: np.ndarray, cov: np.ndarray, first: int, values: np.ndarray,
             variances: np.ndarray, angle: int) -> None:  # fmt: skip
    """The EKF's measurement update in place for states first .. first + len(values) - 1.

    ``angle`` is the index (within ``values``) of a heading, whose innovation is
    wrapped, or -1.
    """
    m = values.shape[0]
    innovation = np.empty(m)
    for j in range(m):
        innovation[j] = values[j] - x[first + j]
        if j == angle:
            innovation[j] = wrap_angle(innovation[j])
    s = cov[first : first + m, first : first + m].copy()
    for j in range(m):
        s[j, j] += max(variances[j], MEASUREMENT_FLOOR)
    gain = np.ascontiguousarray(cov[:, first : first + m]) @ np.ascontiguousarray(np.linalg.inv(s))
    x += gain @ innovation
    keep = np.eye(STATES)
    keep[:, first : first + m] -= gain
    cov[:, :] = keep @ cov
    cov[:, :] = 0.5 * (cov + cov.T)


@numba.njit(cache=True)
def filter_rows(obs: np.ndarray, index: np.ndarray, kinds: np.ndarray, paths: np.ndarray,
                nominal: np.ndarray, dt: float, sensor_variances: np.ndarray,
                velocity_measured: bool, q: np.ndarray, initial: np.ndarray,
                state: np.ndarray, cov: np.ndarray, last_fix: np.ndarray, ready: np.ndarray,
                out: np.ndarray) -> None:  # fmt: skip
    """Filter one step of every listed fleet and write the estimated observations.

    Args:
        obs: (rows, n, obs_dim) float32 observations.
        index: (rows,) int64 fleet of each row.
        kinds: (n,) int64 path kinds.
        paths: (n, PATH_PARAM_SIZE) path parameters (``encode_paths``).
        nominal: (n, PARAM_SIZE) nominal vessel parameters.
        dt: Control period (s).
        sensor_variances: (3,) x, y (m^2), psi (rad^2) variances of a fix.
        velocity_measured: Whether ``obs``'s nu is a measurement.
        q: (9,) process noise densities (``FILTER_NOISE``).
        initial: (6,) initial velocity and bias variances (``INITIAL_VARIANCE``).
        state: (F, n, 9) estimates (written).
        cov: (F, n, 9, 9) their covariances (written).
        last_fix: (F, n, 3) the last fix each filter corrected with (written).
        ready: (F, n) bool, whether each filter has started (written).
        out: (rows, n, obs_dim) float32, the estimated observations (written).
    """
    n = obs.shape[1]
    pose_variances = np.empty(3)
    for row in range(obs.shape[0]):
        f = index[row]
        for i in range(n):
            o = obs[row, i]
            point = path_values(kinds[i], paths[i], float(o[THETA]))
            target, first, _ = point
            heading = math.atan2(first[1], first[0]) - math.atan2(float(o[T1 + 1]), float(o[T1]))
            c, s = math.cos(heading), math.sin(heading)
            fix = np.array((target[0] + c * o[Z1] - s * o[Z1 + 1],
                            target[1] + s * o[Z1] + c * o[Z1 + 1], heading))  # fmt: skip
            x, p = state[f, i], cov[f, i]
            if not ready[f, i]:
                x[:] = 0.0
                x[0], x[1], x[2] = fix[0], fix[1], fix[2]
                if velocity_measured:
                    for k in range(3):
                        x[3 + k] = o[NU + k]
                p[:, :] = 0.0
                for k in range(3):
                    p[k, k] = max(sensor_variances[k], MEASUREMENT_FLOOR)
                for k in range(6):
                    p[3 + k, 3 + k] = initial[k]
                last_fix[f, i] = fix
                ready[f, i] = True
            else:
                tau = np.array((float(o[TAU]), float(o[TAU + 1]), float(o[TAU + 2])))
                _predict(nominal[i], x, p, tau, dt, q)
                moved = (
                    abs(fix[0] - last_fix[f, i, 0]) > HELD_TOLERANCE[0]
                    or abs(fix[1] - last_fix[f, i, 1]) > HELD_TOLERANCE[0]
                    or abs(wrap_angle(fix[2] - last_fix[f, i, 2])) > HELD_TOLERANCE[1]
                )
                if moved:
                    for k in range(3):
                        pose_variances[k] = sensor_variances[k]
                    _correct(x, p, 0, fix, pose_variances, 2)
                    last_fix[f, i] = fix
                if velocity_measured:
                    measured = np.array((float(o[NU]), float(o[NU + 1]), float(o[NU + 2])))
                    _correct(x, p, 3, measured, np.zeros(3), -1)
            seen = out[row, i]
            seen[:] = o
            z1, t1, t2 = path_frame(x[0], x[1], x[2], point)
            for k in range(3):
                seen[NU + k] = x[3 + k]
                seen[Z1 + k] = z1[k]
                seen[T1 + k] = t1[k]
                seen[T2 + k] = t2[k]


class Filtered(FleetPolicy):
    """An analytic policy acting on the navigation filter's estimate (module docstring).

    Subclasses name the policy (``name``) and the policy under the filter (``inner``).

    Args:
        env: An env, a simulator or a ``Scenario`` (``resolve_scenario``).
        **options: Passed to the inner policy.
    """

    name: ClassVar[str]
    inner: ClassVar[type[FleetPolicy]]

    def __init__(self, env: object, **options: Any) -> None:
        scenario = resolve_scenario(env)
        self.policy = self.inner(env, **options)  # type: ignore[call-arg]
        self.n = scenario.n
        self.obs_dim, self.act_dim = self.policy.obs_dim, self.policy.act_dim
        self.message_entries = self.policy.message_entries
        self.agents = self.policy.agents
        kinds, paths = encode_paths(scenario.paths)
        self._kinds = np.ascontiguousarray(kinds, dtype=np.int64)
        self._paths = np.ascontiguousarray(paths, dtype=np.float64)
        self._nominal = np.stack([model.to_params() for model in scenario.vessel_models])
        sensors = scenario.sensors
        self._variances = np.square(sensors.fix_std)
        self._velocity = bool(sensors.velocity)
        self._dt = float(scenario.dt)
        self._q = np.array(FILTER_NOISE)
        self._initial = np.array(INITIAL_VARIANCE)
        self._fleets = 0
        self.diagnostics: dict[str, Array] = {}
        self.reset()

    def _allocate(self, fleets: int) -> None:
        """Filter states for ``fleets`` fleets, none started."""
        self._fleets = fleets
        self._state = np.zeros((fleets, self.n, STATES))
        self._cov = np.zeros((fleets, self.n, STATES, STATES))
        self._last_fix = np.zeros((fleets, self.n, 3))
        self._ready = np.zeros((fleets, self.n), dtype=bool)

    def reset(self, seed: int | None = None) -> None:
        """Forget every fleet's estimate and the inner policy's states."""
        self.policy.reset(seed)
        self._allocate(self._fleets)

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget the listed fleets' estimates (they start again at their next fix)."""
        self.policy.reset_fleets(fleets)
        self._ready[np.asarray(fleets, dtype=np.int64)] = False

    def estimate(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> NDArray[np.float32]:
        """Filter one step and return the observation rebuilt from the estimate (rows, n, dim)."""
        batch = np.ascontiguousarray(obs, dtype=np.float32)
        if batch.ndim != 3 or batch.shape[1] != self.n:
            raise ValueError(f"obs must be (B, {self.n}, obs_dim), got shape {batch.shape}.")
        if fleets is None:
            index = np.arange(batch.shape[0], dtype=np.int64)
            if batch.shape[0] != self._fleets:
                self._allocate(batch.shape[0])
        else:
            index = np.ascontiguousarray(fleets, dtype=np.int64)
            if (
                index.shape != (batch.shape[0],)
                or np.any(index < 0)
                or np.any(index >= self._fleets)
            ):
                raise ValueError(
                    f"fleets must be {batch.shape[0]} indices below {self._fleets} (the batch "
                    f"of the last full act_batch), got {np.asarray(fleets)!r}."
                )
        out = np.empty_like(batch)
        filter_rows(batch, index, self._kinds, self._paths, self._nominal, self._dt,
                    self._variances, self._velocity, self._q, self._initial, self._state,
                    self._cov, self._last_fix, self._ready, out)  # fmt: skip
        return out

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """The inner policy's actions on the estimated observations."""
        actions = self.policy.act_batch(self.estimate(obs, fleets), fleets)
        self.diagnostics = {**self.policy.diagnostics, "estimate": self._state.copy()}
        return actions


class NNDSCFiltered(Filtered):
    """``nn_dsc`` on the navigation filter's estimate."""

    name = "nn_dsc_ekf"
    inner = NNDSCPolicy


class MPCTunedFiltered(Filtered):
    """``mpc_tuned`` on the navigation filter's estimate."""

    name = "mpc_tuned_ekf"
    inner = MPCTuned


class ILOSFiltered(Filtered):
    """``ilos`` on the navigation filter's estimate."""

    name = "ilos_ekf"
    inner = ILOSPolicy
