"""Controller gains: frozen dataclasses with the paper's values as defaults.

Gains are shared by every vessel of the fleet (the paper gives every vessel the
same values). Diagonal gain matrices are given by their diagonal; a scalar is
broadcast to the three axes (surge, sway, yaw). Defaults are the paper's
section 4 (docs/model.md, section 7); K5, K6 and the NN size l are not given there
and default to 1, 1 and 20.

The weight law [30] has two readings (the paper's displayed equation is lost
in our copy; docs/model.md section 7), chosen by ``NNDSCGains.leakage``:

==================  ==========================================  ==============================
``leakage``         law                                         What at rest, leakage rate
==================  ==========================================  ==============================
``"gamma_scaled"``  What' = -Gamma_W (sigma e2^T + k_W What)    -sigma e2^T / k_W, 100 1/s
``"plain"``         What' = -Gamma_W sigma e2^T - k_W What      -Gamma_W sigma e2^T / k_W, 1 1/s
==================  ==========================================  ==============================

``"gamma_scaled"`` (the default) is stable at the RL control step of 0.05 s
but learns only s / (K2 + s) of the lumped uncertainty, s = ||sigma||^2 / k_W;
``"plain"`` integrates (s = Gamma_W ||sigma||^2 / k_W ~ 1010) and tracks it, but
with K2 it forms a lightly damped PI loop (yaw: sqrt(s / M33) ~ 19 rad/s) that
sampling destabilizes above a control step of about 0.01 s: use it with the
0.01 s scenarios ``*_fine`` (``docs/reproduction.md``).

======================  ===========  =========================================
class                   used by      fields
======================  ===========  =========================================
``CooperativeGains``    all          k3, k4 (synchronization [34]), k5, k6 (estimator [35])
``BacksteppingGains``   backstepping + K1 [15], K2
``NNDSCGains``          nn_dsc, ...  + rho [18], K_pi [21], k_W, Gamma_W, leakage [30],
                                     hidden, nn_seed
======================  ===========  =========================================

Example:
    >>> NNDSCGains.from_options({"K2": (30, 30, 5), "hidden": 40}).K2
    (30.0, 30.0, 5.0)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

__all__ = ["LEAKAGE_LAWS", "BacksteppingGains", "CooperativeGains", "NNDSCGains", "scalar_gain"]

#: Readings of the weight law [30] (see the module docstring).
LEAKAGE_LAWS = ("gamma_scaled", "plain")

Diagonal = tuple[float, float, float]
_G = TypeVar("_G", bound="CooperativeGains")


def _diagonal(name: str, value: object) -> Diagonal:
    """Broadcast a scalar or 3-sequence to a positive diagonal, or raise ValueError."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        array = np.full(3, np.nan)
    if array.shape not in ((), (3,)) or not np.all(np.isfinite(array) & (array > 0.0)):
        raise ValueError(
            f"gain {name} must be a positive number or 3 positive numbers (surge, sway, yaw), "
            f"got {value!r}."
        )
    diagonal = np.broadcast_to(array, (3,))
    return (float(diagonal[0]), float(diagonal[1]), float(diagonal[2]))


def scalar_gain(name: str, value: object, allow_zero: bool = True) -> float:
    """A scalar gain checked (>= 0, or > 0 without ``allow_zero``), or ValueError naming it."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number) or number < 0.0 or (number == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"gain {name} must be a finite number {bound}, got {value!r}.")
    return number


def _integer(name: str, value: object, minimum: int) -> int:
    """Check an integer option, or raise ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"option {name} must be an integer >= {minimum}, got {value!r}.")
    return int(value)


