"""Three-degree-of-freedom surface vessel model (Fossen), Cybership II by default.

The model of Wang, Wang & Peng (2014), eqs. [2]-[4]::

    d/dt eta = J(psi) nu
    M nu' + C(nu) nu + D(nu) nu = tau            (+ unmodeled terms, see model.disturbances)

with ``eta = [x, y, psi]`` (m, m, rad, earth frame) and ``nu = [u, v, r]``
(m/s, m/s, rad/s, body frame). Parameters are those of Cybership II, a 1:70
supply ship (Skjetne, Fossen & Kokotovic, Automatica 41(2), 2005).

The physics is written once, as scalar numba functions over a flat parameter
vector (``VesselModel.to_params()``, layout ``PARAM_NAMES``), so the same code
runs inside the simulator's fused kernel and behind the batched NumPy helpers
(``coriolis_matrix``, ``damping_matrix``, ``rotation``) used by tests and
controllers.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CYBERSHIP2",
    "PARAM_NAMES",
    "VesselModel",
    "coriolis_matrix",
    "damping_matrix",
    "kinetic_energy",
    "rotation",
]

#: Layout of the flat parameter vector: mass matrix, its inverse, damping.
PARAM_NAMES: tuple[str, ...] = (
    "m11", "m22", "m23", "m32", "m33",
    "i11", "i22", "i23", "i32", "i33",
    "X_u", "X_uu", "X_uuu",
    "Y_v", "Y_vv", "Y_rv", "Y_r", "Y_vr", "Y_rr",
    "N_v", "N_vv", "N_rv", "N_r", "N_vr", "N_rr",
)  # fmt: skip
PARAM_SIZE = len(PARAM_NAMES)
_P = {name: k for k, name in enumerate(PARAM_NAMES)}
# Indices as module constants: numba freezes them into the compiled kernels.
M11, M22, M23, M32, M33 = _P["m11"], _P["m22"], _P["m23"], _P["m32"], _P["m33"]
I11, I22, I23, I32, I33 = _P["i11"], _P["i22"], _P["i23"], _P["i32"], _P["i33"]
X_U = _P["X_u"]


@dataclass(frozen=True)
class VesselModel:
    """Rigid-body, added-mass and damping parameters of a 3-DOF vessel.

    Defaults are Cybership II (docs/model.md, section 1). Hydrodynamic derivatives
    follow SNAME notation; ``X_uu`` stands for X_|u|u, ``Y_rv`` for Y_|r|v, etc.

    Attributes:
        mass: Rigid-body mass m (kg).
        inertia_z: Yaw moment of inertia I_z (kg m^2).
        x_g: Longitudinal position of the centre of gravity (m).
        X_udot, Y_vdot, Y_rdot, N_vdot, N_rdot: Added-mass derivatives
            (kg, kg, kg m, kg m, kg m^2).
        X_u .. N_rr: Linear and quadratic damping derivatives (SI).
    """

    mass: float = 23.8
    inertia_z: float = 1.76
    x_g: float = 0.046
    X_udot: float = -2.0
    Y_vdot: float = -10.0
    Y_rdot: float = 0.0
    N_vdot: float = 0.0
    N_rdot: float = -1.0
    X_u: float = -0.72253
    X_uu: float = -1.32742
    X_uuu: float = -5.86643
    Y_v: float = -0.88965
    Y_vv: float = -36.47287
    Y_rv: float = -0.805
    Y_r: float = -7.250
    Y_vr: float = -0.845
    Y_rr: float = -3.450
    N_v: float = 0.03130
    N_vv: float = 3.95645
    N_rv: float = 0.130
    N_r: float = -1.900
    N_vr: float = 0.080
    N_rr: float = -0.750

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not math.isfinite(value):
                raise ValueError(
                    f"VesselModel.{field.name} = {value} is not finite; give a number."
                )
        if self.mass <= 0.0 or self.inertia_z <= 0.0:
            raise ValueError(
                f"VesselModel needs mass > 0 and inertia_z > 0 (got {self.mass}, {self.inertia_z})."
            )
        eigenvalues = np.linalg.eigvalsh(0.5 * (self.mass_matrix() + self.mass_matrix().T))
        if eigenvalues.min() <= 0.0:
            raise ValueError(
                "VesselModel mass matrix M is not positive definite "
                f"(eigenvalues {eigenvalues.round(4).tolist()}); check mass, inertia_z, x_g "
                "and the added-mass derivatives (they are usually <= 0)."
            )

    def mass_matrix(self) -> NDArray[np.float64]:
        """Return M = M_RB + M_A, shape (3, 3), docs/model.md, section 1."""
        m, xg = self.mass, self.x_g
        return np.array(
            [
                [m - self.X_udot, 0.0, 0.0],
                [0.0, m - self.Y_vdot, m * xg - self.Y_rdot],
                [0.0, m * xg - self.N_vdot, self.inertia_z - self.N_rdot],
            ]
        )

    def to_params(self) -> NDArray[np.float64]:
        """Flatten to the kernel's parameter vector, shape (PARAM_SIZE,), layout ``PARAM_NAMES``."""
        mass = self.mass_matrix()
        inverse = np.linalg.inv(mass)
        damping = [getattr(self, name) for name in PARAM_NAMES[10:]]
        return np.array(
            [mass[0, 0], mass[1, 1], mass[1, 2], mass[2, 1], mass[2, 2]]
            + [inverse[0, 0], inverse[1, 1], inverse[1, 2], inverse[2, 1], inverse[2, 2]]
            + damping,
            dtype=np.float64,
        )

    def perturbed(self, rng: np.random.Generator, spread: float) -> VesselModel:
        """Draw a model with every parameter scaled by its own factor U(1 - spread, 1 + spread).

        Used by heterogeneous-fleet scenarios (rigid-body, added-mass and
        damping parameters alike); the result is re-validated.

        Args:
            rng: Generator to draw from (the env's, for reproducibility).
            spread: Relative half-width of the uniform factor, in [0, 1).
        """
        if not 0.0 <= spread < 1.0:
            raise ValueError(f"spread must be in [0, 1), got {spread}.")
        names = [field.name for field in dataclasses.fields(self)]
        factors = rng.uniform(1.0 - spread, 1.0 + spread, size=len(names))
        return dataclasses.replace(
            self, **{name: getattr(self, name) * f for name, f in zip(names, factors, strict=True)}
        )


