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

No single process noise suits every sea: on the hard track's training seeds
the filter under ``mpc_tuned`` costs least with 0.003-0.01 times
``FILTER_NOISE``'s velocity and bias densities in calm water and with 3
times them in waves (``studies/hard_track/filter_tuning.py``). The adaptive
answer is a bank of filters (multiple-model adaptive estimation, Magill
1965): M filters differing only in that factor (``ADAPTIVE_SCALES``) run side
by side, each fix adds the log-likelihood of each filter's innovation,
log N(0, S), to its score, discounted by ``FORGETTING`` per fix, and the
estimate is the filters' states weighted by the softmax of their scores.

``Filtered`` runs the filter (a bank of one, ``noise_scales = (1,)``, or
several) and hands its inner policy the observation rebuilt from the
estimate (``nu``, ``z1``, ``t1``, ``t2``), everything else as observed. It is
deployable: it uses only the vessel's observation and the scenario's known
constants. ``nn_dsc_ekf``, ``mpc_tuned_ekf`` and ``ilos_ekf`` are one filter
under ``nn_dsc``, ``mpc_tuned`` and ``ilos``; ``mpc_tuned_mmae`` is the bank
under ``mpc_tuned``.
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
from cpf_env.envs.policy import Array, FleetPolicy, fleet_mask
from cpf_env.model.paths import encode_paths, path_values
from cpf_env.model.plant import plant_rhs_given
from cpf_env.sim.observation import NU, T1, T2, TAU, THETA, Z1, path_frame, wrap_angle

__all__ = [
    "ADAPTIVE_SCALES",
    "FILTER_NOISE",
    "Filtered",
    "ILOSFiltered",
    "MPCTunedAdaptive",
    "MPCTunedFiltered",
    "NNDSCFiltered",
]

