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
                                            residual: a = k + learned messages,
                                            in [-1, 1]
("vessel", "reward")           [B, n, 1]    float32 reward of each vessel
("vessel", "done"/...)         [B, n, 1]    bool done, terminated, truncated of each vessel
"done"/"terminated"/...        [B, 1]       bool, the fleet's flags (equal to its vessels')
"state"                        [B, 10 n]    float32 global state (``state=True``): the
                                            ParallelEnv's ``state()`` of each fleet;
                               [B, (10+k) n] with ``extra_state``: followed by its
                                            features (B, n, k), vessel by vessel
("vessel", "info", <name>)     [B, n, ...]  ``EpisodeCore.info_arrays(info_level)``: none
                                            by default; "minimal": the four errors;
                                            "full": every diagnostic (float32, bool)
=============================  ===========  ===================================================

Episodes end per fleet: terminated when a vessel leaves its path, truncated
after ``max_steps``; every vessel of a fleet shares the fleet's flags. As in
every TorchRL env, nothing resets by itself: ``rollout``, collectors and
``step_and_maybe_reset`` reset the done fleets through the ``"_reset"`` mask
(root [B, 1] or group [B, n, 1]; a fleet resets if any of its entries is set).

Seeding, horizons, stagger, resets and the residual are the ``EpisodeCore``'s,
as on every route: ``set_seed(s)`` (or ``seed=s``) makes fleet k draw its
episodes from ``default_rng(s + k)``, so fleet k reproduces
``cpf_env.parallel_env(...).reset(seed=s + k)`` bit for bit (up to the stagger);
later resets continue each fleet's generator. Differences TorchRL forces:
nothing resets by itself (see above), and ``set_seed`` reseeds at once rather
than at the next reset (``EnvBase``'s contract). Importing ``cpf_env`` does not
import this module (it needs the ``torchrl`` extra), and this module imports no
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

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import torch
from numpy.typing import NDArray
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import EnvBase

from cpf_env.envs.core import DEFAULT_INFO_LEVEL, EpisodeCore, check_flag, check_info_level
from cpf_env.envs.input_statistics import InputStatistics, estimate_input_statistics
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.torchrl_specs import GROUP, FleetSpecs
from cpf_env.scenarios import Scenario, make_scenario

if TYPE_CHECKING:
    from cpf_env.sim.fleet import FleetSim

__all__ = ["GROUP", "StateFeatures", "TorchRLFleetEnv"]


class StateFeatures(NamedTuple):
    """Per-vessel features appended to the global ``"state"`` (``extra_state=``).

    Attributes:
        size: k, the features per vessel (>= 1).
        compute: The ``FleetSim`` -> (B, n, k) features, read once the simulator holds
            an episode (float; output as float32).
    """

    size: int
    compute: Callable[[FleetSim], NDArray[Any]]


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
        base_policy: A ``FleetPolicy`` object acting underneath (residual form), e.g.
            ``baselines.make_policy("nn_dsc", scenario)``; names are resolved by
            ``agents.marl.make_env``. It must offer ``reset_fleets``.
        residual: ``ResidualConfig`` of the residual form (``EpisodeCore``).
        stagger: At each reset of all fleets, end fleet k's episode after
            ``max_steps - k * max_steps // B`` steps (truncated), as every batched
            route does; a fleet reset alone runs ``max_steps``.
        info_level: ``"none"`` (default, the hot path), ``"minimal"`` or ``"full"``:
            what ``("vessel", "info")`` holds.
        device: Where the outputs and specs live (the simulator stays on the CPU;
            actions are brought back to it).
        seed: If given, ``set_seed(seed)`` at construction (fleet k: seed + k).
        normalize: False (raw inputs), True (scale them with ``InputStatistics``
            estimated over ``normalization_steps`` of the base policy alone on a
            separate simulator of 16 fleets, seeds 0 .. 15; residual form only) or
            given statistics.
        normalization_steps: Control periods pooled by ``normalize=True``.
        state: Also output the global ``"state"`` [B, 10 n] for centralized critics.
        extra_state: ``StateFeatures``: k features per vessel computed from the
            ``FleetSim`` and appended to ``"state"`` vessel by vessel: [B, (10 + k) n].
            For a critic only, e.g. what no vessel observes for an asymmetric
            actor-critic (``agents.marl.envs.make_env(privileged_state=True)`` gives
            ``cpf_env.evaluation.privileged.unobserved_state``, k = 5); needs
            ``state=True``. After a step it reads the simulator as each fleet ended
            its step, before any reset, as every ``"next"`` entry does.
        **overrides: ``Scenario`` field overrides, as in ``cpf_env.parallel_env``.

    Attributes:
        core: The ``EpisodeCore``.
        scenario: The task.
        sim: The ``FleetSim`` (``core.sim``; its ``arrays`` hold anything else, e.g. poses).
        num_fleets: B.
        n: Vessels per fleet.
        group_map: ``{"vessel": ["vessel_0", ...]}``, as TorchRL's multi-agent envs.
        input_statistics: The ``InputStatistics`` applied, or None.
        state: Whether ``"state"`` is output.
        extra_state: The ``StateFeatures`` it also holds, or None.
    """

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        num_fleets: int = 64,
        base_policy: FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        stagger: bool = True,
        info_level: str = DEFAULT_INFO_LEVEL,
        device: str | torch.device = "cpu",
        seed: int | None = None,
        normalize: bool | InputStatistics = False,
        normalization_steps: int = 200,
        state: bool = False,
        extra_state: StateFeatures | None = None,
        **overrides: Any,
    ) -> None:
        resolved = _checked_device(device)
        self.info_level = check_info_level(info_level)
        self.state = check_flag(state, "state")
        if extra_state is not None:
            if not (isinstance(extra_state, StateFeatures) and self.state):
                raise ValueError(
                    'extra_state= holds features appended to the global "state": pass '
                    f"StateFeatures(size, compute) and state=True (got "
                    f"{type(extra_state).__name__} and state={self.state})."
                )
            if not (isinstance(extra_state.size, int) and extra_state.size >= 1):
                raise ValueError(
                    f"StateFeatures.size must be an int >= 1, got {extra_state.size!r}."
                )
        self.extra_state = extra_state
        self.scenario = make_scenario(scenario, **overrides)
        self.core = EpisodeCore(self.scenario, num_fleets, base_policy, residual, stagger)
        self.sim, self.num_fleets, self.n = self.core.sim, self.core.num_fleets, self.core.n
        self.group_map = {GROUP: [f"vessel_{i}" for i in range(self.n)]}
        self.input_statistics = self._statistics(normalize, normalization_steps)
        super().__init__(device=resolved, batch_size=torch.Size([self.num_fleets]))
        extra = 0 if extra_state is None else extra_state.size
        specs = FleetSpecs.build(self.core, self.info_level, self.state, self.device, extra)
        self.observation_spec = specs.observation
        self.full_action_spec = specs.action
        self.full_reward_spec = specs.reward
        self.full_done_spec = specs.done
        if seed is not None:
            self.set_seed(seed)

    def _statistics(self, normalize: bool | InputStatistics, steps: int) -> InputStatistics | None:
        """The input statistics ``normalize`` asks for (estimated, given or none)."""
        if isinstance(normalize, InputStatistics):
            if normalize.size != self.core.input_size:
                raise ValueError(
                    f"the input statistics have {normalize.size} dimensions but the inputs "
                    f"have {self.core.input_size}; estimate them for this scenario and residual."
                )
            return normalize
        if not check_flag(normalize, "normalize (True, False or InputStatistics)"):
            return None
        controller = self.core.controller
        if controller is None:
            raise ValueError(
                "normalize=True estimates the statistics under the base policy, and this env "
                "has none: give base_policy= (or residual=), or pass InputStatistics."
            )
        return estimate_input_statistics(
            self.scenario, controller.base, controller.config, steps=steps
        )

    # --- EnvBase interface ----------------------------------------------------------------

    def _set_seed(self, seed: int | None) -> None:
        """Fleet k draws its next episodes from ``default_rng(seed + k)``; None: fresh entropy."""
        self.core.reseed(seed)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        """Reset the fleets selected by the ``"_reset"`` masks (all fleets without one).

        Args:
            tensordict: May hold ``"_reset"`` [B, 1] and/or ``("vessel", "_reset")``
                [B, n, 1]; a fleet resets if any of its entries is True.
            **kwargs: Ignored (TorchRL passes its own reset options).
        """
        fleets = self._fleets_to_reset(tensordict)
        if fleets is None or fleets.size:
            self.core.reset(fleets=fleets)
        return self._output(step=False)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Advance every fleet one control period ``dt``.

        Raises:
            ValueError: The action is missing or bad (``EpisodeCore.check_actions``);
                nothing changes.
            RuntimeError: Stepping before ``reset()``, or the plant diverged.
        """
        action = tensordict.get((GROUP, "action"), None)
        if action is None:
            raise ValueError(
                f"the tensordict has no ({GROUP!r}, 'action') entry; set one of shape "
                f"[B, n, a] = {[self.num_fleets, self.n, self.core.action_size]}."
            )
        self.core.step(action.detach().cpu().numpy())
        return self._output(step=True)

    # --- helpers --------------------------------------------------------------------------
    def _extra_state(self) -> NDArray[np.float32]:
        """The extra state's features, float32 (B, n, k), or a ValueError saying what came."""
        assert self.extra_state is not None
        features = np.asarray(self.extra_state.compute(self.sim))
        expected = (self.num_fleets, self.n, self.extra_state.size)
        if features.shape != expected:
            raise ValueError(
                f"extra_state.compute must return (B, n, k) = {expected} features, got shape "
                f"{features.shape}."
            )
        return features.astype(np.float32, copy=False)

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
            step: After a step: include rewards and the core's flags. After a reset
                the flags are False, as TorchRL requires: a fleet whose drawn start is
                already off its path reports ``terminated`` at its first step.
        """
        B, n, core = self.num_fleets, self.n, self.core
        if step:
            terminated, truncated = core.terminated[:, None], core.truncated[:, None]
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
        inputs = core.inputs.copy()
        if self.input_statistics is not None:
            inputs = self.input_statistics.apply(inputs)
        group["observation"] = torch.from_numpy(inputs)
        if step:
            group["reward"] = torch.from_numpy(core.reward.astype(np.float32)).unsqueeze(-1)
        # Every tensor is made here, on the CPU: with the device given to each level
        # and (on the CPU) non_blocking=False, tensordict skips its device-transfer
        # bookkeeping, which was most of this function's time at small B.
        device, non_blocking = self.device, False if self.device.type == "cpu" else None
        if self.info_level != "none":
            infos = {
                key: torch.from_numpy(value if value.dtype == bool else value.astype(np.float32))
                for key, value in core.info_arrays(self.info_level).items()
            }
            group["info"] = TensorDict(
                infos, batch_size=(B, n), device=device, non_blocking=non_blocking
            )
        vessels = TensorDict(group, batch_size=(B, n), device=device, non_blocking=non_blocking)
        root: dict[str, Any] = {**flags, GROUP: vessels}
        if self.state:
            state = core.state()
            if self.extra_state is not None:
                state = np.concatenate([state, self._extra_state().reshape(B, -1)], axis=1)
            root["state"] = torch.from_numpy(state)
        return TensorDict(
            root, batch_size=self.batch_size, device=device, non_blocking=non_blocking
        )
