"""Unmodeled dynamics, ocean current and environmental forces, all seeded.

Three parts, combined by the simulator's plant right-hand side:

* The paper's unmodeled dynamics Delta_i(nu) and disturbance tau_wi(t, nu)
  (Wang, Wang & Peng 2014, section 4; docs/model.md, section 2), scaled by
  ``Disturbances.unmodeled_scale``. Sign convention of eq. [3]: Delta on the
  left-hand side, tau_w on the right.
* An earth-fixed, irrotational ocean current V_c = (V_x, V_y) (m/s), constant
  or slowly varying (first-order Gauss-Markov). The hydrodynamic terms act on
  the velocity relative to the water, nu_r = nu - J(psi)^T [V_c, 0]
  (Fossen 2011, section 10.3).
* Wave and wind forces, each a first-order Gauss-Markov process
  ``x' = -(x - mean)/T + w`` in the earth frame (N, N, N m), discretized
  exactly per control step and rotated into the body frame.

Random draws come from the counter-based generator of ``cpf_env.model.counter_rng``,
keyed per fleet, so a fleet's disturbances do not depend on how many fleets
run beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DIST_PARAM_SIZE",
    "Disturbances",
    "GaussMarkov",
    "OceanCurrent",
    "paper_disturbance",
    "paper_unmodeled",
]


def _check_vector(name: str, value: tuple[float, ...], size: int, nonnegative: bool) -> None:
    if len(value) != size or not all(math.isfinite(x) for x in value):
        raise ValueError(f"{name} must be {size} finite numbers, got {value}.")
    if nonnegative and any(x < 0.0 for x in value):
        raise ValueError(f"{name} must be >= 0 (a standard deviation), got {value}.")


@dataclass(frozen=True)
class GaussMarkov:
    """First-order Gauss-Markov force process in the earth frame.

    Attributes:
        mean: Mean force (X, Y, N) in (N, N, N m), earth frame.
        std: Stationary standard deviation per component, same units.
        time_constant: Correlation time T (s), > 0.
    """

    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (0.0, 0.0, 0.0)
    time_constant: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "mean", tuple(float(x) for x in self.mean))
        object.__setattr__(self, "std", tuple(float(x) for x in self.std))
        _check_vector("GaussMarkov.mean", self.mean, 3, nonnegative=False)
        _check_vector("GaussMarkov.std", self.std, 3, nonnegative=True)
        if not self.time_constant > 0.0:
            raise ValueError(f"GaussMarkov.time_constant must be > 0 s, got {self.time_constant}.")


@dataclass(frozen=True)
class OceanCurrent:
    """Earth-fixed irrotational current, optionally slowly varying.

    Attributes:
        velocity: Mean current (V_x, V_y) in m/s, earth frame.
        std: Stationary standard deviation of each component (m/s).
        time_constant: Correlation time of the variation (s), > 0.
    """

    velocity: tuple[float, float] = (0.0, 0.0)
    std: float = 0.0
    time_constant: float = 60.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "velocity", tuple(float(x) for x in self.velocity))
        _check_vector("OceanCurrent.velocity", self.velocity, 2, nonnegative=False)
        if not (math.isfinite(self.std) and self.std >= 0.0):
            raise ValueError(f"OceanCurrent.std must be >= 0 m/s, got {self.std}.")
        if not self.time_constant > 0.0:
            raise ValueError(f"OceanCurrent.time_constant must be > 0 s, got {self.time_constant}.")


@dataclass(frozen=True)
class Disturbances:
    """Everything the controller does not know about the plant.

    Attributes:
        unmodeled_scale: Factor on the paper's Delta(nu) and tau_w(t, nu): 1 is the
            paper, 0 removes them.
        current: Ocean current.
        waves: Wave force process (fast: T of a few seconds).
        wind: Wind force process (slow gusts around a mean).
    """

    unmodeled_scale: float = 1.0
    current: OceanCurrent = OceanCurrent()
    waves: GaussMarkov = GaussMarkov(time_constant=2.0)
    wind: GaussMarkov = GaussMarkov(time_constant=30.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.unmodeled_scale) and self.unmodeled_scale >= 0.0):
            raise ValueError(
                f"Disturbances.unmodeled_scale must be >= 0, got {self.unmodeled_scale}."
            )

    def encode(self) -> NDArray[np.float64]:
        """Flatten for the kernel, shape (DIST_PARAM_SIZE,), layout of the ``D_*`` indices."""
        c, w, g = self.current, self.waves, self.wind
        return np.array(
            [self.unmodeled_scale, *c.velocity, c.std, c.time_constant]
            + [*w.mean, *w.std, w.time_constant]
            + [*g.mean, *g.std, g.time_constant],
            dtype=np.float64,
        )


# Layout of Disturbances.encode(); the kernel reads these indices.
D_SCALE, D_CURRENT_MEAN, D_CURRENT_STD, D_CURRENT_TC = 0, 1, 3, 4
D_WAVE_MEAN, D_WAVE_STD, D_WAVE_TC = 5, 8, 11
D_WIND_MEAN, D_WIND_STD, D_WIND_TC = 12, 15, 18
DIST_PARAM_SIZE = 19


@numba.njit(cache=True, inline="always")
def paper_unmodeled(u: float, v: float, r: float) -> tuple:
    """Delta_i(nu) of the paper's section 4 (N, N, N m)."""
    return v * v * v + 0.03 * u, u * r + 0.02 * u, u * r + 0.2 * r * r


