"""``TorchRLFleetEnv``: a native batched TorchRL environment over one ``FleetSim``.

B fleets of n vessels are one TorchRL env with ``batch_size = [B]`` and one
group of agents, ``"vessel"`` (the group ``PettingZooWrapper`` makes of the
agents ``vessel_0 .. vessel_{n-1}``, so a policy written for one route runs on
the other). The simulator steps every fleet with one compiled kernel call;
arrays go to tensors in bulk, with no Python loop over fleets or vessels.

=============================  ===========  ===================================================
key                            shape        meaning
=============================  ===========  ===================================================
("vessel", "observation")      [B, n, d]    float32 local observation (``ObsLayout``), bounds
                                            of ``observation_box``; d = 18 + K (3 + m)
("vessel", "action")           [B, n, 4+m]  float32 [tau_u (N), tau_v (N), tau_r (N m),
                                            theta_dot (1/s), message (m)], bounds of the
                                            ParallelEnv's ``action_space``
("vessel", "reward")           [B, n, 1]    float32 reward of each vessel
("vessel", "done"/...)         [B, n, 1]    bool done, terminated, truncated of each vessel
"done"/"terminated"/...        [B, 1]       bool, the fleet's flags (equal to its vessels')
("vessel", "info", <error>)    [B, n]       float32 path_error, heading_error, sync_error,
                                            speed_error; only with ``info_level="minimal"``
=============================  ===========  ===================================================

Episodes end per fleet: terminated when a vessel leaves its path, truncated
after ``max_steps``; every vessel of a fleet shares the fleet's flags. As in
every TorchRL env, nothing resets by itself: ``rollout``, collectors and
``step_and_maybe_reset`` reset the done fleets through the ``"_reset"`` mask
(root [B, 1] or group [B, n, 1]; a fleet resets if any of its entries is set).

Seeding follows the other batched forms of this package (``FleetVecEnv``):
``set_seed(s)`` makes fleet k draw its episodes from ``default_rng(s + k)``,
so fleet k reproduces ``FleetSim.reset(seeds=[..., s + k, ...])`` and
``cpf_env.parallel_env(...).reset(seed=s + k)`` bit for bit; later resets
continue each fleet's generator. Importing ``cpf_env`` does not import this
module (it needs the ``torchrl`` extra).

Example:
    >>> env = TorchRLFleetEnv("wang2014", num_fleets=4, max_steps=50)
    >>> _ = env.set_seed(0)
    >>> data = env.rollout(3)
    >>> data["next", "vessel", "observation"].shape
    torch.Size([4, 3, 5, 26])
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from cpf_env.envs.parallel import make_scenario
from cpf_env.scenarios import Scenario
from cpf_env.sim import arrays
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import observation_box

__all__ = ["ERROR_KEYS", "GROUP", "TorchRLFleetEnv", "action_bounds"]

#: The one agent group (``PettingZooWrapper``'s default group of ``vessel_i`` agents).
GROUP = "vessel"

#: The per-vessel errors of ``info_level="minimal"``, as (info key, index into ``errors``).
ERROR_KEYS = arrays.ERROR_KEYS

_INFO_LEVELS = ("none", "minimal")
_DONE_KEYS = ("done", "terminated", "truncated")


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


class TorchRLFleetEnv(EnvBase):
    """B fleets x n vessels as one batched TorchRL env with one group of vessels.

    Args:
        scenario: A name of ``cpf_env.scenarios.list_scenarios()`` or a ``Scenario``.
        num_fleets: B, the number of fleets simulated together (the batch size).
        info_level: ``"none"`` (default, the hot path) or ``"minimal"``: also output
            the four errors of each vessel under ``("vessel", "info")``.
        device: Must be the CPU (accepted for TorchRL's signature; see the error).
        **overrides: ``Scenario`` field overrides, as in ``cpf_env.parallel_env``.

    Attributes:
        scenario: The task.
        sim: The ``FleetSim`` (read its ``arrays`` for anything else, e.g. poses).
        num_fleets: B.
        n: Vessels per fleet.
        info_level: The detail level.

    Raises:
        ValueError: A bad ``num_fleets``, ``info_level`` or ``device`` (or a bad override).
    """

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        num_fleets: int = 64,
        info_level: str = "none",
        device: str | torch.device = "cpu",
        **overrides: Any,
    ) -> None:
        if torch.device(device).type != "cpu":
            raise ValueError(
                f"TorchRLFleetEnv runs on the CPU (the simulator is compiled CPU code), got "
                f"device={device!r}; move its outputs with a transform, e.g. "
                f"env.append_transform(DeviceCastTransform({str(device)!r})), or td.to(...)."
            )
        if isinstance(num_fleets, bool) or int(num_fleets) != num_fleets or num_fleets < 1:
            raise ValueError(f"num_fleets must be an integer >= 1, got {num_fleets!r}.")
        if info_level not in _INFO_LEVELS:
            raise ValueError(
                f"info_level must be one of {_INFO_LEVELS}, got {info_level!r}. The full "
                "diagnostics are in env.sim.arrays (eta, nu, tau_applied, reward_terms, ...)."
            )
        self.scenario = make_scenario(scenario, **overrides)
        self.num_fleets = B = int(num_fleets)
        self.n = self.scenario.n
        self.info_level = info_level
        self.sim = FleetSim(self.scenario, num_fleets=B)
        super().__init__(device="cpu", batch_size=torch.Size([B]))
        self._make_specs()

    def _make_specs(self) -> None:
        """Observation, action, reward and done specs from the scenario."""
        B, n, sim = self.num_fleets, self.n, self.sim
        group = torch.Size([B, n])
        box = observation_box(sim.obs_dim)
        obs_low = torch.from_numpy(box.low).expand(B, n, -1)
        obs_high = torch.from_numpy(box.high).expand(B, n, -1)
        observation: dict[str, Any] = {
            "observation": Bounded(obs_low, obs_high, dtype=torch.float32, device=self.device)
        }
        if self.info_level == "minimal":
            infos = {key: Unbounded(group, dtype=torch.float32) for key, _ in ERROR_KEYS}
            observation["info"] = Composite(infos, shape=group)
        self.observation_spec = Composite({GROUP: Composite(observation, shape=group)}, shape=[B])
        low, high = (
            torch.from_numpy(bound).expand(B, n, -1) for bound in action_bounds(self.scenario)
        )
        action = Bounded(low, high, dtype=torch.float32, device=self.device)
        self.full_action_spec = Composite(
            {GROUP: Composite({"action": action}, shape=group)}, shape=[B]
        )
        reward = Unbounded((B, n, 1), dtype=torch.float32)
        self.full_reward_spec = Composite(
            {GROUP: Composite({"reward": reward}, shape=group)}, shape=[B]
        )
        fleet_flags = {key: Categorical(2, (B, 1), dtype=torch.bool) for key in _DONE_KEYS}
        vessel_flags = {key: Categorical(2, (B, n, 1), dtype=torch.bool) for key in _DONE_KEYS}
        self.full_done_spec = Composite(
            {**fleet_flags, GROUP: Composite(vessel_flags, shape=group)}, shape=[B]
        )

    # --- EnvBase interface ----------------------------------------------------------------

    def _set_seed(self, seed: int | None) -> None:
        """Fleet k draws its next episodes from ``default_rng(seed + k)``; None: fresh entropy.

        Raises:
            ValueError: ``seed`` is not a non-negative integer (nothing is reseeded).
        """
        if seed is None:
            seed = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        elif isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0 or None, got {seed!r}.")
        for k in range(self.num_fleets):
            self.sim.rngs[k] = np.random.default_rng(int(seed) + k)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        """Reset the fleets selected by the ``"_reset"`` masks (all fleets without one).

        Args:
            tensordict: May hold ``"_reset"`` [B, 1] and/or ``("vessel", "_reset")``
                [B, n, 1]; a fleet resets if any of its entries is True.
            **kwargs: Ignored (TorchRL passes its own reset options).

        Returns:
            Observations and flags of every fleet (TorchRL keeps the entries of the
            fleets that were not reset).
        """
        fleets = self._fleets_to_reset(tensordict)
        if fleets is None:
            obs = self.sim.reset()
        elif fleets.size:
            obs = self.sim.reset(fleets=fleets)
        else:
            obs = self.sim.arrays.obs
        return self._output(obs, step=False)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Advance every fleet one control period ``dt``.

        Raises:
            ValueError: The action is missing, has the wrong shape, is complex or is not
                finite (naming fleet, vessel, component); nothing is changed.
            RuntimeError: Stepping before ``reset()``, or the plant diverged (the message
                says where and what to change).
        """
        action = tensordict.get((GROUP, "action"), None)
        expected = (self.num_fleets, self.n, self.sim.act_dim)
        if action is None:
            raise ValueError(
                f"the tensordict has no ({GROUP!r}, 'action') entry; set one of shape "
                f"[B, n, 4 + m] = {list(expected)}."
            )
        if tuple(action.shape) != expected:
            raise ValueError(
                f"({GROUP!r}, 'action') must have shape [B, n, 4 + m] = {list(expected)}, "
                f"got {list(action.shape)}."
            )
        obs = self.sim.step(action.detach().cpu().numpy())
        return self._output(obs, step=True)

    # --- helpers --------------------------------------------------------------------------

    def _fleets_to_reset(self, tensordict: TensorDictBase | None) -> NDArray[np.int64] | None:
        """Indices of the fleets the reset masks select, or None for all (no mask given)."""
        if tensordict is None:
            return None
        masks = [tensordict.get(key, None) for key in ("_reset", (GROUP, "_reset"))]
        for key, mask in zip(("'_reset'", f"({GROUP!r}, '_reset')"), masks, strict=True):
            if mask is None:
                continue
            if mask.dtype != torch.bool:
                raise ValueError(
                    f"the {key} mask must be a bool tensor, got {mask.dtype}; nothing was reset."
                )
            if mask.numel() % self.num_fleets or mask.shape[0] != self.num_fleets:
                raise ValueError(
                    f"the {key} mask must have B = {self.num_fleets} rows, got "
                    f"{list(mask.shape)}; nothing was reset."
                )
        given = [mask.reshape(self.num_fleets, -1).any(-1) for mask in masks if mask is not None]
        if not given:
            return None
        selected = given[0] if len(given) == 1 else given[0] | given[1]
        return np.flatnonzero(selected.cpu().numpy())

    def _output(self, obs: NDArray[np.float32], step: bool) -> TensorDict:
        """Observations, flags (and rewards, infos) of every fleet as a tensordict [B].

        Args:
            obs: The simulator's observations (B, n, d) float32 (copied here).
            step: After a step: include rewards and the simulator's flags. After a
                reset the flags are False, as TorchRL requires: a fleet whose drawn
                start is already off its path reports ``terminated`` at its first
                step, as the ParallelEnv does.
        """
        B, n, a = self.num_fleets, self.n, self.sim.arrays
        if step:
            terminated = torch.from_numpy(a.terminated.copy()).unsqueeze(-1)
            truncated = torch.from_numpy(self.sim.truncated).unsqueeze(-1)
        else:
            terminated = truncated = torch.zeros((B, 1), dtype=torch.bool)
        flags = {"done": terminated | truncated, "terminated": terminated, "truncated": truncated}
        group: dict[str, Any] = {
            key: value.unsqueeze(1).expand(B, n, 1).clone() for key, value in flags.items()
        }
        group["observation"] = torch.from_numpy(obs.copy())
        if step:
            group["reward"] = torch.from_numpy(a.reward.astype(np.float32)).unsqueeze(-1)
        if self.info_level == "minimal":
            errors = torch.from_numpy(a.errors.astype(np.float32))
            infos = {key: errors[..., index] for key, index in ERROR_KEYS}
            group["info"] = TensorDict(infos, batch_size=(B, n))
        return TensorDict(
            {**flags, GROUP: TensorDict(group, batch_size=(B, n))}, batch_size=self.batch_size
        )
