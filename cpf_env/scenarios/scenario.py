"""The ``Scenario`` type: everything that defines a cooperative path-following task.

A ``Scenario`` is a frozen dataclass composed of parts users can recombine:
vessel models, paths, a communication topology with leader links, link
impairments, a leader-speed schedule, saturation limits, disturbances, the
initial-state distribution, timing and reward weights. Named scenarios live in
the registry (``cpf_env.scenarios.registry``)::

    >>> from cpf_env import scenarios
    >>> scenarios.get("wang2014").n
    5
    >>> fast = scenarios.get("wang2014").replace(v0=0.2, max_steps=1000)

Unknown override keys and inconsistent parts raise ``ValueError`` at
construction, with a message that says what to fix.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from cpf_env.model.actuators import Thrusters
from cpf_env.model.disturbances import Disturbances
from cpf_env.model.graph import Graph, SwitchingTopology, as_switching
from cpf_env.model.links import LinkImpairments
from cpf_env.model.paths import Path
from cpf_env.model.sensors import Sensors
from cpf_env.model.separation import Separation
from cpf_env.model.vessel import CYBERSHIP2, VesselModel
from cpf_env.scenarios.checks import as_integer, as_real, check_plant_step
from cpf_env.scenarios.reward_weights import RewardWeights

__all__ = ["InitialState", "Scenario", "SpeedSchedule"]

Vector3 = tuple[float, float, float]

#: Scalar float fields of ``Scenario`` and their units (for error messages).
_REAL_FIELDS = {
    "model_spread": "relative",
    "dt": "s",
    "theta_dot_max": "1/s",
    "message_max": "-",
    "max_path_error": "m",
}


def _as_rows(name: str, value: object, n: int, width: int) -> tuple[tuple[float, ...], ...]:
    """Broadcast ``value`` to n rows of ``width`` floats, or raise a ValueError saying why not."""
    array = np.asarray(value, dtype=np.float64)
    if array.shape == (width,):
        array = np.broadcast_to(array, (n, width))
    if array.shape != (n, width):
        raise ValueError(
            f"{name} must have shape ({width},) or ({n}, {width}) for {n} vessels, "
            f"got {array.shape}."
        )
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} has non-finite entries: {array.tolist()}.")
    return tuple(tuple(float(x) for x in row) for row in array)


@dataclass(frozen=True)
class SpeedSchedule:
    """Piecewise-constant leader speed v0(t).

    Attributes:
        times: Switch times (s), first 0, strictly increasing.
        values: v0 (m/s) from each switch time on.
    """

    times: tuple[float, ...] = (0.0,)
    values: tuple[float, ...] = (0.1,)

    def __post_init__(self) -> None:
        times = tuple(float(t) for t in self.times)
        values = tuple(float(v) for v in self.values)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        if len(times) != len(values) or not times:
            raise ValueError("SpeedSchedule needs as many values as times, at least one.")
        if times[0] != 0.0 or any(b <= a for a, b in itertools.pairwise(times)):
            raise ValueError(f"SpeedSchedule.times must start at 0 and increase, got {times}.")
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"SpeedSchedule.values must be finite, got {values}.")

    def at(self, time: float) -> float:
        """v0 (m/s) at ``time`` (s)."""
        index = int(np.searchsorted(self.times, time, side="right")) - 1
        return self.values[max(index, 0)]


@dataclass(frozen=True)
class InitialState:
    """Initial-state distribution: a nominal state plus Gaussian spread.

    Attributes:
        eta: Nominal poses, n rows of (x (m), y (m), psi (rad)).
        nu: Nominal velocities, n rows of (u, v, r), or None for rest.
        theta: Nominal path variables (n,), or None for zeros.
        position_std: Std of x and y (m).
        heading_std: Std of psi (rad).
        theta_std: Std of theta.
    """

    eta: tuple[Vector3, ...]
    nu: tuple[Vector3, ...] | None = None
    theta: tuple[float, ...] | None = None
    position_std: float = 0.0
    heading_std: float = 0.0
    theta_std: float = 0.0

    def __post_init__(self) -> None:
        n = len(self.eta)
        object.__setattr__(self, "eta", _as_rows("InitialState.eta", self.eta, n, 3))
        nu = np.zeros((n, 3)) if self.nu is None else self.nu
        object.__setattr__(self, "nu", _as_rows("InitialState.nu", nu, n, 3))
        theta = np.zeros(n) if self.theta is None else self.theta
        rows = _as_rows("InitialState.theta", np.reshape(theta, (-1, 1)), n, 1)
        object.__setattr__(self, "theta", tuple(row[0] for row in rows))
        for name in ("position_std", "heading_std", "theta_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"InitialState.{name} must be >= 0, got {value}.")

    @property
    def n(self) -> int:
        """Number of vessels."""
        return len(self.eta)

    def sample(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Draw (eta (n, 3), nu (n, 3), theta (n,)) from this distribution with ``rng``."""
        eta = np.array(self.eta)
        nu = np.array(self.nu)
        theta = np.array(self.theta)
        noise = rng.standard_normal((self.n, 4))
        eta[:, :2] += self.position_std * noise[:, :2]
        eta[:, 2] += self.heading_std * noise[:, 2]
        theta += self.theta_std * noise[:, 3]
        return eta, nu, theta