#: The paper's vessel (Skjetne et al. 2005 identification).
CYBERSHIP2 = VesselModel()


@numba.njit(cache=True, inline="always")
def coriolis_coefficients(p: NDArray[np.float64], u: float, v: float, r: float) -> tuple:
    """Return (c13, c23) of C(nu) = [[0, 0, c13], [0, 0, c23], [-c13, -c23, 0]] (docs/model.md)."""
    return -p[M22] * v - p[M23] * r, p[M11] * u


@numba.njit(cache=True, inline="always")
def damping_coefficients(p: NDArray[np.float64], u: float, v: float, r: float) -> tuple:
    """Return (d11, d22, d23, d32, d33) of the nonlinear damping D(nu) (docs/model.md s. 1)."""
    au, av, ar = abs(u), abs(v), abs(r)
    d11 = -p[X_U] - p[X_U + 1] * au - p[X_U + 2] * u * u
    d22 = -p[X_U + 3] - p[X_U + 4] * av - p[X_U + 5] * ar
    d23 = -p[X_U + 6] - p[X_U + 7] * av - p[X_U + 8] * ar
    d32 = -p[X_U + 9] - p[X_U + 10] * av - p[X_U + 11] * ar
    d33 = -p[X_U + 12] - p[X_U + 13] * av - p[X_U + 14] * ar
    return d11, d22, d23, d32, d33