@numba.njit(cache=True, inline="always")
def paper_time_term(t: float) -> float:
    """The time-varying part 0.001 sin(t) of tau_wi(t, nu), the same on every axis (N, N m)."""
    return 0.001 * math.sin(t)


@numba.njit(cache=True, inline="always")
def paper_disturbance_given(time_term: float, u: float, v: float, r: float) -> tuple:
    """tau_wi(t, nu) (N, N, N m) from its time term ``paper_time_term(t)``.

    The time term depends on t only, so a caller evaluating many vessels at
    one time computes it once.
    """
    s = time_term
    return v * v * v + 0.06 * u + s, u * r + 0.1 * u + s, 0.4 * u * r + v * v + s


@numba.njit(cache=True, inline="always")
def paper_disturbance(t: float, u: float, v: float, r: float) -> tuple:
    """tau_wi(t, nu) of the paper's section 4 (N, N, N m); t in s."""
    return paper_disturbance_given(paper_time_term(t), u, v, r)


@numba.njit(cache=True, inline="always")
def gauss_markov_factors(time_constant: float, dt: float) -> tuple:
    """(a, sqrt(1 - a^2)), a = exp(-dt / T): the one-step factors of ``gauss_markov_update``.

    Args:
        time_constant: Correlation time T (s).
        dt: Step (s).
    """
    a = math.exp(-dt / time_constant)
    return a, math.sqrt(1.0 - a * a)


@numba.njit(cache=True, inline="always")
def gauss_markov_drift(x: float, mean: float, a: float) -> float:
    """The deterministic part mean + a (x - mean) of ``gauss_markov_update``."""
    return mean + a * (x - mean)


@numba.njit(cache=True, inline="always")
def gauss_markov_update(drift: float, spread: float, noise: float) -> float:
    """Exact one-step update of a stationary first-order Gauss-Markov process.

    x_next = mean + a (x - mean) + std sqrt(1 - a^2) noise, evaluated in that order.

    Args:
        drift: ``gauss_markov_drift(x, mean, a)``.
        spread: std * sqrt(1 - a^2), with std the stationary standard deviation and
            a, sqrt(1 - a^2) from ``gauss_markov_factors``.
        noise: A standard normal draw.
    """
    return drift + spread * noise


@numba.njit(cache=True, inline="always")
def gauss_markov_needs_noise(drift: float, spread: float) -> bool:
    """False when the update is ``drift`` whatever the (finite) noise draw.

    With ``spread == 0`` the noise term is +0.0 or -0.0 (the sign of the draw),
    and adding either leaves every ``drift`` unchanged but -0.0 (-0.0 + 0.0 is
    0.0; 0.0 + -0.0 is 0.0): a process without spread needs no draw, bit for bit.
    """
    return spread != 0.0 or (drift == 0.0 and math.copysign(1.0, drift) < 0.0)