#: Process noise spectral densities of the nine states (per second): pose (m^2/s, rad^2/s),
#: velocity (m^2/s^3, rad^2/s^3), the acceleration bias (m^2/s^5, rad^2/s^5).
FILTER_NOISE = (1e-8, 1e-8, 1e-8, 4e-4, 4e-4, 4e-3, 2.5e-5, 2.5e-5, 2.5e-4)
#: The adaptive bank's factors on the velocity and bias densities of ``FILTER_NOISE``, from
#: calm water to waves, 30 times apart (``studies/hard_track/filter_tuning.py``).
ADAPTIVE_SCALES = (0.001, 0.03, 1.0, 30.0)
#: Discount of each filter's log-likelihood per fix (its memory: 1 / (1 - 0.98) = 50 fixes, 10 s
#: at 5 Hz).
FORGETTING = 0.98
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
             variances: np.ndarray, angle: int) -> float:  # fmt: skip
    """The EKF's measurement update in place for states first .. first + len(values) - 1.

    ``angle`` is the index (within ``values``) of a heading, whose innovation is
    wrapped, or -1. Returns the log-likelihood of the innovation, log N(0, S).
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
    inverse = np.ascontiguousarray(np.linalg.inv(s))
    gain = np.ascontiguousarray(cov[:, first : first + m]) @ inverse
    x += gain @ innovation
    keep = np.eye(STATES)
    keep[:, first : first + m] -= gain
    cov[:, :] = keep @ cov
    cov[:, :] = 0.5 * (cov + cov.T)
    return -0.5 * (innovation @ inverse @ innovation + math.log(np.linalg.det(s))
                   + m * math.log(2.0 * math.pi))  # fmt: skip


@numba.njit(cache=True)
def _blend(bank: np.ndarray, loglik: np.ndarray, out: np.ndarray) -> None:
    """The bank's estimate: its filters' states weighted by their likelihoods, into ``out`` (9,).

    ``bank`` is (M, 9), ``loglik`` (M,) the filters' discounted log-likelihoods; the
    weights are their softmax, the headings averaged as offsets from the likeliest one's.
    A bank of one is its filter's state, as it is.
    """
    if bank.shape[0] == 1:
        out[:] = bank[0]
        return
    best = 0
    for m in range(bank.shape[0]):
        if loglik[m] > loglik[best]:
            best = m
    weights = np.exp(loglik - loglik[best])
    weights /= weights.sum()
    out[:] = 0.0
    for m in range(bank.shape[0]):
        for j in range(STATES):
            if j == 2:
                out[j] += weights[m] * wrap_angle(bank[m, j] - bank[best, j])
            else:
                out[j] += weights[m] * bank[m, j]
    out[2] = wrap_angle(out[2] + bank[best, 2])


@numba.njit(cache=True)
def filter_rows(obs: np.ndarray, index: np.ndarray, kinds: np.ndarray, paths: np.ndarray,
                nominal: np.ndarray, dt: float, sensor_variances: np.ndarray,
                velocity_measured: bool, q: np.ndarray, scales: np.ndarray, forgetting: float,
                initial: np.ndarray, bank: np.ndarray, cov: np.ndarray, loglik: np.ndarray,
                last_fix: np.ndarray, ready: np.ndarray, state: np.ndarray,
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
        scales: (M,) the bank's factors on the velocity and bias densities (one filter: (1,)).
        forgetting: Discount of the log-likelihoods per fix, in (0, 1] (``FORGETTING``).
        initial: (6,) initial velocity and bias variances (``INITIAL_VARIANCE``).
        bank: (F, n, M, 9) each filter's estimate (written).
        cov: (F, n, M, 9, 9) their covariances (written).
        loglik: (F, n, M) their discounted log-likelihoods (written).
        last_fix: (F, n, 3) the last fix the filters corrected with (written).
        ready: (F, n) bool, whether each vessel's filters have started (written).
        state: (F, n, 9) the bank's estimate (``_blend``; written).
        out: (rows, n, obs_dim) float32, the estimated observations (written).
    """
    n = obs.shape[1]
    models = scales.shape[0]
    pose_variances = np.empty(3)
    scaled = np.empty(STATES)
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
            if not ready[f, i]:
                for m in range(models):
                    x, p = bank[f, i, m], cov[f, i, m]
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
                    loglik[f, i, m] = 0.0
                last_fix[f, i] = fix
                ready[f, i] = True
            else:
                tau = np.array((float(o[TAU]), float(o[TAU + 1]), float(o[TAU + 2])))
                moved = (
                    abs(fix[0] - last_fix[f, i, 0]) > HELD_TOLERANCE[0]
                    or abs(fix[1] - last_fix[f, i, 1]) > HELD_TOLERANCE[0]
                    or abs(wrap_angle(fix[2] - last_fix[f, i, 2])) > HELD_TOLERANCE[1]
                )
                for m in range(models):
                    x, p = bank[f, i, m], cov[f, i, m]
                    for j in range(STATES):
                        scaled[j] = q[j] * (scales[m] if j >= 3 else 1.0)
                    _predict(nominal[i], x, p, tau, dt, scaled)
                    if moved:
                        for k in range(3):
                            pose_variances[k] = sensor_variances[k]
                        likelihood = _correct(x, p, 0, fix, pose_variances, 2)
                        loglik[f, i, m] = forgetting * loglik[f, i, m] + likelihood
                    if velocity_measured:
                        measured = np.array((float(o[NU]), float(o[NU + 1]), float(o[NU + 2])))
                        _correct(x, p, 3, measured, np.zeros(3), -1)
                if moved:
                    last_fix[f, i] = fix
            _blend(bank[f, i], loglik[f, i], state[f, i])
            _observe(o, point, state[f, i], out[row, i])


@numba.njit(cache=True)
def _observe(o: np.ndarray, point: tuple, x: np.ndarray, seen: np.ndarray) -> None:
    """Write into ``seen`` the observation ``o`` with nu, z1, t1, t2 rebuilt from estimate ``x``."""
    seen[:] = o
    z1, t1, t2 = path_frame(x[0], x[1], x[2], point)
    for k in range(3):
        seen[NU + k] = x[3 + k]
        seen[Z1 + k] = z1[k]
        seen[T1 + k] = t1[k]
        seen[T2 + k] = t2[k]


@numba.njit(cache=True)
def observe_rows(obs: np.ndarray, kinds: np.ndarray, paths: np.ndarray, states: np.ndarray,
                 out: np.ndarray) -> None:  # fmt: skip
    """``obs`` (rows, n, obs_dim) rebuilt from ``states`` (rows, n, 9), written into ``out``."""
    for row in range(obs.shape[0]):
        for i in range(obs.shape[1]):
            o = obs[row, i]
            point = path_values(kinds[i], paths[i], float(o[THETA]))
            _observe(o, point, states[row, i], out[row, i])