@numba.njit(cache=True, inline="always")
def hydrodynamic_forces(p: NDArray[np.float64], u: float, v: float, r: float) -> tuple:
    """Return C(nu) nu + D(nu) nu, components (N, N, N m)."""
    c13, c23 = coriolis_coefficients(p, u, v, r)
    d11, d22, d23, d32, d33 = damping_coefficients(p, u, v, r)
    return (
        c13 * r + d11 * u,
        c23 * r + d22 * v + d23 * r,
        -c13 * u - c23 * v + d32 * v + d33 * r,
    )


@numba.njit(cache=True, inline="always")
def solve_mass(p: NDArray[np.float64], f0: float, f1: float, f2: float) -> tuple:
    """Return M^{-1} f for a force vector f = (f0, f1, f2)."""
    return p[I11] * f0, p[I22] * f1 + p[I23] * f2, p[I32] * f1 + p[I33] * f2


@numba.njit(cache=True)
def _matrices(
    params: NDArray[np.float64], nu: NDArray[np.float64], out: NDArray[np.float64]
) -> None:
    for k in range(nu.shape[0]):
        p, u, v, r = params[k], nu[k, 0], nu[k, 1], nu[k, 2]
        c13, c23 = coriolis_coefficients(p, u, v, r)
        d11, d22, d23, d32, d33 = damping_coefficients(p, u, v, r)
        out[k, 0, 0, 2], out[k, 0, 1, 2] = c13, c23
        out[k, 0, 2, 0], out[k, 0, 2, 1] = -c13, -c23
        out[k, 1, 0, 0], out[k, 1, 1, 1], out[k, 1, 1, 2] = d11, d22, d23
        out[k, 1, 2, 1], out[k, 1, 2, 2] = d32, d33


def _coriolis_and_damping(params: ArrayLike, nu: ArrayLike) -> NDArray[np.float64]:
    nu = np.asarray(nu, dtype=np.float64)
    params = np.broadcast_to(np.asarray(params, dtype=np.float64), (*nu.shape[:-1], PARAM_SIZE))
    flat_nu = np.ascontiguousarray(nu.reshape(-1, 3))
    out = np.zeros((flat_nu.shape[0], 2, 3, 3))
    _matrices(np.ascontiguousarray(params.reshape(-1, PARAM_SIZE)), flat_nu, out)
    return out.reshape((*nu.shape[:-1], 2, 3, 3))


def coriolis_matrix(params: ArrayLike, nu: ArrayLike) -> NDArray[np.float64]:
    """Coriolis-centripetal matrix C(nu), skew-symmetric.

    Args:
        params: Parameter vectors, shape (..., PARAM_SIZE) broadcastable to nu's batch shape.
        nu: Body velocities [u, v, r], shape (..., 3), (m/s, m/s, rad/s).

    Returns:
        Array of shape (..., 3, 3).
    """
    return _coriolis_and_damping(params, nu)[..., 0, :, :]


def damping_matrix(params: ArrayLike, nu: ArrayLike) -> NDArray[np.float64]:
    """Nonlinear damping matrix D(nu), shape (..., 3, 3); see ``coriolis_matrix`` for arguments."""
    return _coriolis_and_damping(params, nu)[..., 1, :, :]


def kinetic_energy(params: ArrayLike, nu: ArrayLike) -> NDArray[np.float64]:
    """Kinetic energy 0.5 nu^T M nu (J), shape (...) for nu of shape (..., 3)."""
    p = np.asarray(params, dtype=np.float64)
    nu = np.asarray(nu, dtype=np.float64)
    u, v, r = nu[..., 0], nu[..., 1], nu[..., 2]
    return 0.5 * (
        p[..., M11] * u * u
        + p[..., M22] * v * v
        + (p[..., M23] + p[..., M32]) * v * r
        + p[..., M33] * r * r
    )


def rotation(psi: ArrayLike) -> NDArray[np.float64]:
    """Rotation J(psi) from body to earth frame, eq. [4]; shape psi.shape + (3, 3)."""
    psi = np.asarray(psi, dtype=np.float64)
    c, s = np.cos(psi), np.sin(psi)
    out = np.zeros((*psi.shape, 3, 3))
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    out[..., 2, 2] = 1.0
    return out
