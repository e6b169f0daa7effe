"""A learned correction of the navigation filter's estimate, from what the vessel has seen.

The filter (``baselines.estimator``) weighs its fixes by a model of the hull
and of the sea. What it gets wrong is partly predictable from what the vessel
saw since: the fixes it was handed and how far each lay from the estimate,
and the forces the thrusters applied. A ``Correction`` maps that recent
history to the estimate's error, fitted on closed-loop episodes where the
true state is known:

* inputs, per vessel, over the last ``window`` control steps (newest first):
  the last fix (x, y, psi) minus the estimate, in the estimate's body frame
  (m, m, rad; held between fixes, as the observation holds it), and the
  applied force the observation reports over the vessel's force scale
  ``max(|tau_min|, |tau_max|)``; then the estimate's velocity and bias (6);
  then, for each of the M filters of the base's bank (``Filtered.members``),
  its own estimate minus the blend, the pose in the blend's body frame
  (m, m, rad, m/s, m/s, rad/s and the bias's three, 9 each): filters of one
  model at several process noises, so several averages of the same fixes
  over several memories, which the map weighs where the likelihood's blend
  holds one weight per filter;
* output, per vessel: the estimate's error, true minus estimated, of the
  pose in the estimate's body frame (m, m, rad) and of the body velocity
  (m/s, m/s, rad/s).

Each input is standardized with the training data's mean and spread. The
map is a matrix (``weights``, (D, 6)) and an offset, fitted by ridge
regression (``fit``), plus, optionally, a network (``layers``: SiLU hidden
layers) on the same standardized inputs whose output, times each error's
spread (``target_scale``), adds what the matrix leaves
(``agents.estimation.network`` fits it). A ``Correction`` of zeros
(``Correction.zero``) changes nothing, bit for bit: the base itself, where
a fit starts. Everything here is batched over (fleets, vessels), in NumPy:
the correction acts without a learning library.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from cpf_env.sim.observation import wrap_angles

__all__ = [
    "CHUNK",
    "MEMBER_SIZE",
    "STEP_SIZE",
    "TARGET_SIZE",
    "Correction",
    "assemble",
    "body_error",
    "correct",
    "fit",
    "input_size",
    "member_offsets",
    "step_inputs",
]

Array = NDArray[np.float64]

#: Samples the fits standardize or map at a time (rows): a bound on their extra memory.
CHUNK = 65_536
#: Inputs per vessel and control step: the fix offset (3) and the applied force (3).
STEP_SIZE = 6
#: The estimate's velocity and bias, appended once (6).
STATE_SIZE = 6
#: Inputs per filter of the bank: its estimate minus the blend (9).
MEMBER_SIZE = 9
#: Outputs per vessel: the pose error in the body frame (3) and the velocity error (3).
TARGET_SIZE = 6


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
    heading = wrap_angles(last_fix[..., 2] - states[..., 2])
    return np.concatenate([np.stack([x, y, heading], axis=-1), applied / force_scale], axis=-1)


def body_error(states: Array, eta: Array, nu: Array) -> Array:
    """The estimate's error, true minus estimated (..., n, ``TARGET_SIZE``) (module docstring).

    Args:
        states: (..., n, 9) the filter's estimates.
        eta: (..., n, 3) the true pose x, y (m), psi (rad).
        nu: (..., n, 3) the true body velocity u, v (m/s), r (rad/s).
    """
    x, y = _to_body(states, eta[..., 0] - states[..., 0], eta[..., 1] - states[..., 1])
    pose = np.stack([x, y, wrap_angles(eta[..., 2] - states[..., 2])], axis=-1)
    return np.concatenate([pose, nu - states[..., 3:6]], axis=-1)


def correct(states: Array, errors: Array) -> Array:
    """The estimates (..., n, 9) moved by predicted ``errors`` (..., n, ``TARGET_SIZE``).

    A heading left in [-pi, pi) is not rewrapped, so errors of zero return ``states``
    bit for bit.
    """
    out = np.array(states, dtype=np.float64)
    c, s = np.cos(states[..., 2]), np.sin(states[..., 2])
    out[..., 0] += c * errors[..., 0] - s * errors[..., 1]
    out[..., 1] += s * errors[..., 0] + c * errors[..., 1]
    heading = out[..., 2] + errors[..., 2]
    inside = (heading >= -np.pi) & (heading < np.pi)
    out[..., 2] = np.where(inside, heading, wrap_angles(heading))
    out[..., 3:6] += errors[..., 3:6]
    return out


def input_size(window: int, members: int) -> int:
    """D, the inputs per vessel of a ``window``-step history and a bank of ``members`` filters."""
    return window * STEP_SIZE + STATE_SIZE + members * MEMBER_SIZE


def member_offsets(states: Array, members: Array) -> Array:
    """Each filter of the bank minus the blend (..., n, M * ``MEMBER_SIZE``) (module docstring).

    Args:
        states: (..., n, 9) the blended estimates (``Filtered.state``).
        members: (..., n, M, 9) each filter's estimate (``Filtered.members``).
    """
    blend = states[..., None, :]
    x, y = _to_body(blend, members[..., 0] - blend[..., 0], members[..., 1] - blend[..., 1])
    heading = wrap_angles(members[..., 2] - blend[..., 2])
    rest = members[..., 3:] - blend[..., 3:]
    offsets = np.concatenate([np.stack([x, y, heading], axis=-1), rest], axis=-1)
    return offsets.reshape(*offsets.shape[:-2], -1)


def assemble(history: Array, states: Array, members: Array) -> Array:
    """The inputs (..., n, D) of a vessel's history, estimate and bank (module docstring).

    Args:
        history: (..., n, window, ``STEP_SIZE``) the step inputs, newest first.
        states: (..., n, 9) the blended estimates.
        members: (..., n, M, 9) each filter's estimate.
    """
    flat = history.reshape(*history.shape[:-2], -1)
    return np.concatenate([flat, states[..., 3:9], member_offsets(states, members)], axis=-1)


@dataclasses.dataclass(frozen=True)
class Correction:
    """A fitted correction: a matrix, and maybe a network (module docstring).

    Attributes:
        window: Control steps of history it reads.
        members: M, the filters of the base's bank it reads.
        weights: (D, ``TARGET_SIZE``) on the standardized inputs, D = window *
            ``STEP_SIZE`` + ``STATE_SIZE`` + M * ``MEMBER_SIZE``.
        input_mean: (D,) the training inputs' mean.
        input_scale: (D,) their standard deviation (floored: a constant input reads 0).
        offset: (``TARGET_SIZE``,) the training errors' mean.
        target_scale: (``TARGET_SIZE``,) the training errors' spread, the network
            output's unit.
        layers: The network's (weight (inputs, outputs), bias (outputs,)) pairs, first
            to last: D inputs, ``TARGET_SIZE`` outputs, SiLU between; () for none.
    """

    window: int
    members: int
    weights: Array
    input_mean: Array
    input_scale: Array
    offset: Array
    target_scale: Array
    layers: tuple[tuple[Array, Array], ...] = ()

    def __post_init__(self) -> None:
        for name in ("window", "members"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"a correction's {name} must be an integer >= 1, got {value!r}.")
        size = self.inputs
        shapes = {
            "weights": (size, TARGET_SIZE),
            "input_mean": (size,),
            "input_scale": (size,),
            "offset": (TARGET_SIZE,),
            "target_scale": (TARGET_SIZE,),
        }
        width = size
        for k, (weight, _) in enumerate(self.layers):
            last = k == len(self.layers) - 1
            out = TARGET_SIZE if last or np.ndim(weight) != 2 else np.shape(weight)[-1]
            shapes[f"layers.{k}.weight"] = (width, out)
            shapes[f"layers.{k}.bias"] = (out,)
            width = out
        for name, shape in shapes.items():
            value = self.arrays[name]
            if np.shape(value) != shape:
                raise ValueError(
                    f"a correction with a window of {self.window} steps and {self.members} "
                    f"filters needs {name} of shape {shape}, got {np.shape(value)}."
                )
            if not np.all(np.isfinite(value)):
                raise ValueError(f"the correction's {name} holds a non-finite value.")
        if not np.all(self.input_scale > 0.0):
            raise ValueError("the correction's input_scale must be > 0 everywhere.")

    @classmethod
    def zero(cls, window: int, members: int) -> Correction:
        """The correction that changes nothing: its filter acts as its base."""
        size = input_size(window, members)
        return cls(
            window, members, np.zeros((size, TARGET_SIZE)), np.zeros(size), np.ones(size),
            np.zeros(TARGET_SIZE), np.ones(TARGET_SIZE),
        )  # fmt: skip

    @property
    def inputs(self) -> int:
        """D, the inputs per vessel."""
        return input_size(self.window, self.members)

    def predict(self, history: Array, states: Array, members: Array) -> Array:
        """The predicted errors (..., n, ``TARGET_SIZE``) (arguments: ``assemble``)."""
        return self.apply(assemble(history, states, members))

    @property
    def arrays(self) -> dict[str, Array]:
        """Every array by name (``layers.{k}.weight`` and ``.bias`` for the network's)."""
        named = {
            name: getattr(self, name)
            for name in ("weights", "input_mean", "input_scale", "offset", "target_scale")
        }
        for k, (weight, bias) in enumerate(self.layers):
            named[f"layers.{k}.weight"], named[f"layers.{k}.bias"] = weight, bias
        return named

    def apply(self, inputs: Array) -> Array:
        """The predicted errors (..., ``TARGET_SIZE``) of assembled inputs (..., D)."""
        standard = (inputs - self.input_mean) / self.input_scale
        errors = standard @ self.weights + self.offset
        if self.layers:
            hidden = standard
            for weight, bias in self.layers[:-1]:
                hidden = hidden @ weight + bias
                with np.errstate(over="ignore"):  # exp(-h) = inf below h = -709: SiLU -> -0
                    hidden = hidden / (1.0 + np.exp(-hidden))  # SiLU
            errors = errors + (hidden @ self.layers[-1][0] + self.layers[-1][1]) * self.target_scale
        return errors


def fit(inputs: Array, errors: Array, window: int, members: int, ridge: float) -> Correction:
    """Least squares with a ridge penalty: the ``Correction`` that maps ``inputs`` to ``errors``.

    Args:
        inputs: (N, D) samples (``assemble``).
        errors: (N, ``TARGET_SIZE``) the estimate's errors (``body_error``).
        window: The history's length in steps.
        members: The filters of the bank the inputs hold.
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
    spread = np.maximum(errors.std(axis=0), 1e-12)
    return Correction(window, members, weights, mean, scale, offset, spread)
