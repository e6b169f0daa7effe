"""``FleetVecEnv``: a native Stable-Baselines3 ``VecEnv`` over one batched ``FleetSim``.

One slot per vessel: ``num_envs = num_fleets * n``, slot ``k * n + i`` is
vessel i of fleet k, and one network acts for every vessel (parameter
sharing). Each slot sees only its vessel's local observation (plus the local
extras of ``cpf_env.envs.residual``); the simulator and the base policy run
batched, with no Python loop over fleets.

================  ==============================================================
Observation       ``Box(obs_dim + extras)`` float32, finite bounds (raw units;
                  ``cpf-train`` normalizes with SB3's ``VecNormalize``); with
                  ``critic_state`` ``+ UNOBSERVED_SIZE``
Action            ``Box(-1, 1, (k,))`` float32: the residual (k = 3 forces by
                  default), or with ``base_policy=None`` the whole command:
                  forces and theta_dot as fractions of their limits (k = 4)
Reward            the vessel's reward (``Scenario.reward``)
Episode end       a fleet ends when it terminates (a vessel left its path) or
                  reaches its horizon; it is reset in the same step, and its
                  vessels' infos carry ``terminal_observation`` and
                  ``TimeLimit.truncated`` (SB3's convention)
================  ==============================================================

Seeding, horizons, stagger, per-fleet resets and the residual are the
``EpisodeCore``'s (``cpf_env.envs.core``), as on every route: fleet k starts
from seed ``s + k``; later auto-resets continue each fleet's generator;
``stagger=True`` (default) ends fleet k's episode after ``max_steps - k *
max_steps // B`` steps at each reset of all fleets (truncation, bootstrapped
by SB3), so fleets do not end in lockstep. Differences SB3 forces: ``seed(s)``
takes effect at the next ``reset()`` (every vessel of a fleet shares the
fleet's episode, so the seed is per fleet, not per slot), and an ending fleet
is reset in the same step, its last observation in ``terminal_observation``.

``critic_state=True`` appends ``UNOBSERVED_SIZE`` = 5 floats to every slot's
input, after the local input: what the vessel cannot observe
(``cpf_env.evaluation.privileged.unobserved_state``: the true lumped force
over the force scale, v0, theta_i minus the fleet's mean). They are for an
asymmetric critic (``TrainConfig.asymmetric_critic``); the actor drops them
(``agents.training.algorithms.AsymmetricActorCriticPolicy``). A terminal observation
carries the state the fleet ended in.

Infos follow ``info_level`` (``"none"``, the default of every route: an empty
dict per slot, the hot path at thousands of slots; ``"minimal"``/``"full"``:
each slot's ``EpisodeCore.vessel_infos``), plus SB3's entries of ending
slots. The arrays are always in ``env.core`` (``core.info_arrays("full")``).

Example:
    >>> env = FleetVecEnv("wang2014", num_fleets=4, base_policy="nn_dsc", max_steps=50)
    >>> env.seed(0)
    [0, 1, 2, 3]
    >>> obs = env.reset()
    >>> obs.shape, env.num_envs
    ((20, 26), 20)
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from agents.envs.resolve import make_core
from cpf_env.envs.core import DEFAULT_INFO_LEVEL, check_info_level, checked_actions
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.evaluation.privileged import UNOBSERVED_SIZE, unobserved_state
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import check_seed
from cpf_env.sim.observation import observation_box

__all__ = ["FleetVecEnv"]


class FleetVecEnv(VecEnv):
    """B fleets x n vessels as one SB3 vector env, a slot per vessel.

    Args:
        scenario: A name of ``cpf_env.scenarios.list_scenarios()`` or a ``Scenario``.
        num_fleets: B, the number of fleets simulated together.
        base_policy: A name of ``baselines.DEPLOYABLE`` (e.g. ``"nn_dsc"``), a policy
            object (``act_batch``, ``reset``, ``reset_fleets``), or None (default,
            as on every route): the agent outputs the whole command (forces and
            path-variable rate, as fractions of their limits; messages are zero).
        residual: How the correction enters (``ResidualConfig``); default: forces,
            scale 0.2, no extras. With ``base_policy=None`` only its
            ``neighbour_slots`` is used.
        stagger: Spread the horizons over the fleets at each reset of all fleets.
        info_level: ``"none"`` (default), ``"minimal"`` or ``"full"``.
        policy_options: Options (gains) for a base policy given by name.
        critic_state: Append the unobserved state to each input (module docstring).
        **overrides: ``Scenario`` field overrides, as in ``cpf_env.parallel_env``.

    Attributes:
        core: The ``EpisodeCore``.
        scenario: The task.
        sim: The ``FleetSim`` (``core.sim``).
        controller: The ``ResidualController`` (``core.controller``).
    """

    render_mode = None

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        num_fleets: int = 64,
        base_policy: str | FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        stagger: bool = True,
        info_level: str = DEFAULT_INFO_LEVEL,
        policy_options: dict[str, Any] | None = None,
        critic_state: bool = False,
        **overrides: Any,
    ) -> None:
        self.info_level = check_info_level(info_level)
        self.critic_state = critic_state
        core = make_core(
            scenario, num_fleets, base_policy, residual, stagger, policy_options, **overrides
        )
        self.core, self.scenario, self.sim = core, core.scenario, core.sim
        assert core.controller is not None  # make_core: always the residual form
        self.controller = core.controller
        self.num_fleets, self.n, self.stagger = core.num_fleets, core.n, core.stagger
        observation_space = observation_box(
            core.input_size + (UNOBSERVED_SIZE if critic_state else 0)
        )
        action_space = spaces.Box(-1.0, 1.0, (core.action_size,), dtype=np.float32)
        super().__init__(core.num_fleets * core.n, observation_space, action_space)
        self._fleet_seeds: list[int | None] = []
        self._actions = np.zeros((core.num_fleets, core.n, core.action_size))

    # --- SB3 VecEnv interface -------------------------------------------------------------

    def seed(self, seed: int | None = None) -> list[int | None]:
        """Fleet k starts from seed ``seed + k`` at the next ``reset()``.

        Returns:
            The fleets' seeds (length B; SB3 documents one per sub-env, and a fleet
            is the unit that shares an episode here).

        Raises:
            ValueError: ``seed`` is not a non-negative integer (the seeds are unchanged).
        """
        checked = check_seed(seed)
        if checked is None:
            checked = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        self._fleet_seeds = self.core.fleet_seeds(checked, np.arange(self.num_fleets))
        return list(self._fleet_seeds)

    def reset(self) -> NDArray[np.float32]:
        """Reset every fleet (with the seeds of ``seed()``, once) and return the observations.

        Returns:
            (num_envs, input_size) float32.
        """
        seeds = self._fleet_seeds or None
        self._fleet_seeds = []
        self.core.reset(seeds=seeds)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._observations()

    def step_async(self, actions: NDArray[np.floating]) -> None:
        """Store the actions (num_envs, k) for ``step_wait``.

        Raises:
            ValueError: Another shape (a transposed array is not reshaped), not real
                numbers, or NaN/inf; nothing is stored.
        """
        shape = (self.num_envs, self.core.action_size)
        form = "(num_envs, k), one row per slot = fleet * n + vessel,"
        checked = checked_actions(actions, shape, form, ("slot {}", "component {}"))
        self._actions = checked.reshape(self.num_fleets, self.n, -1)

    def step_wait(self) -> VecEnvStepReturn:
        """Step every fleet; reset the fleets that ended, in the same step.

        Returns:
            (observations (num_envs, input_size) float32, rewards (num_envs,) float32,
            dones (num_envs,) bool, infos (list of num_envs dicts)).
        """
        self.core.step(self._actions, checked=True)
        rewards = self.core.reward.astype(np.float32).reshape(-1)
        terminated, ended = self.core.terminated, self.core.ended
        infos = self.core.vessel_infos(self.info_level)
        if not ended.any():  # the hot path
            return self._observations(), rewards, np.zeros(self.num_envs, dtype=bool), infos
        unobserved = (
            unobserved_state(self.sim, np.flatnonzero(ended)) if self.critic_state else None
        )
        fleets, terminal = self.core.reset_ended()
        if unobserved is not None:
            terminal = np.concatenate([terminal, unobserved], axis=-1)
        for row, b in enumerate(fleets):
            truncated = not terminated[b]
            for i in range(self.n):
                slot = infos[b * self.n + i]
                slot["terminal_observation"] = terminal[row, i]
                slot["TimeLimit.truncated"] = truncated
        dones = np.zeros(self.num_fleets, dtype=bool)
        dones[fleets] = True
        return self._observations(), rewards, np.repeat(dones, self.n), infos

    def close(self) -> None:
        """Nothing to release (the simulator holds only arrays)."""

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of this env, once per requested slot (all slots share it)."""
        return [getattr(self, attr_name)] * len(self._slots(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of this env (shared by all slots)."""
        self._slots(indices)
        setattr(self, attr_name, value)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Call a method of this env once per requested slot, and collect the results."""
        method = getattr(self, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._slots(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """False for every slot: there is no Gymnasium env inside to wrap."""
        return [False] * len(self._slots(indices))

    # --- helpers --------------------------------------------------------------------------

    def _observations(self) -> NDArray[np.float32]:
        """(B * n, d) inputs, slot k * n + i = vessel i of fleet k; a copy (module docstring)."""
        if self.critic_state:  # a new array already
            inputs = np.concatenate([self.core.inputs, unobserved_state(self.sim)], axis=-1)
            return inputs.reshape(self.num_envs, -1)
        return self.core.inputs.reshape(self.num_envs, -1).copy()

    def _slots(self, indices: VecEnvIndices) -> Sequence[int]:
        """Slot indices from SB3's ``indices`` argument (None, an int or an iterable)."""
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        assert isinstance(indices, Iterable)
        return list(indices)
