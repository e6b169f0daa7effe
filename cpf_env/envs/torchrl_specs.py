"""The TorchRL specs of ``TorchRLFleetEnv``: one group of vessels, B fleets, raw or residual.

Kept apart from the env so that each module holds one thing: this one says
what the tensors look like (shapes, dtypes, bounds), ``torchrl_env`` how
they are computed. Shapes are batched, [B, ...]; ``EnvBase`` derives the
unbatched ones BenchMARL reads.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from numpy.typing import NDArray
from torchrl.data import Bounded, Categorical, Composite, Unbounded

from cpf_env.scenarios import Scenario
from cpf_env.sim import arrays

__all__ = ["DONE_KEYS", "ERROR_KEYS", "GROUP", "STATE_PER_VESSEL", "FleetSpecs", "action_bounds"]

#: The one agent group (``PettingZooWrapper``'s default group of ``vessel_i`` agents).
GROUP = "vessel"
#: The per-vessel errors of ``info_level="minimal"``, as (info key, index into ``errors``).
ERROR_KEYS = arrays.ERROR_KEYS
#: The flags, at the root [B, 1] and per vessel [B, n, 1].
DONE_KEYS = ("done", "terminated", "truncated")
#: Values of the global state per vessel: eta (3), nu (3), theta, tau_applied (3).
STATE_PER_VESSEL = 10


def action_bounds(scenario: Scenario) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Per-vessel action bounds, those of the ParallelEnv's ``action_space``.

    Args:
        scenario: The task.

    Returns:
        (low, high), each float32 of shape (n, 4 + m): the force limits (N, N, N m),
        +-theta_dot_max (1/s) and +-message_max. Forces beyond the limits are legal
        (the plant saturates them); rate and message are clipped.
    """
    tau_min, tau_max = scenario.tau_limits
    n, m = scenario.n, scenario.message_size
    rate = np.full((n, 1), scenario.theta_dot_max)
    message = np.full((n, m), scenario.message_max)
    low = np.concatenate([tau_min, -rate, -message], axis=1).astype(np.float32)
    high = np.concatenate([tau_max, rate, message], axis=1).astype(np.float32)
    return low, high


class FleetSpecs(NamedTuple):
    """The four spec composites of the env, batched [B]."""

    observation: Composite
    action: Composite
    reward: Composite
    done: Composite

    @classmethod
    def build(
        cls,
        scenario: Scenario,
        num_fleets: int,
        input_size: int,
        residual_actions: int | None,
        info_level: str,
        state: bool,
        device: torch.device,
    ) -> FleetSpecs:
        """The specs of B fleets of ``scenario``.

        Args:
            scenario: The task (n, limits).
            num_fleets: B.
            input_size: d, each vessel's observation length.
            residual_actions: k for residual actions in [-1, 1]; None for raw commands
                bounded by ``action_bounds``.
            info_level: ``"none"`` or ``"minimal"`` (adds the four errors per vessel).
            state: Add the global ``"state"`` [B, 10 n].
            device: Where the specs live.
        """
        B, n = num_fleets, scenario.n
        group = torch.Size([B, n])

        def composite(entries: dict[str, Any], shape: Any) -> Composite:
            return Composite(entries, shape=shape, device=device)

        observation: dict[str, Any] = {
            "observation": Unbounded((B, n, input_size), dtype=torch.float32, device=device)
        }
        if info_level == "minimal":
            infos = {
                key: Unbounded(group, dtype=torch.float32, device=device) for key, _ in ERROR_KEYS
            }
            observation["info"] = composite(infos, group)
        root: dict[str, Any] = {GROUP: composite(observation, group)}
        if state:
            size = STATE_PER_VESSEL * n
            root["state"] = Unbounded((B, size), dtype=torch.float32, device=device)
        if residual_actions is None:
            low, high = (torch.from_numpy(b).expand(B, n, -1) for b in action_bounds(scenario))
        else:
            low = -torch.ones((B, n, residual_actions))
            high = torch.ones((B, n, residual_actions))
        action = Bounded(low, high, dtype=torch.float32, device=device)
        reward = Unbounded((B, n, 1), dtype=torch.float32, device=device)
        fleet_flags = {
            key: Categorical(2, (B, 1), dtype=torch.bool, device=device) for key in DONE_KEYS
        }
        vessel_flags = {
            key: Categorical(2, (B, n, 1), dtype=torch.bool, device=device) for key in DONE_KEYS
        }
        return cls(
            observation=composite(root, [B]),
            action=composite({GROUP: composite({"action": action}, group)}, [B]),
            reward=composite({GROUP: composite({"reward": reward}, group)}, [B]),
            done=composite({**fleet_flags, GROUP: composite(vessel_flags, group)}, [B]),
        )
