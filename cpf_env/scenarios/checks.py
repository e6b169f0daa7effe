"""Checks of scenario values: plain numbers, and a plant sub-step the integrator can take.

``Scenario`` calls these at construction so that a setting the simulator
cannot run fails there, with the fix in the message, instead of as a
diverged state many steps later.

The step-size check linearizes the plant of ``cpf_env.model.plant`` at rest:

    nu' = A nu,   A = -M^-1 (D_lin - s L)

with D_lin the linear damping (-X_u; -Y_v, -Y_r; -N_v, -N_r), s the
``unmodeled_scale`` and L the linear part of the paper's tau_w - Delta
(0.03 u in surge, 0.08 u in sway; see ``docs/model.md``). Classical RK4 is
stable on the negative real axis up to h |lambda| = 2.785; we require
h |lambda| <= ``RK4_LIMIT`` for every eigenvalue lambda of A, with h = dt /
substeps, and for a heterogeneous fleet (``model_spread`` = e) scale |lambda|
by (1 + e) / (1 - e), the worst draw of the mass and damping factors. The
check is necessary, not sufficient: quadratic damping and the paper's cubic
terms make the plant stiffer at speed, which the run-time check of
``FleetSim.step`` reports.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import NDArray

from cpf_env.model.vessel import VesselModel

__all__ = ["RK4_LIMIT", "as_integer", "as_real", "fastest_mode", "plant_modes"]

#: Largest h |lambda| accepted for the plant's RK4 sub-step (stability limit 2.785).
RK4_LIMIT = 2.5

#: Linear part of the paper's tau_w - Delta per unit unmodeled_scale, acting on nu (N per m/s).
_UNMODELED_LINEAR = np.array([[0.03, 0.0, 0.0], [0.08, 0.0, 0.0], [0.0, 0.0, 0.0]])


def as_real(name: str, value: object, unit: str) -> float:
    """``value`` as a float, or a ValueError that names the field and the expected type.

    Accepts python and numpy reals (not bools, strings or complex numbers).
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(
            f"{name} must be a real number ({unit}), got {value!r} ({type(value).__name__})."
        )
    return float(value)


def as_integer(name: str, value: object) -> int:
    """``value`` as an int, or a ValueError; accepts python and numpy integers (not bools)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r} ({type(value).__name__}).")
    return int(value)


def plant_modes(model: VesselModel, unmodeled_scale: float) -> NDArray[np.complex128]:
    """Eigenvalues (1/s) of the plant linearized at rest, nu' = A nu (see module docstring)."""
    damping = np.array(
        [
            [-model.X_u, 0.0, 0.0],
            [0.0, -model.Y_v, -model.Y_r],
            [0.0, -model.N_v, -model.N_r],
        ]
    )
    matrix = -np.linalg.solve(model.mass_matrix(), damping - unmodeled_scale * _UNMODELED_LINEAR)
    return np.linalg.eigvals(matrix).astype(np.complex128)


def fastest_mode(model: VesselModel, unmodeled_scale: float) -> float:
    """|lambda| (1/s) of the plant's fastest linear mode at rest."""
    return float(np.max(np.abs(plant_modes(model, unmodeled_scale))))


def check_plant_step(
    models: tuple[VesselModel, ...],
    unmodeled_scale: float,
    model_spread: float,
    dt: float,
    substeps: int,
) -> None:
    """Raise ValueError if the RK4 sub-step dt / substeps cannot resolve a vessel's fastest mode.

    Args:
        models: Nominal model of every vessel.
        unmodeled_scale: Factor on the paper's unmodeled dynamics.
        model_spread: Relative spread of the true models around the nominal ones, in [0, 1).
        dt: Control period (s).
        substeps: RK4 steps per control period.
    """
    h = dt / substeps
    worst = (1.0 + model_spread) / (1.0 - model_spread)
    for i, model in enumerate(models):
        rate = fastest_mode(model, unmodeled_scale) * worst
        if h * rate <= RK4_LIMIT:
            continue
        needed = math.ceil(dt * rate / RK4_LIMIT)
        raise ValueError(
            f"the plant sub-step dt / substeps = {dt:g} / {substeps} = {h:.3g} s is too long "
            f"for vessel {i}: its fastest linear mode has a rate of {rate:.3g} 1/s (mass "
            f"matrix, linear damping, unmodeled_scale = {unmodeled_scale:g}"
            + (f", model_spread = {model_spread:g}" if model_spread else "")
            + f"), and RK4 needs h * rate <= {RK4_LIMIT} to stay stable. Use substeps >= "
            f"{needed} (or a smaller dt), or a heavier vessel / smaller unmodeled_scale."
        )
