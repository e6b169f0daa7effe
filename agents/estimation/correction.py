"""A learned correction of the navigation filter's estimate, from what the vessel has seen.

The filter (``baselines.estimator``) weighs its fixes by a model of the hull
and of the sea. What it gets wrong is partly predictable from what the vessel
saw since: the fixes it was handed and how far each lay from the estimate,
and the forces the thrusters applied. A ``Correction`` is a linear map,
fitted by ridge regression on closed-loop episodes where the true state is
known, from that recent history to the estimate's error:

* inputs, per vessel, over the last ``window`` control steps (newest first):
  the last fix (x, y, psi) minus the estimate, in the estimate's body frame
  (m, m, rad; held between fixes, as the observation holds it), and the
  applied force the observation reports over the vessel's force scale
  ``max(|tau_min|, |tau_max|)``; then the estimate's velocity and bias (6);
* output, per vessel: the estimate's error, true minus estimated, of the
  pose in the estimate's body frame (m, m, rad) and of the body velocity
  (m/s, m/s, rad/s).

Each input is standardized with the training data's mean and spread; the
map is one matrix (``weights``, (D, 6)) and an offset. Everything here is
batched over (fleets, vessels) and free of any learning library: fitting
is least squares (``fit``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

__all__ = ["STEP_SIZE", "TARGET_SIZE", "Correction", "body_error", "correct", "fit", "step_inputs"]

Array = NDArray[np.float64]

#: Inputs per vessel and control step: the fix offset (3) and the applied force (3).
STEP_SIZE = 6
#: The estimate's velocity and bias, appended once (6).
STATE_SIZE = 6
#: Outputs per vessel: the pose error in the body frame (3) and the velocity error (3).
TARGET_SIZE = 6


def _wrap(angle: Array) -> Array:
    """Angles wrapped to [-pi, pi) (rad)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def _to_body(states: Array, dx: Array, dy: Array) -> tuple[Array, Array]:
    """Earth-frame offsets (dx, dy) in the body frame of each estimate's heading."""
    c, s = np.cos(states[..., 2]), np.sin(states[..., 2])
    return c * dx + s * dy, -s * dx + c * dy


def step_inputs(states: Array, last_fix: Array, applied: Array, force_scale: Array) -> Array:
    """One control step's inputs per vessel (..., n, ``STEP_SIZE``).

    Args:
        states: (..., n, 9) the filter's estimates (``Filtered.state``).
        last_fix: (..., n, 3) the last fix x, y (m), psi (rad) (``Filtered.last_fix``).
        applied: (..., n, 3) the applied force the observation reports (N, N, N m).
        force_scale: (n, 3) each vessel's force scale (N, N, N m).
    """
    x, y = _to_body(states, last_fix[..., 0] - states[..., 0], last_fix[..., 1] - states[..., 1])
    heading = _wrap(last_fix[..., 2] - states[..., 2])
    return np.concatenate([np.stack([x, y, heading], axis=-1), applied / force_scale], axis=-1)


def body_error(states: Array, eta: Array, nu: Array) -> Array:
    """The estimate's error, true minus estimated (..., n, ``TARGET_SIZE``) (module docstring).

    Args:
        states: (..., n, 9) the filter's estimates.
        eta: (..., n, 3) the true pose x, y (m), psi (rad).
        nu: (..., n, 3) the true body velocity u, v (m/s), r (rad/s).
    """
    x, y = _to_body(states, eta[..., 0] - states[..., 0], eta[..., 1] - states[..., 1])
    pose = np.stack([x, y, _wrap(eta[..., 2] - states[..., 2])], axis=-1)
    return np.concatenate([pose, nu - states[..., 3:6]], axis=-1)


def correct(states: Array, errors: Array) -> Array:
    """The estimates (..., n, 9) moved by predicted ``errors`` (..., n, ``TARGET_SIZE``)."""
    out = np.array(states, dtype=np.float64)
    c, s = np.cos(states[..., 2]), np.sin(states[..., 2])
    out[..., 0] += c * errors[..., 0] - s * errors[..., 1]
    out[..., 1] += s * errors[..., 0] + c * errors[..., 1]
    out[..., 2] = _wrap(out[..., 2] + errors[..., 2])
    out[..., 3:6] += errors[..., 3:6]
    return out


@dataclasses.dataclass(frozen=True)
class Correction:
    """A fitted linear correction (module docstring).

    Attributes:
        window: Control steps of history it reads.
        weights: (D, ``TARGET_SIZE``) on the standardized inputs, D = window *
            ``STEP_SIZE`` + ``STATE_SIZE``.
        input_mean: (D,) the training inputs' mean.
        input_scale: (D,) their standard deviation (floored: a constant input reads 0).
        offset: (``TARGET_SIZE``,) the training errors' mean.
    """

    window: int
    weights: Array
    input_mean: Array
    input_scale: Array
    offset: Array

    def __post_init__(self) -> None:
        size = self.inputs
        shapes = {
            "weights": (size, TARGET_SIZE),
            "input_mean": (size,),
            "input_scale": (size,),
            "offset": (TARGET_SIZE,),
        }
        for name, shape in shapes.items():
            value = getattr(self, name)
            if np.shape(value) != shape:
                raise ValueError(
                    f"a correction with a window of {self.window} steps needs {name} of shape "
                    f"{shape}, got {np.shape(value)}."
                )
            if not np.all(np.isfinite(value)):
                raise ValueError(f"the correction's {name} holds a non-finite value.")
        if not np.all(self.input_scale > 0.0):
            raise ValueError("the correction's input_scale must be > 0 everywhere.")

    @property
    def inputs(self) -> int:
        """D, the inputs per vessel."""
        return self.window * STEP_SIZE + STATE_SIZE

    def predict(self, history: Array, states: Array) -> Array:
        """The predicted errors (..., n, ``TARGET_SIZE``).

        Args:
            history: (..., n, window, ``STEP_SIZE``) the step inputs, newest first.
            states: (..., n, 9) the filter's estimates.
        """
        return self.apply(assemble(history, states))

    def apply(self, inputs: Array) -> Array:
        """The predicted errors (..., ``TARGET_SIZE``) of assembled inputs (..., D)."""
        return ((inputs - self.input_mean) / self.input_scale) @ self.weights + self.offset


def assemble(history: Array, states: Array) -> Array:
    """The inputs (..., n, D) of a history (..., n, window, ``STEP_SIZE``) and the estimates."""
    flat = history.reshape(*history.shape[:-2], -1)
    return np.concatenate([flat, states[..., 3:9]], axis=-1)


def fit(inputs: Array, errors: Array, window: int, ridge: float) -> Correction:
    """Least squares with a ridge penalty: the ``Correction`` that maps ``inputs`` to ``errors``.

    Args:
        inputs: (N, D) samples (``assemble``).
        errors: (N, ``TARGET_SIZE``) the estimate's errors (``body_error``).
        window: The history's length in steps (D = window * ``STEP_SIZE`` + 6).
        ridge: The penalty on the standardized weights, per sample (>= 0).
    """
    if ridge < 0.0:
        raise ValueError(f"ridge must be >= 0, got {ridge!r}.")
    mean = inputs.mean(axis=0)
    scale = np.maximum(inputs.std(axis=0), 1e-9)
    offset = errors.mean(axis=0)
    a = (inputs - mean) / scale
    gram = a.T @ a + ridge * len(a) * np.eye(a.shape[1])
    weights = np.linalg.solve(gram, a.T @ (errors - offset))
    return Correction(window, weights, mean, scale, offset)