@dataclass(frozen=True)
class CooperativeGains:
    """Gains of the cooperative layer (docs/model.md, section 8).

    Attributes:
        k3: Synchronization gain on s_i - mu_i in omega_is (1/s), eq. [34].
        k4: Leakage rate of the auxiliary state gamma_i (1/s), eq. [34].
        k5: Consensus gain of the speed estimator (1/s), eq. [35].
        k6: Leader-tracking gain of the speed estimator (1/s), eq. [35].
    """

    k3: float = 1.0
    k4: float = 1.0
    k5: float = 1.0
    k6: float = 1.0

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.type == "Diagonal":
                object.__setattr__(self, field.name, _diagonal(field.name, value))
            elif field.type == "float":
                object.__setattr__(self, field.name, scalar_gain(field.name, value))

    @classmethod
    def option_names(cls) -> list[str]:
        """Names accepted by ``from_options``, in declaration order."""
        return [field.name for field in dataclasses.fields(cls)]

    @classmethod
    def from_options(cls: type[_G], options: Mapping[str, Any], owner: str = "") -> _G:
        """Build from keyword options; unknown names raise ValueError listing the valid ones.

        Args:
            options: Field name -> value.
            owner: Who takes these options, for the error message (e.g. a policy name).
        """
        unknown = sorted(set(options) - set(cls.option_names()))
        if unknown:
            raise ValueError(
                f"unknown option(s) {unknown} for {owner or cls.__name__}; valid options are "
                f"{cls.option_names()}."
            )
        return cls(**options)


@dataclass(frozen=True)
class BacksteppingGains(CooperativeGains):
    """Gains of the backstepping design (the paper's Remark 1).

    Attributes:
        K1: Diagonal of K_i1, kinematic gain of the virtual control (1/s), eq. [15].
        K2: Diagonal of K_i2, velocity-error feedback (N s/m, N s/m, N m s/rad), eq. [29].
    """

    K1: Diagonal = (1.0, 1.0, 1.0)
    K2: Diagonal = (60.0, 70.0, 8.0)


@dataclass(frozen=True)
class NNDSCGains(BacksteppingGains):
    """Gains of the NN-based adaptive DSC (docs/model.md, section 7).

    Attributes:
        rho: Time constant of the DSC filter (s), eq. [18].
        K_pi: Diagonal of K_pi, rate of the saturation auxiliary system (1/s), eq. [21].
        k_W: sigma-modification leakage of the NN weights, eq. [30].
        Gamma_W: Adaptation gain of the NN weights, eq. [30].
        leakage: Reading of [30]: ``"gamma_scaled"`` (Gamma_W multiplies the
            leakage k_W What too) or ``"plain"`` (it does not); see the module docstring.
        hidden: Number l of tanh hidden nodes of the NN, eq. [28].
        nn_seed: Seed of the NN's fixed N(0, 1) input weights.
    """

    rho: float = 0.05
    K_pi: Diagonal = (200.0, 200.0, 200.0)
    k_W: float = 1.0
    Gamma_W: float = 100.0
    leakage: str = "gamma_scaled"
    hidden: int = 20
    nn_seed: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        scalar_gain("rho", self.rho, allow_zero=False)
        if self.leakage not in LEAKAGE_LAWS:
            raise ValueError(
                f"option leakage must be one of {list(LEAKAGE_LAWS)}, got {self.leakage!r}."
            )
        object.__setattr__(self, "hidden", _integer("hidden", self.hidden, minimum=1))
        object.__setattr__(self, "nn_seed", _integer("nn_seed", self.nn_seed, minimum=0))

    def leakage_rate(self) -> float:
        """Decay rate of What under [30] with sigma e2^T = 0 (1/s)."""
        return self.Gamma_W * self.k_W if self.leakage == "gamma_scaled" else self.k_W

    def static_gain(self) -> float:
        """What / (-sigma e2^T) at equilibrium of [30] (inf without leakage, k_W = 0)."""
        if self.k_W == 0.0:
            return math.inf
        return 1.0 / self.k_W if self.leakage == "gamma_scaled" else self.Gamma_W / self.k_W

    def input_weights(self) -> NDArray[np.float64]:
        """Fixed NN input weights v_l ~ N(0, 1) drawn from ``nn_seed``, shape (hidden, 7)."""
        return np.random.default_rng(self.nn_seed).standard_normal((self.hidden, 7))
