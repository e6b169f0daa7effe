"""``TorchRLFleetEnv``: a native batched multi-agent TorchRL environment over one ``FleetSim``.

B fleets of n vessels are one TorchRL env with ``batch_size = [B]`` and one
group of agents, ``"vessel"`` (``group_map``; the group ``PettingZooWrapper``
makes of the agents ``vessel_0 .. vessel_{n-1}``, so a policy written for one
route runs on the other). The simulator steps every fleet with one compiled
kernel call; arrays go to tensors in bulk, with no Python loop over fleets.

Two action forms:

- **raw** (no ``base_policy``, no ``residual``): the whole command, in the
  ParallelEnv's units and bounds;
- **residual** (``base_policy=`` a policy object and/or ``residual=`` a
  ``ResidualConfig``): the composition of ``agents.FleetVecEnv``
  (``cpf_env.envs.residual``): the base policy acts underneath, the action is
  its bounded correction in [-1, 1]^k, and the observation is the learner's
  input (local observation plus the configured local extras). A zero action
  reproduces the base policy bit for bit.

=============================  ===========  ===================================================
key                            shape        meaning
=============================  ===========  ===================================================
("vessel", "observation")      [B, n, d]    float32 local input of each vessel: observation
                                            (``ObsLayout``, 18 + K (3 + m)) plus the residual's
                                            extras; scaled by ``InputStatistics`` if normalized
("vessel", "action")           [B, n, a]    float32 raw: [tau_u (N), tau_v (N), tau_r (N m),
                                            theta_dot (1/s), message (m)], a = 4 + m;
                                            residual: a = k in [-1, 1]
("vessel", "reward")           [B, n, 1]    float32 reward of each vessel
("vessel", "done"/...)         [B, n, 1]    bool done, terminated, truncated of each vessel
"done"/"terminated"/...        [B, 1]       bool, the fleet's flags (equal to its vessels')
"state"                        [B, 10 n]    float32 global state (``state=True``): the
                                            ParallelEnv's ``state()`` of each fleet
("vessel", "info", <error>)    [B, n]       float32 path_error, heading_error, sync_error,
                                            speed_error; only with ``info_level="minimal"``
=============================  ===========  ===================================================

Episodes end per fleet: terminated when a vessel leaves its path, truncated
after ``max_steps``; every vessel of a fleet shares the fleet's flags. As in
every TorchRL env, nothing resets by itself: ``rollout``, collectors and
``step_and_maybe_reset`` reset the done fleets through the ``"_reset"`` mask
(root [B, 1] or group [B, n, 1]; a fleet resets if any of its entries is set).

Seeding follows the other batched forms of this package (``FleetVecEnv``):
``set_seed(s)`` (or ``seed=s``) makes fleet k draw its episodes from
``default_rng(s + k)``, so fleet k reproduces ``FleetSim.reset(seeds=[..., s + k,
...])`` and ``cpf_env.parallel_env(...).reset(seed=s + k)`` bit for bit; later
resets continue each fleet's generator. Importing ``cpf_env`` does not import
this module (it needs the ``torchrl`` extra), and this module imports no
policy: the base policy is an object (``agents.marl`` resolves names).

Example:
    >>> env = TorchRLFleetEnv("wang2014", num_fleets=4, max_steps=50, seed=0)
    >>> data = env.rollout(3)
    >>> data["next", "vessel", "observation"].shape
    torch.Size([4, 3, 5, 26])
    >>> env.group_map
    {'vessel': ['vessel_0', 'vessel_1', 'vessel_2', 'vessel_3', 'vessel_4']}
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import EnvBase

from cpf_env.envs.input_statistics import InputStatistics, estimate_input_statistics
from cpf_env.envs.parallel import make_scenario
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.envs.torchrl_specs import ERROR_KEYS, GROUP, FleetSpecs, action_bounds
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim

__all__ = ["ERROR_KEYS", "GROUP", "TorchRLFleetEnv", "action_bounds"]

_INFO_LEVELS = ("none", "minimal")


def _checked_device(device: str | torch.device) -> torch.device:
    """The device, if tensors can live there (else a ValueError saying what to do)."""
    try:
        resolved = torch.device(device)
        torch.empty(0, device=resolved)
    except (RuntimeError, AssertionError, TypeError) as error:
        raise ValueError(
            f"device={device!r} is not usable here ({error}); give 'cpu' or an available "
            "accelerator. The simulator runs on the CPU either way; only the outputs move."
        ) from None
    return resolved


class TorchRLFleetEnv(EnvBase):
    """B fleets x n vessels as one batched multi-agent TorchRL env, one group of vessels.

    Args:
        scenario: A name of ``cpf_env.scenarios.list_scenarios()`` or a ``Scenario``.
        num_fleets: B, the number of fleets simulated together (the batch size).
        info_level: ``"none"`` (default, the hot path) or ``"minimal"``: also output
            the four errors of each vessel under ``("vessel", "info")``.
        device: Where the outputs and specs live (the simulator stays on the CPU;
            actions are brought back to it).
        seed: If given, ``set_seed(seed)`` at construction (fleet k: seed + k).
        base_policy: A ``FleetPolicy`` object acting underneath (residual form), e.g.
            ``baselines.make_policy("nn_dsc", scenario)``; names are resolved by
            ``agents.marl.make_env``. It must offer ``reset_fleets``.
        residual: ``ResidualConfig`` of the residual form (default with a base policy:
            force residual, scale 0.2, no extras). Without a base policy it makes
            the learner command everything through the same composition.
        normalize: False (raw inputs), True (scale them with ``InputStatistics``
            estimated over ``normalization_steps`` of the base policy alone on a
            separate simulator of 16 fleets, seeds 0 .. 15; residual form only) or
            given statistics.
        normalization_steps: Control periods pooled by ``normalize=True``.
        state: Also output the global ``"state"`` [B, 10 n] for centralized critics.
        stagger: After each reset of all fleets, end fleet k's episode after
            ``max_steps - k * max_steps // B`` steps (truncated), as ``FleetVecEnv``
            does, so that fleets do not end in lockstep and a batch of steps sees
            every phase of an episode; a fleet reset alone runs ``max_steps``.
        **overrides: ``Scenario`` field overrides, as in ``cpf_env.parallel_env``.

    Attributes:
        scenario: The task.
        sim: The ``FleetSim`` (read its ``arrays`` for anything else, e.g. poses).
        num_fleets: B.
        n: Vessels per fleet.
        info_level: The detail level.
        group_map: ``{"vessel": ["vessel_0", ...]}``, as TorchRL's multi-agent envs.
        controller: The ``ResidualController`` (None in the raw form).
        input_statistics: The ``InputStatistics`` applied, or None.

    Raises:
        ValueError: A bad ``num_fleets``, ``info_level``, ``device``, ``normalize`` or seed
            (or a bad override or residual configuration).
        TypeError: ``base_policy`` is not a policy object.
    """

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        num_fleets: int = 64,
        info_level: str = "none",
        device: str | torch.device = "cpu",
        seed: int | None = None,
        base_policy: FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        normalize: bool | InputStatistics = False,
        normalization_steps: int = 200,
        state: bool = False,
        stagger: bool = False,
        **overrides: Any,
    ) -> None:
        resolved = _checked_device(device)
        if isinstance(num_fleets, bool) or int(num_fleets) != num_fleets or num_fleets < 1:
            raise ValueError(f"num_fleets must be an integer >= 1, got {num_fleets!r}.")
        if info_level not in _INFO_LEVELS:
            raise ValueError(
                f"info_level must be one of {_INFO_LEVELS}, got {info_level!r}. The full "
                "diagnostics are in env.sim.arrays (eta, nu, tau_applied, reward_terms, ...)."
            )
        if base_policy is not None and not isinstance(base_policy, FleetPolicy):
            raise TypeError(
                "base_policy must be a policy object (act_batch, reset, reset_fleets, "
                f"diagnostics), got {type(base_policy).__name__}; to give a name such as "
                "'nn_dsc', build the env with agents.marl.make_env."
            )
        self.scenario = make_scenario(scenario, **overrides)
        self.num_fleets = B = int(num_fleets)
        self.n = self.scenario.n
        self.info_level = info_level
        if not isinstance(stagger, bool | np.bool_):
            raise ValueError(f"stagger must be True or False, got {stagger!r}.")
        self.state, self.stagger = bool(state), bool(stagger)
        self.group_map = {GROUP: [f"vessel_{i}" for i in range(self.n)]}
        self.sim = FleetSim(self.scenario, num_fleets=B)
        self._horizon = np.full(B, self.scenario.max_steps, dtype=np.int64)
        residual_form = base_policy is not None or residual is not None
        self.controller = (
            ResidualController(self.scenario, base_policy, B, residual) if residual_form else None
        )
        self.input_statistics = self._statistics(normalize, normalization_steps)
        self._inputs = np.zeros((B, self.n, self.input_size))
        super().__init__(device=resolved, batch_size=torch.Size([B]))
        self._make_specs()
        if seed is not None:
            self.set_seed(seed)

    @property
    def input_size(self) -> int:
        """d, the length of each vessel's observation entry."""
        return self.sim.obs_dim if self.controller is None else self.controller.input_size

    @property
    def action_size(self) -> int:
        """a, the length of each vessel's action: 4 + m raw, k residual."""
        return self.sim.act_dim if self.controller is None else self.controller.action_size

    def _statistics(self, normalize: bool | InputStatistics, steps: int) -> InputStatistics | None:
        """The input statistics ``normalize`` asks for (estimated, given or none)."""
        if isinstance(normalize, InputStatistics):
            if normalize.size != self.input_size:
                raise ValueError(
                    f"the input statistics have {normalize.size} dimensions but the inputs "
                    f"have {self.input_size}; estimate them for this scenario and residual."
                )
            return normalize
        if not isinstance(normalize, bool | np.bool_):
            raise ValueError(
                f"normalize must be True, False or InputStatistics, got {normalize!r}."
            )
        if not normalize:
            return None
        if self.controller is None:
            raise ValueError(
                "normalize=True estimates the statistics under the base policy, and this env "
                "has none: give base_policy= (or residual=), or pass InputStatistics."
            )
        controller = self.controller
        return estimate_input_statistics(
            self.scenario, controller.base, controller.config, steps=steps
        )

    def _make_specs(self) -> None:
        """Observation, action, reward, done (and state) specs (``torchrl_specs``)."""
        residual = None if self.controller is None else self.action_size
        specs = FleetSpecs.build(
            self.scenario,
            self.num_fleets,
            self.input_size,
            residual,
            self.info_level,
            self.state,
            self.device,
        )
        self.observation_spec = specs.observation
        self.full_action_spec = specs.action
        self.full_reward_spec = specs.reward
        self.full_done_spec = specs.done

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

        The base policy's states of the reset fleets restart with them.

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
            self._horizon[:] = self.scenario.max_steps
            if self.stagger:
                self._horizon -= (
                    np.arange(self.num_fleets) * self.scenario.max_steps // self.num_fleets
                )
            if self.controller is not None:
                self.controller.reset()
            self._observe(obs, None)
        elif fleets.size:
            obs = self.sim.reset(fleets=fleets)
            self._horizon[fleets] = self.scenario.max_steps
            if self.controller is not None:
                mask = np.zeros(self.num_fleets, dtype=bool)
                mask[fleets] = True
                self.controller.reset_fleets(mask)
            self._observe(obs, fleets)
        return self._output(step=False)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Advance every fleet one control period ``dt``.

        Raises:
            ValueError: The action is missing, has the wrong shape, is complex or is not
                finite (naming fleet, vessel, component in the raw form); nothing changes.
            RuntimeError: Stepping before ``reset()``, or the plant diverged (the message
                says where and what to change).
        """
        action = tensordict.get((GROUP, "action"), None)
        expected = (self.num_fleets, self.n, self.action_size)
        form = "[B, n, 4 + m]" if self.controller is None else "[B, n, k]"
        if action is None:
            raise ValueError(
                f"the tensordict has no ({GROUP!r}, 'action') entry; set one of shape "
                f"{form} = {list(expected)}."
            )
        if tuple(action.shape) != expected:
            raise ValueError(
                f"({GROUP!r}, 'action') must have shape {form} = {list(expected)}, "
                f"got {list(action.shape)}."
            )
        values = action.detach().cpu().numpy()
        if self.controller is None:
            obs = self.sim.step(values)
        else:
            if not np.issubdtype(values.dtype, np.floating):
                raise ValueError(
                    f"residual actions must be real floating-point numbers, got {values.dtype}."
                )
            obs = self.sim.step(self.controller.compose(values))
        self._observe(obs, None)
        return self._output(step=True)

    # --- helpers --------------------------------------------------------------------------

    def _observe(self, obs: NDArray[np.float32], fleets: NDArray[np.int64] | None) -> None:
        """Keep the learner inputs of all fleets, or of the listed (just reset) ones."""
        if self.controller is None:
            self._inputs[:] = obs
        elif fleets is None:
            self._inputs[:] = self.controller.observe(obs)
        else:
            self._inputs[fleets] = self.controller.observe(obs[fleets], fleets=fleets)

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

    def _output(self, step: bool) -> TensorDict:
        """Observations, flags (and rewards, state, infos) of every fleet as a tensordict [B].

        Args:
            step: After a step: include rewards and the simulator's flags. After a
                reset the flags are False, as TorchRL requires: a fleet whose drawn
                start is already off its path reports ``terminated`` at its first
                step, as the ParallelEnv does.
        """
        B, n, a = self.num_fleets, self.n, self.sim.arrays
        if step:
            terminated = a.terminated[:, None].copy()
            truncated = ((a.step >= self._horizon) & ~a.terminated)[:, None]
        else:
            terminated = truncated = np.zeros((B, 1), dtype=bool)
        fleet_flags = {
            "done": terminated | truncated,
            "terminated": terminated,
            "truncated": truncated,
        }  # (B, 1) each, in numpy (cheaper than torch at these sizes), then per vessel
        flags = {key: torch.from_numpy(value) for key, value in fleet_flags.items()}
        group: dict[str, Any] = {
            key: torch.from_numpy(np.repeat(value[:, None], n, axis=1))
            for key, value in fleet_flags.items()
        }
        inputs = self._inputs.astype(np.float32)
        if self.input_statistics is not None:
            inputs = self.input_statistics.apply(inputs)
        group["observation"] = torch.from_numpy(inputs)
        if step:
            group["reward"] = torch.from_numpy(a.reward.astype(np.float32)).unsqueeze(-1)
        # Every tensor is made here, on the CPU: with the device given to each level
        # and (on the CPU) non_blocking=False, tensordict skips its device-transfer
        # bookkeeping, which was most of this function's time at small B.
        device, non_blocking = self.device, False if self.device.type == "cpu" else None
        if self.info_level == "minimal":
            errors = torch.from_numpy(a.errors.astype(np.float32))
            infos = {key: errors[..., index] for key, index in ERROR_KEYS}
            group["info"] = TensorDict(
                infos, batch_size=(B, n), device=device, non_blocking=non_blocking
            )
        vessels = TensorDict(group, batch_size=(B, n), device=device, non_blocking=non_blocking)
        root: dict[str, Any] = {**flags, GROUP: vessels}
        if self.state:
            per_vessel = np.concatenate([a.eta, a.nu, a.theta[..., None], a.tau_applied], axis=-1)
            root["state"] = torch.from_numpy(per_vessel.reshape(B, -1).astype(np.float32))
        return TensorDict(
            root, batch_size=self.batch_size, device=device, non_blocking=non_blocking
        )