class Filtered(FleetPolicy):
    """An analytic policy acting on the navigation filter's estimate (module docstring).

    Subclasses name the policy (``name``) and the policy under the filter (``inner``).

    Args:
        env: An env, a simulator or a ``Scenario`` (``resolve_scenario``).
        **options: Passed to the inner policy.
    """

    name: ClassVar[str]
    inner: ClassVar[type[FleetPolicy]]
    #: Factors on the velocity and bias process noise, one filter each: (1,) is one EKF on
    #: ``FILTER_NOISE``; several make a bank weighted by likelihood (``ADAPTIVE_SCALES``).
    noise_scales: ClassVar[tuple[float, ...]] = (1.0,)

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
        self._scales = np.array(self.noise_scales, dtype=np.float64)
        self._initial = np.array(INITIAL_VARIANCE)
        self._fleets = 0
        self.diagnostics: dict[str, Array] = {}
        self.reset()

    def _allocate(self, fleets: int) -> None:
        """Filter states for ``fleets`` fleets, none started."""
        self._fleets = fleets
        models = self._scales.shape[0]
        self._bank = np.zeros((fleets, self.n, models, STATES))
        self._cov = np.zeros((fleets, self.n, models, STATES, STATES))
        self._loglik = np.zeros((fleets, self.n, models))
        self._state = np.zeros((fleets, self.n, STATES))
        self._last_fix = np.zeros((fleets, self.n, 3))
        self._ready = np.zeros((fleets, self.n), dtype=bool)

    def reset(self, seed: int | None = None) -> None:
        """Forget every fleet's estimate and the inner policy's states."""
        self.policy.reset(seed)
        self._allocate(self._fleets)

    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget some fleets' estimates (they start again at their next fix).

        Args:
            fleets: (F,) bool mask, or indices, of the fleets to restart.
        """
        self.policy.reset_fleets(fleets)
        self._ready[fleet_mask(fleets, self._fleets)] = False

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
                    self._variances, self._velocity, self._q, self._scales, FORGETTING,
                    self._initial, self._bank, self._cov, self._loglik, self._last_fix,
                    self._ready, self._state, out)  # fmt: skip
        return out

    @property
    def state(self) -> NDArray[np.float64]:
        """(F, n, 9) every fleet's vessels' estimates after the last step (module docstring)."""
        return self._state

    @property
    def members(self) -> NDArray[np.float64]:
        """(F, n, M, 9) each filter of the bank's own estimate (``state`` is their blend)."""
        return self._bank

    @property
    def last_fix(self) -> NDArray[np.float64]:
        """(F, n, 3) the last fix x, y (m), psi (rad) each vessel's filters corrected with."""
        return self._last_fix

    def observe(self, obs: ArrayLike, states: ArrayLike) -> NDArray[np.float32]:
        """The observations (rows, n, dim) with nu, z1, t1 and t2 rebuilt from ``states``.

        ``states`` is (rows, n, 9), in the filter's layout (``state``): what a
        design acting on a corrected estimate hands its inner policy.
        """
        batch = np.ascontiguousarray(obs, dtype=np.float32)
        out = np.empty_like(batch)
        observe_rows(batch, self._kinds, self._paths,
                     np.ascontiguousarray(states, dtype=np.float64), out)  # fmt: skip
        return out

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """The inner policy's actions on the estimated observations.

        ``diagnostics`` gains ``estimate`` (F, n, 9), the state estimate of every
        fleet's vessels, and ``filter_weights`` (F, n, M), the weight of each filter
        of the bank (1 for a single filter).
        """
        actions = self.policy.act_batch(self.estimate(obs, fleets), fleets)
        scores = self._loglik - self._loglik.max(axis=-1, keepdims=True)
        weights = np.exp(scores) / np.exp(scores).sum(axis=-1, keepdims=True)
        self.diagnostics = {
            **self.policy.diagnostics,
            "estimate": self._state.copy(),
            "filter_weights": weights,
        }
        return actions


class NNDSCFiltered(Filtered):
    """``nn_dsc`` on the navigation filter's estimate."""

    name = "nn_dsc_ekf"
    inner = NNDSCPolicy


class MPCTunedFiltered(Filtered):
    """``mpc_tuned`` on the navigation filter's estimate."""

    name = "mpc_tuned_ekf"
    inner = MPCTuned


class MPCTunedAdaptive(Filtered):
    """``mpc_tuned`` on a bank of filters weighted by their likelihood (module docstring)."""

    name = "mpc_tuned_mmae"
    inner = MPCTuned
    noise_scales = ADAPTIVE_SCALES


class ILOSFiltered(Filtered):
    """``ilos`` on the navigation filter's estimate."""

    name = "ilos_ekf"
    inner = ILOSPolicy