@dataclass(frozen=True)
class Scenario:
    """A cooperative path-following task for n vessels.

    Attributes:
        name: Registry name or a user label.
        paths: One desired path per vessel.
        topology: Communication graph with leader links, or a switching schedule of graphs.
        initial: Initial-state distribution.
        vessels: Nominal vessel model, one for all or one per vessel.
        model_spread: Relative spread of the true model around the nominal one,
            drawn per vessel at every reset (0 = the true plant is the nominal model).
        v0: Leader speed (m/s), constant or a ``SpeedSchedule``.
        tau_max: Upper force limits (N, N, N m), (3,) or (n, 3).
        tau_min: Lower force limits, same shape; None means -tau_max.
        disturbances: Unmodeled dynamics, current, waves, wind.
        links: Packet loss and delay on every link.
        thrusters: Lag and slew-rate limit of the applied force
            (``cpf_env.model.actuators``); the default is an instant thruster.
        sensors: Noise, rate and dropouts of the pose fixes the observation is
            computed from, and whether velocity is measured (``cpf_env.model.sensors``);
            the default observes the true state every step.
        separation: Keep-out and collision distances between the fleet's vessels
            (``cpf_env.model.separation``); None (the default) constrains nothing.
        dt: Control period (s).
        substeps: RK4 plant steps per control period.
        max_steps: Episode length (control steps) before truncation.
        theta_dot_max: Bound on the commanded path-variable rate (1/s).
        message_size: Floats per broadcast message m.
        message_max: Bound on each message float.
        max_path_error: Path error (m) past which the episode terminates.
        reward: Reward weights.
        description: One line for listings.
    """

    name: str
    paths: tuple[Path, ...]
    topology: Graph | SwitchingTopology
    initial: InitialState
    vessels: VesselModel | tuple[VesselModel, ...] = CYBERSHIP2
    model_spread: float = 0.0
    v0: float | SpeedSchedule = 0.1
    tau_max: Vector3 | tuple[Vector3, ...] = (9.2, 4.5, 3.0)
    tau_min: Vector3 | tuple[Vector3, ...] | None = None
    disturbances: Disturbances = field(default_factory=Disturbances)
    links: LinkImpairments = field(default_factory=LinkImpairments)
    thrusters: Thrusters = field(default_factory=Thrusters)
    sensors: Sensors = field(default_factory=Sensors)
    separation: Separation | None = None
    dt: float = 0.05
    substeps: int = 5
    max_steps: int = 3000
    theta_dot_max: float = 1.0
    message_size: int = 1
    message_max: float = 10.0
    max_path_error: float = 10.0
    reward: RewardWeights = field(default_factory=RewardWeights)
    description: str = ""

    def __post_init__(self) -> None:
        paths = tuple(self.paths)
        n = len(paths)
        object.__setattr__(self, "paths", paths)
        topology = as_switching(self.topology)
        if topology.n != n:
            raise ValueError(f"topology has {topology.n} vessels but {n} paths are given.")
        if self.initial.n != n:
            raise ValueError(f"initial state has {self.initial.n} vessels but {n} paths are given.")
        vessels = self.vessels
        vessels = (vessels,) * n if isinstance(vessels, VesselModel) else tuple(vessels)
        if len(vessels) != n or not all(isinstance(v, VesselModel) for v in vessels):
            raise ValueError(f"vessels must be one VesselModel or {n} of them, got {len(vessels)}.")
        object.__setattr__(self, "vessels", vessels)
        if not isinstance(self.v0, SpeedSchedule):
            object.__setattr__(self, "v0", SpeedSchedule((0.0,), (float(self.v0),)))
        tau_max = _as_rows("tau_max", self.tau_max, n, 3)
        tau_min = _as_rows(
            "tau_min", -np.array(tau_max) if self.tau_min is None else self.tau_min, n, 3
        )
        upper, lower = np.array(tau_max), np.array(tau_min)
        unactuated = (upper == 0.0) & (lower == 0.0)  # an axis without an actuator
        if not np.all(((upper > 0.0) & (lower < 0.0)) | unactuated):
            raise ValueError(
                "saturation limits must satisfy tau_min < 0 < tau_max on every actuated axis, "
                "or tau_min = tau_max = 0 on an axis without an actuator (an underactuated "
                f"hull: sway 0); got tau_min={tau_min}, tau_max={tau_max}. Give magnitudes in "
                "N, N, N m."
            )
        object.__setattr__(self, "tau_max", tau_max)
        object.__setattr__(self, "tau_min", tau_min)
        self._check_numbers()
        if not isinstance(self.thrusters, Thrusters):
            raise ValueError(
                f"thrusters must be a cpf_env.model.actuators.Thrusters, got {self.thrusters!r}."
            )
        if not isinstance(self.sensors, Sensors):
            raise ValueError(
                f"sensors must be a cpf_env.model.sensors.Sensors, got {self.sensors!r}."
            )
        self._check_separation()
        if self.links.delay_steps >= self.max_steps:
            raise ValueError(
                f"links.delay_steps = {self.links.delay_steps} is not shorter than the episode "
                f"(max_steps = {self.max_steps}): no packet would ever arrive. Use a delay "
                "shorter than max_steps (a delay of d steps is d * dt seconds)."
            )
        check_plant_step(
            self.vessel_models,
            self.disturbances.unmodeled_scale,
            self.model_spread,
            self.dt,
            self.substeps,
        )

    def _check_separation(self) -> None:
        """Refuse a separation the fleet's nominal start already violates."""
        sep = self.separation
        if sep is None:
            return
        if not isinstance(sep, Separation):
            raise ValueError(
                f"separation must be a cpf_env.model.separation.Separation or None, got {sep!r}."
            )
        start = np.array(self.initial.eta)[:, :2]
        for i, j in itertools.combinations(range(self.n), 2):
            gap = float(np.hypot(*(start[i] - start[j])))
            if gap <= sep.safe_distance:
                raise ValueError(
                    f"vessels {i} and {j} start {gap:.3g} m apart (initial.eta), inside the "
                    f"separation's safe_distance of {sep.safe_distance:.3g} m: the fleet would "
                    "begin in its own keep-out zone. Use a safe_distance below the closest "
                    "spacing at start, or place the vessels further apart."
                )

    def _check_numbers(self) -> None:
        """Coerce the scalar fields to float / int (numpy scalars welcome) and check ranges."""
        for name, unit in _REAL_FIELDS.items():
            object.__setattr__(self, name, as_real(f"Scenario.{name}", getattr(self, name), unit))
        for name in ("substeps", "max_steps", "message_size"):
            object.__setattr__(self, name, as_integer(f"Scenario.{name}", getattr(self, name)))
        checks = {  # name -> (valid, what it must be)
            "dt": (0.0 < self.dt < math.inf, "> 0 and finite"),
            "substeps": (self.substeps >= 1, "an integer >= 1"),
            "max_steps": (self.max_steps >= 1, "positive: an integer >= 1 (control steps)"),
            "theta_dot_max": (self.theta_dot_max > 0.0, "> 0"),
            "message_size": (self.message_size >= 0, "an integer >= 0"),
            "message_max": (self.message_max > 0.0, "> 0"),
            "max_path_error": (self.max_path_error > 0.0, "> 0 (m)"),
            "model_spread": (0.0 <= self.model_spread < 1.0, "in [0, 1)"),
        }
        for name, (ok, requirement) in checks.items():
            if not ok:
                raise ValueError(
                    f"Scenario.{name} = {getattr(self, name)!r} is invalid: {name} must be "
                    f"{requirement}."
                )

    @property
    def n(self) -> int:
        """Number of vessels."""
        return len(self.paths)

    @property
    def vessel_models(self) -> tuple[VesselModel, ...]:
        """Nominal model of every vessel, length n."""
        return self.vessels  # type: ignore[return-value]  # normalized in __post_init__

    @property
    def v0_schedule(self) -> SpeedSchedule:
        """The leader speed as a schedule (a constant v0 is a one-entry schedule)."""
        return self.v0  # type: ignore[return-value]  # normalized in __post_init__

    @property
    def tau_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(tau_min, tau_max) as arrays of shape (n, 3) in N, N, N m."""
        return np.array(self.tau_min), np.array(self.tau_max)

    @property
    def actuated(self) -> np.ndarray:
        """(n, 3) bool: whether vessel i has an actuator on axis k (its limits not both 0).

        An underactuated hull has ``actuated[:, 1]`` False: no sway force acts on it.
        """
        tau_min, tau_max = self.tau_limits
        return (tau_min != 0.0) | (tau_max != 0.0)

    @property
    def tau_scale(self) -> np.ndarray:
        """Per-axis force scale max(|tau_min|, |tau_max|) (n, 3), in N, N, N m.

        What the reward's effort term, the residual's range and the normalized
        forces divide by; 1 on an axis without an actuator, whose force is always 0.
        """
        tau_min, tau_max = self.tau_limits
        return np.where(self.actuated, np.maximum(np.abs(tau_min), np.abs(tau_max)), 1.0)

    @property
    def switching(self) -> SwitchingTopology:
        """The topology as a (possibly one-member) switching schedule."""
        return as_switching(self.topology)

    def replace(self, **changes: object) -> Scenario:
        """Return a copy with fields replaced; unknown names raise ``ValueError``.

        Replaced values are taken as if the scenario had been built with them:
        a tau_min that mirrored tau_max (the default, -tau_max) keeps mirroring
        a replaced tau_max, and when the number of paths changes, per-vessel
        fields that are the same for every vessel (vessels, tau_max, tau_min)
        follow the new fleet size. Per-vessel fields that differ between
        vessels must then be given anew.
        """
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ValueError(
                f"unknown Scenario field(s) {unknown}; valid fields are {sorted(names)}."
            )
        if "tau_max" in changes and "tau_min" not in changes:
            if np.array_equal(np.array(self.tau_min), -np.array(self.tau_max)):
                changes["tau_min"] = None
        if "paths" in changes and len(tuple(changes["paths"])) != self.n:  # type: ignore[arg-type]
            for name in ("vessels", "tau_max", "tau_min"):
                rows = getattr(self, name)
                if name in changes:
                    continue
                if any(row != rows[0] for row in rows):
                    raise ValueError(
                        f"{name} differs between this scenario's vessels, so it cannot follow "
                        f"the new fleet size: pass {name}=... for the new paths too."
                    )
                changes[name] = rows[0]
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]
