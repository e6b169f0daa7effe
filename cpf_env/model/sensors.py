"""Navigation sensors: what a vessel measures of its own pose and velocity.

By default (``Sensors()``) a vessel's observation is computed from its true
pose and velocity at every control step, as in the paper. A real surface
vessel knows its pose from a positioning system (GNSS, or an acoustic or
optical system on a model basin) and a compass, each with noise, at its own
update rate, with lost fixes; and unless it carries a Doppler log, it does
not measure its velocity at all. ``Sensors`` models that, per vessel:

* a **fix** of the pose, ``x + n_x``, ``y + n_y`` (m) and ``psi + n_psi`` (rad),
  with independent zero-mean normal noise of standard deviations
  ``position_std`` (each axis) and ``heading_std``, taken every ``period``
  control steps (the fix rate is 1 / (``period`` dt), never above the control
  rate), starting with a fix at reset;
* each scheduled fix after the reset is lost with probability ``dropout``;
  the vessel keeps the last fix it has;
* the observation's path error and path tangents (``z1``, ``t1``, ``t2``) are
  those of the held fix against the vessel's current path variable, and its
  velocity entries (``nu``) read 0 when ``velocity`` is False (not measured).

The cost, the errors and ``info_level="full"`` stay on the true state. Draws
are counter-based (``cpf_env.model.counter_rng``), so fleet k sees the same
noise at any batch size. A fix that repeats is exactly the held one, so an
estimator tells a new fix from a held one by whether the pose it reconstructs
from the observation moved (``docs/model.md``, "Sensors").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Sensors"]


def _number(name: str, value: object, low: float, high: float = math.inf) -> float:
    """``value`` as a float in [low, high], or a ValueError that names ``name``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or not low <= value <= high
    ):
        bound = f"in [{low:g}, {high:g}]" if math.isfinite(high) else f">= {low:g}"
        raise ValueError(f"Sensors.{name} must be a finite number {bound}, got {value!r}.")
    return float(value)


@dataclass(frozen=True)
class Sensors:
    """Noise, rate and dropouts of a vessel's pose fixes; whether its velocity is measured.

    Attributes:
        position_std: Standard deviation of the position noise on each axis (m), >= 0.
        heading_std: Standard deviation of the heading noise (rad), >= 0.
        period: Control steps between fixes, an integer >= 1 (1: a fix every step;
            a sensor cannot be faster than the control loop that reads it).
        dropout: Probability that a scheduled fix is lost, in [0, 1).
        velocity: Whether the body velocity is measured (a Doppler log or an
            inertial system); False: the observation's ``nu`` reads 0.
    """

    position_std: float = 0.0
    heading_std: float = 0.0
    period: int = 1
    dropout: float = 0.0
    velocity: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_std", _number("position_std", self.position_std, 0.0))
        object.__setattr__(self, "heading_std", _number("heading_std", self.heading_std, 0.0))
        if isinstance(self.period, bool) or not isinstance(self.period, int) or self.period < 1:
            raise ValueError(
                f"Sensors.period must be an integer number of control steps >= 1, got "
                f"{self.period!r}: the fixes come at most once per control step (a faster "
                "sensor is read at the control rate); for a sensor at f Hz give "
                "period = round(1 / (f dt))."
            )
        object.__setattr__(self, "dropout", _number("dropout", self.dropout, 0.0))
        if self.dropout >= 1.0:
            raise ValueError(
                f"Sensors.dropout must be below 1 (every fix lost), got {self.dropout!r}."
            )
        if not isinstance(self.velocity, bool):
            raise ValueError(f"Sensors.velocity must be True or False, got {self.velocity!r}.")

    @property
    def fix_std(self) -> tuple[float, float, float]:
        """Standard deviations of a fix's x (m), y (m) and psi (rad) noise."""
        return (self.position_std, self.position_std, self.heading_std)

    @property
    def ideal(self) -> bool:
        """True if the observation is the true state at every step (the default)."""
        return (
            self.position_std == 0.0
            and self.heading_std == 0.0
            and self.period == 1
            and self.dropout == 0.0
            and self.velocity
        )
