"""Desired paths eta_d(theta) = [x_d, y_d, psi_d] with analytic theta-derivatives.

Each path is a plane curve (x_d(theta), y_d(theta)) in the earth frame (m);
the desired heading follows the tangent, psi_d = atan2(y_d', x_d') (rad,
wrapped to [-pi, pi]), where ' is d/d theta. Its derivatives follow from the
curve's first three derivatives::

    psi'  = (x'y'' - y'x'') / (x'^2 + y'^2)
    psi'' = (x'y''' - y'x''') / (x'^2 + y'^2) - 2 psi' (x'x'' + y'y'') / (x'^2 + y'^2)

Every kind is written as a curve in a local frame (closed-form x, y and their
first three derivatives), placed in the earth frame by a rotation and a
translation that all kinds share. Cross and dot products of tangent vectors
do not change under rotation, so psi' and psi'' come from the local curve.
Paths are parameterized so ||(x_d', y_d')|| is about 1: theta is (close to)
arc length in m, and its rate is roughly a speed in m/s.

The physics is written once, in ``path_values``, a scalar numba function that
reads an integer kind and a flat parameter vector and returns the values
without allocating; ``path_point`` writes them into a caller's (3, 3) buffer.
The simulator's fused kernel calls ``path_values`` per vessel; Python code goes
through ``evaluate_paths`` (the batched compiled loop), ``Path.evaluate`` and
``encode_paths``. Parameter layout of
``Path.encode()`` (unused slots are 0):

==========  ====  ====  ========  ==========  ==========  ======
kind        0     1     2         3           4           5
==========  ====  ====  ========  ==========  ==========  ======
LINE        x0    y0    heading
CIRCLE      cx    cy    phase     radius      +1 / -1
SINUSOID    x0    y0    heading   amplitude   wavenumber  phase
LEMNISCATE  cx    cy    heading   half_width
==========  ====  ====  ========  ==========  ==========  ======
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CIRCLE",
    "LEMNISCATE",
    "LINE",
    "PATH_PARAM_SIZE",
    "SINUSOID",
    "Circle",
    "Lemniscate",
    "Path",
    "Sinusoid",
    "StraightLine",
    "encode_paths",
    "evaluate_paths",
    "path_point",
    "path_values",
]

PATH_PARAM_SIZE = 8  # floats per encoded path
LINE, CIRCLE, SINUSOID, LEMNISCATE = 0, 1, 2, 3
# Parameter indices (module constants: numba freezes them into the kernels).
_X0, _Y0, _ROT, _P3, _P4, _P5 = 0, 1, 2, 3, 4, 5


@numba.njit(cache=True, inline="always")
def _local_curve(kind: int, params: NDArray[np.float64], theta: float) -> tuple:
    """Local-frame curve: (x, y, x', y', x'', y'', x''', y''') at theta (m, m per m^k)."""
    if kind == LINE:
        return theta, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if kind == CIRCLE:
        radius, sign = params[_P3], params[_P4]
        c, s = math.cos(sign * theta / radius), math.sin(sign * theta / radius)
        curvature = 1.0 / radius
        return (
            radius * c, radius * s,
            -sign * s, sign * c,
            -curvature * c, -curvature * s,
            sign * curvature * curvature * s, -sign * curvature * curvature * c,
        )  # fmt: skip
    if kind == SINUSOID:
        amplitude, k = params[_P3], params[_P4]
        c, s = math.cos(k * theta + params[_P5]), math.sin(k * theta + params[_P5])
        return (
            theta, amplitude * s,
            1.0, amplitude * k * c,
            0.0, -amplitude * k * k * s,
            0.0, -amplitude * k * k * k * c,
        )  # fmt: skip
    if kind == LEMNISCATE:
        a = params[_P3]
        t = theta / a
        c1, s1, c2, s2 = math.cos(t), math.sin(t), math.cos(2.0 * t), math.sin(2.0 * t)
        return (
            a * s1, 0.5 * a * s2,
            c1, c2,
            -s1 / a, -2.0 * s2 / a,
            -c1 / (a * a), -4.0 * c2 / (a * a),
        )  # fmt: skip
    raise ValueError("path_point: unknown path kind; use LINE, CIRCLE, SINUSOID or LEMNISCATE.")


@numba.njit(cache=True, inline="always")
def path_values(kind: int, params: NDArray[np.float64], theta: float) -> tuple:
    """Evaluate a path and its first two theta-derivatives, as values (no array).

    Args:
        kind: Path kind, one of LINE, CIRCLE, SINUSOID, LEMNISCATE.
        params: Encoded path, shape (PATH_PARAM_SIZE,), float64 (see module docstring).
        theta: Path variable (about m).

    Returns:
        (eta_d, d eta_d/d theta, d2 eta_d/d theta2), each (x (m), y (m), psi (rad)).
    """
    x, y, x1, y1, x2, y2, x3, y3 = _local_curve(kind, params, theta)
    c, s = math.cos(params[_ROT]), math.sin(params[_ROT])
    tangent_x, tangent_y = c * x1 - s * y1, s * x1 + c * y1
    speed_sq = x1 * x1 + y1 * y1
    psi1 = (x1 * y2 - y1 * x2) / speed_sq
    psi2 = ((x1 * y3 - y1 * x3) - 2.0 * psi1 * (x1 * x2 + y1 * y2)) / speed_sq
    return (
        (params[_X0] + c * x - s * y, params[_Y0] + s * x + c * y,
         math.atan2(tangent_y, tangent_x)),
        (tangent_x, tangent_y, psi1),
        (c * x2 - s * y2, s * x2 + c * y2, psi2),
    )  # fmt: skip


@numba.njit(cache=True)
def path_point(
    kind: int, params: NDArray[np.float64], theta: float, out: NDArray[np.float64]
) -> None:
    """Evaluate a path and its first two theta-derivatives into a caller's buffer.

    Args:
        kind: Path kind, one of LINE, CIRCLE, SINUSOID, LEMNISCATE.
        params: Encoded path, shape (PATH_PARAM_SIZE,), float64 (see module docstring).
        theta: Path variable (about m).
        out: Output, shape (3, 3): out[0] = eta_d, out[1] = d eta_d/d theta,
            out[2] = d2 eta_d/d theta2; columns x (m), y (m), psi (rad).
    """
    point = path_values(kind, params, theta)
    for row in range(3):
        for column in range(3):
            out[row, column] = point[row][column]


@numba.njit(cache=True)
def evaluate_paths(
    kinds: NDArray[np.int64], params: NDArray[np.float64], theta: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Evaluate N paths, each at its own theta, through ``path_point``.

    Args:
        kinds: Path kinds, shape (N,), int64.
        params: Encoded paths, shape (N, PATH_PARAM_SIZE), float64.
        theta: Path variables, shape (N,), float64.

    Returns:
        Shape (N, 3, 3): per path, rows eta_d, d eta_d/d theta, d2 eta_d/d theta2;
        columns x (m), y (m), psi (rad).
    """
    n = kinds.shape[0]
    if params.shape[0] != n or params.shape[1] != PATH_PARAM_SIZE or theta.shape[0] != n:
        raise ValueError(
            "evaluate_paths: need kinds (N,), params (N, PATH_PARAM_SIZE), theta (N,)."
        )
    out = np.empty((n, 3, 3))
    for i in range(n):
        path_point(kinds[i], params[i], theta[i], out[i])
    return out


