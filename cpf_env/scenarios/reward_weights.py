"""The reward's configuration: which terms, in which form, with which weights.

A scenario carries a ``RewardWeights``; the simulator's compiled step
(``cpf_env.sim.reward``, whose docstring defines every term and both forms)
reads it in the encoded form of ``RewardWeights.encode()``.

    >>> RewardWeights().encode().shape
    (11,)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ENCODED_FAILURE",
    "ENCODED_FORM",
    "ENCODED_SCALES",
    "REWARD_FORMS",
    "REWARD_TERMS",
    "RewardWeights",
]

#: Names of the reward terms, in the order of ``FleetSim.arrays.reward_terms``.
REWARD_TERMS = ("position", "heading", "sync", "speed", "effort", "failure", "separation")
#: Accepted values of ``RewardWeights.form``.
REWARD_FORMS = ("log", "quadratic")

#: Layout of ``RewardWeights.encode()``: 5 weights, then the form flag (index
#: ``ENCODED_FORM``), the 4 scales (from ``ENCODED_SCALES``) and the failure weight.
ENCODED_FORM, ENCODED_SCALES, ENCODED_FAILURE = 5, 6, 10


@dataclass(frozen=True)
class RewardWeights:
    """Form, weights and tolerance scales of the reward terms.

    Attributes:
        position: Weight of the path-error term.
        heading: Weight of the heading-error term.
        sync: Weight of the synchronization term.
        speed: Weight of the path-speed term.
        effort: Weight of the normalized-force term ||tau / tau_max||^2.
        failure: Weight of the failure term (0 disables it).
        team: If True, every vessel gets the fleet-mean reward.
        form: ``"log"`` (cost log(1 + (x / scale)^2)) or ``"quadratic"``
            (cost x^2, scales unused): see the module docstring.
        position_scale: Path-error tolerance of the log form (m).
        heading_scale: Heading-error tolerance (rad).
        sync_scale: Synchronization-error tolerance (path-variable units, about m).
            Tight (1 mm) on purpose: theta is commanded directly, so holding it
            costs a controller nothing, and at 1 cm a residual agent let the final
            coordination error rise from 5e-5 to 2e-3 for path accuracy (measured).
        speed_scale: Path-speed tolerance (m/s).

    Example:
        >>> RewardWeights().form, RewardWeights(form="quadratic").position
        ('log', 1.0)
    """

    position: float = 1.0
    heading: float = 0.1
    sync: float = 1.0
    speed: float = 0.1
    effort: float = 0.01
    failure: float = 1.0
    team: bool = False
    form: str = "log"
    position_scale: float = 0.01
    heading_scale: float = 0.05
    sync_scale: float = 0.001
    speed_scale: float = 0.01

    def __post_init__(self) -> None:
        if self.form not in REWARD_FORMS:
            raise ValueError(
                f"RewardWeights.form must be one of {REWARD_FORMS}, got {self.form!r}."
            )
        for field in fields(self):
            if field.name in ("team", "form"):
                continue
            value = getattr(self, field.name)
            positive = field.name.endswith("_scale")
            if not (
                isinstance(value, int | float)
                and math.isfinite(value)
                and (value > 0.0 if positive else value >= 0.0)
            ):
                bound = "> 0" if positive else ">= 0"
                raise ValueError(
                    f"RewardWeights.{field.name} must be a finite number {bound}, got {value!r}."
                )

    def encode(self) -> NDArray[np.float64]:
        """The reward in kernel form, shape (11,).

        Weights (position, heading, sync, speed, effort), the form flag (1.0 for
        ``"log"``, 0.0 for ``"quadratic"``), the scales (position, heading,
        sync, speed) and the failure weight.
        """
        return np.array(
            [
                self.position,
                self.heading,
                self.sync,
                self.speed,
                self.effort,
                1.0 if self.form == "log" else 0.0,
                self.position_scale,
                self.heading_scale,
                self.sync_scale,
                self.speed_scale,
                self.failure,
            ]
        )
