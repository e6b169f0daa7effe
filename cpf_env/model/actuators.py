"""Thruster dynamics: the applied force follows the saturated command with a lag and a slew limit.

Real thrusters do not deliver a new force at once: a propeller spins up, an
azimuth unit turns. The model here is the common first-order one, per axis
(surge, sway, yaw) of each vessel, sampled at the control rate:

    target_k  = sat(tau_command_k)                              (the saturation, per axis)
    lagged_k  = a tau_applied_{k-1} + (1 - a) target_k,   a = exp(-dt / T)
    tau_applied_k = tau_applied_{k-1} + clip(lagged_k - tau_applied_{k-1}, -R dt, R dt)

and ``tau_applied_k`` is held over control period k, as the plant holds every
force (``docs/model.md``, "Time discretization"). T is the time constant (s)
and R the slew-rate limit (N/s, N/s, N m/s); the update is the exact step of
x' = (target - x) / T for a target held over the period, then rate-limited.
``tau_applied`` is therefore part of the simulator's state (``FleetArrays``),
starts at zero at every reset, and is what the observation reports as the
applied force, as without dynamics. Because both steps move the force towards
a target inside the limits, it never leaves them.

With T = 0 and no rate limit (``Thrusters()``, every scenario's default) the
applied force is the saturated command itself, bit for bit as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Thrusters"]


@dataclass(frozen=True)
class Thrusters:
    """First-order thruster lag and slew-rate limit, the same for every vessel.

    Attributes:
        time_constant: T, the lag's time constant (s), >= 0; 0 is an instant thruster.
        rate_limit: R, the largest change of the applied force per second on each axis
            (N/s, N/s, N m/s), each > 0; None is no limit.
    """

    time_constant: float = 0.0
    rate_limit: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        t = self.time_constant
        if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t) or t < 0:
            raise ValueError(
                f"Thrusters.time_constant must be a number of seconds >= 0 (0: instant), got "
                f"{t!r}; a negative lag has no physical meaning."
            )
        object.__setattr__(self, "time_constant", float(t))
        if self.rate_limit is not None:
            rates = tuple(self.rate_limit)
            if len(rates) != 3 or not all(
                isinstance(r, int | float) and math.isfinite(r) and r > 0 for r in rates
            ):
                raise ValueError(
                    "Thrusters.rate_limit must be three slew rates > 0 (N/s, N/s, N m/s) or "
                    f"None (no limit), got {self.rate_limit!r}."
                )
            object.__setattr__(self, "rate_limit", tuple(float(r) for r in rates))

    @property
    def instant(self) -> bool:
        """True if the applied force is the saturated command (no lag, no rate limit)."""
        return self.time_constant == 0.0 and self.rate_limit is None

    def decay(self, dt: float) -> float:
        """The share a = exp(-dt / T) of the last applied force kept per step (0 if T = 0)."""
        return 0.0 if self.time_constant == 0.0 else math.exp(-dt / self.time_constant)

    def slews(self, dt: float) -> tuple[float, float, float]:
        """R dt, the largest change per control step on each axis (inf without a limit)."""
        if self.rate_limit is None:
            return (math.inf, math.inf, math.inf)
        return (self.rate_limit[0] * dt, self.rate_limit[1] * dt, self.rate_limit[2] * dt)