@dataclass(frozen=True)
class Path(abc.ABC):
    """A desired path eta_d(theta); subclasses are frozen, keyword-only dataclasses.

    Float fields are coerced to float and must be finite; bool fields must be bools.
    """

    kind: ClassVar[int]

    def __post_init__(self) -> None:
        name = type(self).__name__
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.type in ("bool", bool):
                if not isinstance(value, (bool, np.bool_)):
                    raise ValueError(f"{name}.{field.name} must be True or False, got {value!r}.")
                object.__setattr__(self, field.name, bool(value))
                continue
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if isinstance(value, (bool, np.bool_)) or not math.isfinite(number):
                raise ValueError(f"{name}.{field.name} must be a finite number, got {value!r}.")
            object.__setattr__(self, field.name, number)

    @abc.abstractmethod
    def _values(self) -> tuple[float, ...]:
        """Leading entries of the encoded parameter vector (layout in the module docstring)."""

    def encode(self) -> NDArray[np.float64]:
        """Flatten for the kernel: shape (PATH_PARAM_SIZE,), float64, zero-padded."""
        params = np.zeros(PATH_PARAM_SIZE)
        values = self._values()
        params[: len(values)] = values
        return params

    def evaluate(self, theta: ArrayLike) -> NDArray[np.float64]:
        """Evaluate the path and its derivatives through the compiled kernel.

        Args:
            theta: Path variable(s), any shape S (about m).

        Returns:
            Shape S + (3, 3): rows eta_d, d eta_d/d theta, d2 eta_d/d theta2;
            columns x (m), y (m), psi (rad).
        """
        theta = np.asarray(theta, dtype=np.float64)
        flat = np.ascontiguousarray(theta.reshape(-1))
        kinds = np.full(flat.size, self.kind, dtype=np.int64)
        params = np.tile(self.encode(), (flat.size, 1))
        return evaluate_paths(kinds, params, flat).reshape((*theta.shape, 3, 3))


