"""The TorchRL specs of ``TorchRLFleetEnv``: one group of vessels, B fleets, raw or residual.

Kept apart from the env so that each module holds one thing: this one says
what the tensors look like (shapes, dtypes, bounds), ``torchrl_env`` how
they are computed. Shapes are batched, [B, ...]; ``EnvBase`` derives the
unbatched ones BenchMARL reads.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import torch
from torchrl.data import Bounded, Categorical, Composite, Unbounded

from cpf_env.envs.core import EpisodeCore

__all__ = ["DONE_KEYS", "GROUP", "STATE_PER_VESSEL", "FleetSpecs"]

#: The one agent group (``PettingZooWrapper``'s default group of ``vessel_i`` agents).
GROUP = "vessel"
#: The flags, at the root [B, 1] and per vessel [B, n, 1].
DONE_KEYS = ("done", "terminated", "truncated")
#: Values of the global state per vessel: eta (3), nu (3), theta, tau_applied (3).
STATE_PER_VESSEL = 10


class FleetSpecs(NamedTuple):
    """The four spec composites of the env, batched [B]."""

    observation: Composite
    action: Composite
    reward: Composite
    done: Composite

    @classmethod
    def build(
        cls,
        core: EpisodeCore,
        info_level: str,
        state: bool,
        device: torch.device,
        extra_state_size: int = 0,
    ) -> FleetSpecs:
        """The specs of the core's B fleets.

        Args:
            core: The episode core (n, input size, action form and bounds).
            info_level: ``"none"``, ``"minimal"`` or ``"full"``: the entries of
                ``core.info_arrays(info_level)`` per vessel under ``"info"``.
            state: Add the global ``"state"`` [B, 10 n].
            device: Where the specs live.
            extra_state_size: k, the features per vessel appended to the state:
                [B, (10 + k) n].
        """
        B, n, input_size = core.num_fleets, core.n, core.input_size
        group = torch.Size([B, n])

        def composite(entries: dict[str, Any], shape: Any) -> Composite:
            return Composite(entries, shape=shape, device=device)

        observation: dict[str, Any] = {
            "observation": Unbounded((B, n, input_size), dtype=torch.float32, device=device)
        }
        if info_level != "none":
            infos = {
                key: Unbounded(
                    value.shape,
                    dtype=torch.bool if value.dtype == bool else torch.float32,
                    device=device,
                )
                for key, value in core.info_arrays(info_level).items()
            }
            observation["info"] = composite(infos, group)
        root: dict[str, Any] = {GROUP: composite(observation, group)}
        if state:
            size = (STATE_PER_VESSEL + extra_state_size) * n
            root["state"] = Unbounded((B, size), dtype=torch.float32, device=device)
        low, high = (torch.from_numpy(b).expand(B, n, -1) for b in core.action_bounds())
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
