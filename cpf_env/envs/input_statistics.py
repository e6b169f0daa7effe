"""Fixed input statistics for a learner: estimated once from the base policy, then frozen.

A residual learner sees observations whose dimensions differ by five orders
of magnitude (path errors of 1e-5 m under the reference controller, forces of
several N) and some that never change. ``InputStatistics`` scales each input
dimension as Stable-Baselines3's ``VecNormalize`` does at evaluation,
``clip((x - mean) / sqrt(var + epsilon), -clip, clip)`` in float32, with
statistics measured on a short rollout of the base policy alone (zero
residual). Frozen statistics keep an env deterministic and let a trained
policy be saved with the exact scaling it saw (``agents``' ``normalization.json``
has the same four fields and the same arithmetic).

No torch here: the TorchRL env and the loaders of saved policies share it.

Example:
    >>> import numpy as np
    >>> stats = InputStatistics(np.zeros(2), np.array([4.0, 0.0]), epsilon=1e-8, clip=10.0)
    >>> stats.apply(np.array([[2.0, 3.0]], dtype=np.float32)).tolist()
    [[1.0, 10.0]]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

__all__ = ["NORMALIZATION_FLEETS", "InputStatistics", "estimate_input_statistics"]

#: Fleets the statistics pool (seeds 0 .. 15), whatever the number of fleets trained.
NORMALIZATION_FLEETS = 16


@dataclass(frozen=True)
class InputStatistics:
    """Per-dimension input scaling (the arithmetic of ``VecNormalize`` at evaluation).

    Attributes:
        mean: (k,) float64 mean of each input dimension.
        var: (k,) float64 variance (0 for a constant dimension: it maps to 0 or +-clip).
        epsilon: Added to the variance before the square root.
        clip: Scaled inputs are clipped to [-clip, clip].
    """

    mean: NDArray[np.float64]
    var: NDArray[np.float64]
    epsilon: float = 1e-8
    clip: float = 10.0

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=np.float64)
        var = np.asarray(self.var, dtype=np.float64)
        if mean.ndim != 1 or var.shape != mean.shape:
            raise ValueError(
                f"mean and var must be 1-D of one length, got {mean.shape} and {var.shape}."
            )
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)):
            raise ValueError("input statistics must be finite, with var >= 0.")
        if not (self.epsilon > 0 and self.clip > 0):
            raise ValueError(f"epsilon and clip must be > 0, got {self.epsilon}, {self.clip}.")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "var", var)

    @property
    def size(self) -> int:
        """k, the input length."""
        return int(self.mean.shape[0])

    def apply(self, rows: NDArray[np.float32]) -> NDArray[np.float32]:
        """(..., k) float32 inputs -> scaled and clipped float32 inputs."""
        scaled = (rows - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(scaled, -self.clip, self.clip).astype(np.float32)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (floats round-trip exactly); ``from_json`` reads it back."""
        return {
            "mean": [float(x) for x in self.mean],
            "var": [float(x) for x in self.var],
            "epsilon": float(self.epsilon),
            "clip": float(self.clip),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> InputStatistics:
        """Statistics from ``to_json``'s dict.

        Raises:
            ValueError: A missing field or values that are not statistics.
        """
        try:
            return cls(
                np.asarray(data["mean"], dtype=np.float64),
                np.asarray(data["var"], dtype=np.float64),
                float(data["epsilon"]),
                float(data["clip"]),
            )
        except (KeyError, TypeError) as error:
            raise ValueError(f"input statistics lack or mangle a field: {error}") from None


def estimate_input_statistics(
    scenario: Scenario,
    base_policy: FleetPolicy | None,
    config: ResidualConfig,
    steps: int = 200,
    fleets: int = NORMALIZATION_FLEETS,
    seed: int = 0,
) -> InputStatistics:
    """Mean and variance of the learner's inputs under the base policy alone.

    Runs ``steps`` control periods of ``fleets`` fleets on a simulator of its
    own with a zero residual, fleet k seeded ``seed + k``, and pools the inputs
    of all fleets, vessels and steps (one shared scaling for all vessels, as
    one shared network sees them). Fleets that end are reset and go on. The
    result does not depend on how many fleets the caller trains with, so a
    training env and an evaluation env of other sizes scale alike.

    Args:
        scenario: The task.
        base_policy: The base policy (its states are reset afterwards), or None.
        config: The residual composition (extras decide the inputs).
        steps: Control periods to pool (>= 1).
        fleets: Fleets simulated (>= 1).
        seed: Seed of fleet 0.

    Returns:
        The statistics of the float32 inputs, length ``config.input_size(layout)``.
        The neighbours' learned messages (``config.message_inputs``), which the base
        alone never sends, get mean 0 and variance 1: they pass as sent, in [-1, 1]
        (measured, they would be constant zeros, and the first message a learner
        sent would be scaled to the clip).
    """
    for name, value in (("steps", steps), ("fleets", fleets)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}.")
    sim = FleetSim(scenario, num_fleets=int(fleets))
    controller = ResidualController(scenario, base_policy, int(fleets), config)
    obs = sim.reset(seeds=[seed + k for k in range(sim.num_fleets)])
    controller.reset()
    inputs = controller.observe(obs)
    zero = np.zeros((sim.num_fleets, controller.n, controller.action_size))
    seen = []
    for _ in range(int(steps)):
        seen.append(inputs.astype(np.float32).reshape(-1, controller.input_size))
        obs = sim.step(controller.compose(zero))
        inputs = controller.observe(obs)
        ended = sim.arrays.terminated | sim.truncated
        if ended.any():
            ending = np.flatnonzero(ended)
            obs = sim.reset(fleets=ending)
            controller.reset_fleets(ended)
            inputs[ending] = controller.observe(obs[ending], fleets=ending)
    pooled = np.concatenate(seen).astype(np.float64)
    controller.reset()
    mean, var = pooled.mean(axis=0), pooled.var(axis=0)
    learned = config.message_inputs(controller.layout)
    mean[learned], var[learned] = 0.0, 1.0
    return InputStatistics(mean, var)
