"""Separation between vessels: a keep-out distance in the cost and a collision that ends the task.

Vessels whose paths cross must not meet. The constraint is on the true
positions p_i = (x_i, y_i) of every pair of vessels of a fleet, whatever the
communication graph (two hulls collide whether or not they talk):

    d_ij  = ||p_i - p_j||                                         (m)
    c_i   = sum_{j != i} (max(0, d_safe - d_ij) / (d_safe - d_hard))^2
    r_i  += -dt * weight * c_i                     (the reward's ``separation`` term)

so a vessel pays nothing outside the safe distance, and ``weight`` per
second for each neighbour it has brought to the hard distance. Below the hard
distance (d_ij < d_hard for any pair) the fleet has collided: it terminates
and every vessel is charged the failure term for the rest of the episode, as
for a vessel that leaves its path (``cpf_env.sim.reward``).

Scale for Cybership II, a 1.255 m model ship of beam 0.29 m: two hulls
passing 0.5 m apart centre to centre are in contact if they lie side by side
at the wrong angle, so ``hard_distance`` 0.5 m is a collision; a safe
distance of 1.5 m (a little over a hull length) leaves room to manoeuvre at
0.1-0.2 m/s. The default weight 10 makes a pass at the hard distance cost per
second what a path error of about 1 m costs under the default log form.

    >>> Separation().margin
    1.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Separation"]


@dataclass(frozen=True)
class Separation:
    """The keep-out distance, the collision distance and the weight of the separation cost.

    Attributes:
        safe_distance: d_safe (m): closer than this, the separation term charges.
        hard_distance: d_hard (m), 0 <= d_hard < d_safe: closer than this, the fleet has
            collided and terminates.
        weight: The term's weight (cost per second for one neighbour at the hard distance).
    """

    safe_distance: float = 1.5
    hard_distance: float = 0.5
    weight: float = 10.0

    def __post_init__(self) -> None:
        for name in ("safe_distance", "hard_distance", "weight"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"Separation.{name} must be a number, got {value!r}.")
            object.__setattr__(self, name, float(value))
        if not (
            math.isfinite(self.safe_distance) and 0.0 <= self.hard_distance < self.safe_distance
        ):
            raise ValueError(
                "Separation needs 0 <= hard_distance < safe_distance (m), both finite, got "
                f"hard_distance={self.hard_distance}, safe_distance={self.safe_distance}: the "
                "keep-out zone must start outside the collision distance."
            )
        if not (math.isfinite(self.weight) and self.weight >= 0.0):
            raise ValueError(f"Separation.weight must be finite and >= 0, got {self.weight}.")

    @property
    def margin(self) -> float:
        """d_safe - d_hard (m), the depth of the keep-out zone the cost is scaled by."""
        return self.safe_distance - self.hard_distance
