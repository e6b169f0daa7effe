"""The benchmark's per-episode metrics: one definition, recorded step by step.

``FleetMetrics`` is fed the simulator after every control step (the state
the step's action led to, and the reward that action earned) and reduces
the recorded series to one value per episode and metric (``METRICS``). It
is the one implementation behind ``cpf-bench`` and ``cpf-run`` (both step
through ``cpf_bench.rollout``); ``docs/benchmark.md`` gives every
formula.

Conventions (chosen once, for every metric):

* sampling: after each step, t_k = (k + 1) dt, k = 0 .. T - 1;
* aggregation: first over the n vessels of a fleet at each step (mean of
  squares for an RMS, max for a max, the spread over vessels for a
  formation error), then over the steps;
* failure masking: a fleet that leaves its path (``terminated``) is counted
  up to and including the step it failed and not after;
* window: metrics with suffix ``_window`` use the last quarter of the horizon
  (``WINDOW_FRACTION``); an episode that ended before the window is measured
  at its last counted step.

Path-relative quantities of vessel i, from its pose (x_i, y_i, psi_i), body
velocity (u_i, v_i) and its path point eta_d(theta_i) = (x_d, y_d, psi_d),
psi_d the path's tangent angle and |eta_d'| its speed dp/dtheta:

    along_i  =  cos psi_d (x_i - x_d) + sin psi_d (y_i - y_d)        (m)
    cross_i  = -sin psi_d (x_i - x_d) + cos psi_d (y_i - y_d)        (m)
    heading_i = wrap(psi_i - psi_d) in [-pi, pi)                       (rad)
    course_i = wrap(psi_i + atan2(v_i, u_i) - psi_d)                   (rad)
    sog_i    = u_i cos(psi_i - psi_d) - v_i sin(psi_i - psi_d)        (m/s)
    thetap_i = theta_i + along_i / |eta_d'|  (the vessel's position projected
               onto its path, to first order, as a path variable)

The course is the direction of the velocity over ground (u, v are body
velocities over ground). A hull without a sway actuator holds a path in a
cross current only by crabbing, its heading off the tangent by the drift
angle atan2(v, u): heading minus course is that drift angle, so the course
metrics tell a crab from a steering error. They are measured where no hull
of the fleet has a sway actuator, and are NaN elsewhere
(``COURSE_UNMEASURED``), like the separation metrics where no separation is
required (``UNSEPARATED``). ``unmeasured`` gives both sets.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from cpf_env.evaluation.recording import CHUNK, RECORDED, StepRecord, new_record
from cpf_env.model.paths import encode_paths, evaluate_paths
from cpf_env.scenarios.reward_weights import REWARD_TERMS
from cpf_env.scenarios.scenario import Scenario
from cpf_env.sim import arrays
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import wrap_angles

__all__ = [
    "COURSE_UNMEASURED",
    "METRICS",
    "UNSEPARATED",
    "WINDOW_FRACTION",
    "FleetMetrics",
    "measures_course",
    "path_relative",
    "unmeasured",
]

#: Fraction of the horizon, at its end, that the ``_window`` metrics use.
WINDOW_FRACTION = 0.25

Array = NDArray[np.float64]

_TERM_COSTS = tuple(f"cost_{term}" for term in REWARD_TERMS)
#: Metrics measured over the episode and again over the final window.
_MEASURES = (
    "return",
    "cost",
    *_TERM_COSTS,
    "path_error_rms",
    "path_error_max",
    "along_track_error_rms",
    "cross_track_error_rms",
    "cross_track_error_max",
    "heading_error_rms",
    "heading_error_max",
    "course_error_rms",
    "course_error_max",
    "formation_error_rms",
    "formation_error_max",
    "speed_along_path",
    "speed_along_path_error_rms",
    "progress",
    "theta_spread_rms",
    "theta_rate_error_rms",
    "speed_estimate_error_rms",
    "control_energy",
    "saturated_fraction",
    "separation_min",
)
#: Every per-episode metric, in the column order of ``episodes.csv``.
METRICS: tuple[str, ...] = (
    *_MEASURES,
    "formation_error_end",
    "theta_spread_end",
    *(f"{name}_window" for name in _MEASURES),
    "terminated",
    "steps",
)

#: The separation metrics on a scenario without a ``Scenario.separation``: the term's cost
#: (-0.0, the negated sum of zeros) and the closest approach (not measured: NaN). A table
#: or a cache written before these metrics existed holds them by construction.
UNSEPARATED = {
    "cost_separation": -0.0,
    "cost_separation_window": -0.0,
    "separation_min": math.nan,
    "separation_min_window": math.nan,
}
#: The course metrics where a hull of the fleet has a sway actuator: not measured (NaN).
COURSE_UNMEASURED = {
    "course_error_rms": math.nan,
    "course_error_max": math.nan,
    "course_error_rms_window": math.nan,
    "course_error_max_window": math.nan,
}
#: Per-step fleet series, each (S, T): sums over steps give totals, maxima give maxima.
_SERIES = (
    "reward",
    *_TERM_COSTS,
    "path_error_sq",
    "path_error_max",
    "along_sq",
    "cross_sq",
    "cross_max",
    "heading_sq",
    "heading_max",
    "course_sq",
    "course_max",
    "formation",
    "sog",
    "sog_error_sq",
    "thetap",
    "v0",
    "spread",
    "rate_error_sq",
    "estimate_error_sq",
    "energy",
    "saturated",
    "separation",
)


def measures_course(task: Scenario) -> bool:
    """Whether a scenario's course metrics are measured: no hull of its fleet has a sway actuator.

    Example:
        >>> from cpf_env.scenarios import make_scenario
        >>> [measures_course(make_scenario(name)) for name in ("bench_mild", "hard_underactuated")]
        [False, True]
    """
    return not bool(task.actuated[:, 1].any())


def unmeasured(task: Scenario) -> dict[str, float]:
    """The metrics a scenario does not measure, with their fixed values (module docstring)."""
    fixed = {} if task.separation is not None else dict(UNSEPARATED)
    return fixed if measures_course(task) else {**fixed, **COURSE_UNMEASURED}


def _closest_pair(eta: Array) -> Array:
    """(K, S) the smallest distance between two vessels of each fleet (m).

    ``eta`` is (K, S, n, 3).
    """
    position = eta[..., :2]
    gap = np.linalg.norm(position[..., :, None, :] - position[..., None, :, :], axis=-1)
    n = eta.shape[2]
    gap[..., np.arange(n), np.arange(n)] = np.inf
    return gap.min(axis=(2, 3))


def path_relative(
    eta: Array, nu: Array, theta: Array, kinds: NDArray[np.int64], params: Array
) -> dict[str, Array]:
    """Each vessel's errors relative to its path point, in the path's tangent frame.

    Args:
        eta: (S, n, 3) poses x, y (m), psi (rad).
        nu: (S, n, 3) body velocities u, v (m/s), r (rad/s).
        theta: (S, n) path variables.
        kinds: (n,) path kinds (``encode_paths``).
        params: (n, PATH_PARAM_SIZE) encoded paths.

    Returns:
        ``along``, ``cross`` (m), ``heading``, ``course`` (rad), ``sog`` (m/s), ``path_speed``
        (|eta_d'|, m per unit theta) and ``thetap`` (projected path variable),
        each (S, n); formulas in the module docstring.
    """
    S, n = theta.shape
    point = evaluate_paths(
        np.tile(kinds, S), np.tile(params, (S, 1)), np.ascontiguousarray(theta.reshape(-1))
    ).reshape(S, n, 3, 3)
    psi_d = point[..., 0, 2]
    c, s = np.cos(psi_d), np.sin(psi_d)
    dx, dy = eta[..., 0] - point[..., 0, 0], eta[..., 1] - point[..., 0, 1]
    along = c * dx + s * dy
    relative = eta[..., 2] - psi_d
    path_speed = np.hypot(point[..., 1, 0], point[..., 1, 1])
    return {
        "along": along,
        "cross": -s * dx + c * dy,
        "heading": wrap_angles(relative),
        "course": wrap_angles(relative + np.arctan2(nu[..., 1], nu[..., 0])),
        "sog": nu[..., 0] * np.cos(relative) - nu[..., 1] * np.sin(relative),
        "path_speed": path_speed,
        "thetap": theta + along / path_speed,
    }


class FleetMetrics:
    """Records S fleets' steps and reduces them to per-episode metrics.

    Args:
        sim: The simulator the fleets run in (its paths, force scale, dt, S).
        horizon: T, the control steps the rollout may take.
    """

    def __init__(self, sim: FleetSim, horizon: int) -> None:
        self.dt = float(sim.scenario.dt)
        self.horizon = int(horizon)
        self._kinds, self._params = encode_paths(sim.scenario.paths)
        self._tau_scale = sim.constants.tau_scale
        self._separated = sim.scenario.separation is not None
        self._course = measures_course(sim.scenario)
        self._unmeasured = unmeasured(sim.scenario)
        self.series = {name: np.zeros((sim.num_fleets, self.horizon)) for name in _SERIES}
        self._start_thetap = np.zeros(sim.num_fleets)
        self._has_estimate = True
        self._record: StepRecord | None = None  # allocated on first use, by the arrays' shapes
        self._v0 = np.zeros(CHUNK)
        self._first = 0  # step of the chunk's first row
        self._rows = 0  # rows of the chunk filled

    def start(self, a: arrays.FleetArrays) -> None:
        """Note where each fleet starts (after reset), for ``progress``."""
        rel = path_relative(a.eta, a.nu, a.theta, self._kinds, self._params)
        self._start_thetap = rel["thetap"].mean(axis=1)

    @property
    def next_step(self) -> int:
        """The step the next ``record`` or ``commit`` must start at."""
        return self._first + self._rows

    def buffer(self, a: arrays.FleetArrays) -> StepRecord:
        """The chunk's record (``CHUNK`` rows), allocated on first use by the shapes of ``a``."""
        if self._record is None:
            self._record = new_record(a)
        return self._record

    def record(self, t: int, a: arrays.FleetArrays, v0: float, estimate: Array | None) -> None:
        """Take step t's values (after the step); they become column t of every series.

        The raw arrays are kept for ``CHUNK`` steps and turned into the series
        together (``_flush``): the same element-wise operations and per-fleet
        reductions over the vessels as step by step, on larger arrays.

        Args:
            t: Step index, 0 .. T - 1, one after the other.
            a: The simulator's arrays after step t.
            v0: Leader speed the step's rate is scored against (m/s).
            estimate: (S, n) the policy's speed estimates used at step t, or None.
        """
        self._check_order(t)
        record, row = self.buffer(a), self._rows
        for name in RECORDED:
            getattr(record, name)[row] = getattr(a, name)
        self._v0[row] = v0
        self._has_estimate = self._has_estimate and estimate is not None
        if estimate is not None:
            record.estimate[row] = estimate
        self._rows += 1
        if self._rows == CHUNK:
            self._flush()

    def commit(self, t: int, v0: Array) -> None:
        """Take steps t .. t + K - 1, written to rows 0 .. K - 1 of ``buffer()`` by a compiled loop.

        The loop (``baselines.closed_loop``) writes every fleet's row with
        ``cpf_env.evaluation.recording.record_fleet``, speed estimates included, as
        ``record`` would have one step at a time.

        Args:
            t: The first step, ``next_step`` at the start of a chunk.
            v0: (K,) leader speed of each step (m/s), 1 <= K <= ``CHUNK``.
        """
        self._check_order(t)
        K = len(v0)
        if self._rows != 0 or not 1 <= K <= CHUNK:
            raise ValueError(f"commit takes 1 to {CHUNK} steps at the start of a chunk, got {K}.")
        self._v0[:K] = v0
        self._rows = K
        self._flush()

    def _check_order(self, t: int) -> None:
        if t != self.next_step:
            raise ValueError(f"steps must be recorded in order; expected {self.next_step}.")

    def _flush(self) -> None:
        """Write the recorded chunk's steps into the series (per fleet: mean/max over vessels)."""
        K = self._rows
        if K == 0 or self._record is None:
            return
        r = {name: values[:K] for name, values in self._record._asdict().items()}
        r["v0"] = self._v0[:K]
        x, steps = self.series, slice(self._first, self._first + K)
        S, n = r["theta"].shape[1:]
        rel = {
            name: values.reshape(K, S, n)
            for name, values in path_relative(
                r["eta"].reshape(K * S, n, 3),
                r["nu"].reshape(K * S, n, 3),
                r["theta"].reshape(K * S, n),
                self._kinds,
                self._params,
            ).items()
        }
        v0 = r["v0"][:, None, None]
        path_error = r["errors"][..., arrays.ERR_PATH]

        def put(name: str, value: Array) -> None:  # value (K, S) -> columns of the series
            x[name][:, steps] = value.T

        put("reward", r["reward"].mean(axis=2))
        for k, name in enumerate(_TERM_COSTS):
            put(name, r["reward_terms"][..., k].mean(axis=2))
        put("path_error_sq", (path_error**2).mean(axis=2))
        put("path_error_max", path_error.max(axis=2))
        put("along_sq", (rel["along"] ** 2).mean(axis=2))
        put("cross_sq", (rel["cross"] ** 2).mean(axis=2))
        put("cross_max", np.abs(rel["cross"]).max(axis=2))
        put("heading_sq", (rel["heading"] ** 2).mean(axis=2))
        put("heading_max", np.abs(rel["heading"]).max(axis=2))
        thetap = rel["thetap"]
        spread = thetap.max(axis=2) - thetap.min(axis=2)
        put("formation", spread * rel["path_speed"].mean(axis=2))
        put("sog", rel["sog"].mean(axis=2))
        put("sog_error_sq", ((rel["sog"] - v0 * rel["path_speed"]) ** 2).mean(axis=2))
        put("thetap", thetap.mean(axis=2))
        put("v0", np.broadcast_to(r["v0"][:, None], (K, S)))
        put("spread", r["theta"].max(axis=2) - r["theta"].min(axis=2))
        put("rate_error_sq", ((r["theta_dot"] - v0) ** 2).mean(axis=2))
        energy = ((r["tau_applied"] / self._tau_scale) ** 2).sum(axis=3).mean(axis=2)
        put("energy", energy)
        put("saturated", (r["tau_command"] != r["tau_applied"]).any(axis=3).mean(axis=2))
        if self._course:  # measured where no hull has a sway actuator
            put("course_sq", (rel["course"] ** 2).mean(axis=2))
            put("course_max", np.abs(rel["course"]).max(axis=2))
        if self._separated:  # the closest approach is measured where it is constrained
            put("separation", _closest_pair(r["eta"]))
        if self._has_estimate:
            put("estimate_error_sq", ((r["estimate"] - v0) ** 2).mean(axis=2))
        self._first += K
        self._rows = 0

    def reduce(self, end: NDArray[np.int64], failed: NDArray[np.bool_]) -> dict[str, Array]:
        """Per-episode metrics (``METRICS``), each (S,).

        Args:
            end: (S,) steps each episode lasted (1 .. T).
            failed: (S,) whether each fleet left its path.
        """
        self._flush()
        S = end.shape[0]
        time = np.arange(self.horizon)[None, :]
        counted = time < end[:, None]
        first = self.horizon - max(1, round(WINDOW_FRACTION * self.horizon))
        window_start = np.minimum(first, end - 1)
        window = counted & (time >= window_start[:, None])
        before = self.series["thetap"][np.arange(S), window_start - 1]
        start = np.where(window_start > 0, before, self._start_thetap)
        metrics = self._reduce(counted, self._start_thetap)
        metrics.update({f"{k}_window": v for k, v in self._reduce(window, start).items()})
        last = end - 1
        metrics["formation_error_end"] = self.series["formation"][np.arange(S), last]
        metrics["theta_spread_end"] = self.series["spread"][np.arange(S), last]
        if not self._has_estimate:
            for name in ("speed_estimate_error_rms", "speed_estimate_error_rms_window"):
                metrics[name] = np.full(S, np.nan)
        for name, value in self._unmeasured.items():
            metrics[name] = np.full(S, value)
        metrics["terminated"] = failed.astype(np.float64)
        metrics["steps"] = end.astype(np.float64)
        return {name: metrics[name] for name in METRICS}

    def _reduce(self, mask: NDArray[np.bool_], start_thetap: Array) -> dict[str, Array]:
        """Metrics over the steps in ``mask`` (S, T); progress from ``start_thetap`` (S,).

        Every reduction runs along the contiguous last axis, so fleet k's numbers
        do not depend on how many fleets ran beside it.
        """
        x = self.series
        count = np.maximum(mask.sum(axis=1), 1)
        last = self.horizon - 1 - np.argmax(mask[:, ::-1], axis=1)

        def total(name: str) -> Array:
            return np.where(mask, x[name], 0.0).sum(axis=1)

        def rms(name: str) -> Array:
            return np.sqrt(total(name) / count)

        def peak(name: str) -> Array:
            return np.where(mask, x[name], 0.0).max(axis=1)

        made_good = x["thetap"][np.arange(mask.shape[0]), last] - start_thetap
        return {
            "return": total("reward"),
            "cost": -total("reward"),
            **{name: -total(name) for name in _TERM_COSTS},
            "path_error_rms": rms("path_error_sq"),
            "path_error_max": peak("path_error_max"),
            "along_track_error_rms": rms("along_sq"),
            "cross_track_error_rms": rms("cross_sq"),
            "cross_track_error_max": peak("cross_max"),
            "heading_error_rms": rms("heading_sq"),
            "heading_error_max": peak("heading_max"),
            "course_error_rms": rms("course_sq"),
            "course_error_max": peak("course_max"),
            "formation_error_rms": np.sqrt(np.where(mask, x["formation"] ** 2, 0.0).sum(1) / count),
            "formation_error_max": peak("formation"),
            "speed_along_path": total("sog") / count,
            "speed_along_path_error_rms": rms("sog_error_sq"),
            "progress": made_good / (self.dt * total("v0")),
            "theta_spread_rms": np.sqrt(np.where(mask, x["spread"] ** 2, 0.0).sum(1) / count),
            "theta_rate_error_rms": rms("rate_error_sq"),
            "speed_estimate_error_rms": rms("estimate_error_sq"),
            "control_energy": self.dt * total("energy"),
            "saturated_fraction": total("saturated") / count,
            "separation_min": np.where(mask, x["separation"], np.inf).min(axis=1),
        }