@dataclass(frozen=True, kw_only=True)
class StraightLine(Path):
    """Straight line through (x0, y0) along ``heading``, parameterized by arc length.

    Attributes:
        x0: x at theta = 0 (m).
        y0: y at theta = 0 (m).
        heading: Direction of travel (rad, from the x axis).
    """

    kind: ClassVar[int] = LINE
    x0: float = 0.0
    y0: float = 0.0
    heading: float = 0.0

    def _values(self) -> tuple[float, ...]:
        return self.x0, self.y0, self.heading


@dataclass(frozen=True, kw_only=True)
class Circle(Path):
    """Circle parameterized by arc length: angle = phase ± theta / radius.

    Attributes:
        cx: Centre x (m).
        cy: Centre y (m).
        radius: Radius R (m), > 0.
        phase: Polar angle of the point at theta = 0, seen from the centre (rad).
        clockwise: Travel clockwise (True) or counter-clockwise (False).
    """

    kind: ClassVar[int] = CIRCLE
    cx: float = 0.0
    cy: float = 0.0
    radius: float
    phase: float = 0.0
    clockwise: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.radius <= 0.0:
            raise ValueError(f"Circle.radius must be > 0 m, got {self.radius}.")

    def _values(self) -> tuple[float, ...]:
        return self.cx, self.cy, self.phase, self.radius, -1.0 if self.clockwise else 1.0


@dataclass(frozen=True, kw_only=True)
class Sinusoid(Path):
    """Sine wave about a straight axis: local (theta, amplitude sin(wavenumber theta + phase)).

    The local frame has its origin at (x0, y0) and is rotated by ``heading``.
    ||(x', y')|| lies in [1, sqrt(1 + (amplitude wavenumber)^2)]; the paper's
    path x_d = theta, y_d = y_i + 2 sin(0.2 theta) is
    ``Sinusoid(y0=y_i, amplitude=2.0, wavenumber=0.2)``.

    Attributes:
        x0: Origin x (m).
        y0: Origin y (m).
        amplitude: Lateral amplitude (m), >= 0.
        wavenumber: Spatial frequency along the axis (rad/m), > 0.
        phase: Phase of the sine at theta = 0 (rad).
        heading: Direction of the axis (rad, from the x axis).
    """

    kind: ClassVar[int] = SINUSOID
    x0: float = 0.0
    y0: float = 0.0
    amplitude: float
    wavenumber: float
    phase: float = 0.0
    heading: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.amplitude < 0.0:
            raise ValueError(
                f"Sinusoid.amplitude must be >= 0 m (use phase + pi to flip), got {self.amplitude}."
            )
        if self.wavenumber <= 0.0:
            raise ValueError(f"Sinusoid.wavenumber must be > 0 rad/m, got {self.wavenumber}.")

    def _values(self) -> tuple[float, ...]:
        return self.x0, self.y0, self.heading, self.amplitude, self.wavenumber, self.phase


@dataclass(frozen=True, kw_only=True)
class Lemniscate(Path):
    """Lemniscate of Gerono (closed figure-eight), period 2 pi half_width in theta.

    With a = half_width and t = theta / a the local curve is
    (a sin t, a sin t cos t), rotated by ``heading`` and centred on (cx, cy).
    ||(x', y')|| lies in [sqrt(7)/4, sqrt(2)], about [0.66, 1.41].

    Attributes:
        cx: Centre (crossing point) x (m).
        cy: Centre y (m).
        half_width: Half the extent along the figure's long axis (m), > 0.
        heading: Direction of the long axis (rad, from the x axis).
    """

    kind: ClassVar[int] = LEMNISCATE
    cx: float = 0.0
    cy: float = 0.0
    half_width: float
    heading: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.half_width <= 0.0:
            raise ValueError(f"Lemniscate.half_width must be > 0 m, got {self.half_width}.")

    def _values(self) -> tuple[float, ...]:
        return self.cx, self.cy, self.heading, self.half_width


def encode_paths(paths: Sequence[Path]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Encode paths for the simulator.

    Args:
        paths: n paths.

    Returns:
        kinds, shape (n,), int64, and params, shape (n, PATH_PARAM_SIZE), float64.
    """
    for path in paths:
        if not isinstance(path, Path):
            raise TypeError(f"encode_paths expects Path instances, got {type(path).__name__}.")
    kinds = np.array([path.kind for path in paths], dtype=np.int64)
    params = np.array([path.encode() for path in paths], dtype=np.float64).reshape(
        len(paths), PATH_PARAM_SIZE
    )
    return kinds, params
