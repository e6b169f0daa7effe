"""``FleetVecEnv``: a native Stable-Baselines3 ``VecEnv`` over one batched ``FleetSim``.

One slot per vessel: ``num_envs = num_fleets * n``, slot ``k * n + i`` is
vessel i of fleet k, and one network acts for every vessel (parameter
sharing). Each slot sees only its vessel's local observation (plus the local
extras of ``cpf_env.envs.residual``); the simulator and the base policy run
batched, with no Python loop over fleets.

================  ==============================================================
Observation       ``Box(obs_dim + extras)`` float32, finite bounds (raw units;
                  ``cpf-train`` normalizes with SB3's ``VecNormalize``)
Action            ``Box(-1, 1, (k,))`` float32: the residual (k = 3 forces by
                  default), or with ``base_policy=None`` the whole command:
                  forces and theta_dot as fractions of their limits (k = 4)
Reward            the vessel's reward (``Scenario.reward``)
Episode end       a fleet ends when it terminates (a vessel left its path) or
                  reaches its horizon; it is reset in the same step, and its
                  vessels' infos carry ``terminal_observation`` and
                  ``TimeLimit.truncated`` (SB3's convention)
================  ==============================================================

Seeding follows SB3: ``seed(s)`` makes fleet k start from seed ``s + k`` at
the next ``reset()`` (every vessel of a fleet shares the fleet's episode, so
the seed is per fleet, not per slot); later auto-resets continue each fleet's
generator. ``stagger=True`` (default) ends the first episode of fleet k after
``max_steps - k * max_steps // B`` steps (truncation, bootstrapped by SB3), so
fleets do not end in lockstep and a rollout sees every phase of an episode.

Infos are cheap on purpose (this is the hot path at thousands of slots):
an empty dict per slot, except for the slots of ending fleets. The last
step's base actions, residuals, rewards by term and errors are attributes
(``last_base_actions``, ``last_residual``, ``last_reward_terms``, ``last_errors``).

Example:
    >>> env = FleetVecEnv("wang2014", num_fleets=4, max_steps=50)
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

from baselines import POLICIES, make_policy
from cpf_env.envs.parallel import make_scenario
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.scenarios import Scenario
from cpf_env.sim.fleet import FleetSim
from cpf_env.sim.observation import observation_box

__all__ = ["FleetVecEnv", "resolve_base_policy"]


def resolve_base_policy(
    base_policy: str | FleetPolicy | None,
    scenario: Scenario,
    policy_options: dict[str, Any] | None = None,
) -> FleetPolicy | None:
    """A base policy from a name of ``baselines.POLICIES``, an object, or None (none)."""
    if base_policy is None or base_policy == "none":
        return None
    if isinstance(base_policy, str):
        if base_policy not in POLICIES:
            raise ValueError(
                f"unknown base policy {base_policy!r}; choose one of {sorted(POLICIES)} "
                "or None (the agent commands everything)."
            )
        return make_policy(base_policy, scenario, **(policy_options or {}))
    if not hasattr(base_policy, "act_batch"):
        raise TypeError(
            "base_policy must be a name, None, or an object with act_batch(obs) and "
            f"reset_fleets(mask); got {type(base_policy).__name__}."
        )
    return base_policy


class FleetVecEnv(VecEnv):
    """B fleets x n vessels as one SB3 vector env, a slot per vessel.

    Args:
        scenario: A name of ``cpf_env.scenarios.list_scenarios()`` or a ``Scenario``.
        num_fleets: B, the number of fleets simulated together.
        base_policy: A name of ``baselines.POLICIES`` (default ``"nn_dsc"``), a policy
            object (``act_batch``, ``reset``, ``reset_fleets``), or None: the agent
            outputs the whole command (forces and path-variable rate, as fractions
            of their limits; messages are zero).
        residual: How the correction enters (``ResidualConfig``); default: forces,
            scale 0.2, no extras. With ``base_policy=None`` only its
            ``neighbour_slots`` is used.
        stagger: Spread the first episode's horizons over the fleets.
        policy_options: Options (gains) for a base policy given by name.
        **overrides: ``Scenario`` field overrides, as in ``cpf_env.parallel_env``.

    Attributes:
        scenario: The task.
        sim: The ``FleetSim``.
        controller: The ``ResidualController``.
    """

    render_mode = None

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        num_fleets: int = 64,
        base_policy: str | FleetPolicy | None = "nn_dsc",
        residual: ResidualConfig | None = None,
        stagger: bool = True,
        policy_options: dict[str, Any] | None = None,
        **overrides: Any,
    ) -> None:
        if not isinstance(stagger, bool | np.bool_):
            raise ValueError(f"stagger must be True or False, got {stagger!r}.")
        self.scenario = make_scenario(scenario, **overrides)
        if isinstance(num_fleets, bool) or int(num_fleets) != num_fleets or num_fleets < 1:
            raise ValueError(f"num_fleets must be an integer >= 1, got {num_fleets!r}.")
        self.num_fleets = B = int(num_fleets)
        self.n = n = self.scenario.n
        base = resolve_base_policy(base_policy, self.scenario, policy_options)
        if base is None:
            slots = None if residual is None else residual.neighbour_slots
            residual = ResidualConfig(mode="force_and_rate", scale=1.0, neighbour_slots=slots)
        self.sim = FleetSim(self.scenario, num_fleets=B)
        self.controller = ResidualController(self.scenario, base, B, residual)
        self.stagger = bool(stagger)
        size, k = self.controller.input_size, self.controller.action_size
        observation_space = observation_box(size)
        action_space = spaces.Box(-1.0, 1.0, (k,), dtype=np.float32)
        super().__init__(B * n, observation_space, action_space)
        self._fleet_seeds: list[int | None] = []
        self._horizon = np.full(B, self.scenario.max_steps, dtype=np.int64)
        self._first_reset = True
        self._actions = np.zeros((B, n, k))
        self._inputs = np.zeros((B, n, size), dtype=np.float32)
        self.last_base_actions = np.zeros((B, n, self.controller.act_dim))
        self.last_residual = np.zeros((B, n, k))
        self.last_reward_terms = np.zeros_like(self.sim.arrays.reward_terms)
        self.last_errors = np.zeros_like(self.sim.arrays.errors)

    # --- SB3 VecEnv interface -------------------------------------------------------------

    def seed(self, seed: int | None = None) -> list[int | None]:
        """Fleet k starts from seed ``seed + k`` at the next ``reset()``.

        Returns:
            The fleets' seeds (length B; SB3 documents one per sub-env, and a fleet
            is the unit that shares an episode here).

        Raises:
            ValueError: ``seed`` is not a non-negative integer (the seeds are unchanged).
        """
        if seed is None:
            seed = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        elif (
            isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer) or seed < 0
        ):
            raise ValueError(f"seed must be an integer >= 0 or None, got {seed!r}.")
        self._fleet_seeds = [int(seed) + k for k in range(self.num_fleets)]
        return list(self._fleet_seeds)

    def reset(self) -> NDArray[np.float32]:
        """Reset every fleet (with the seeds of ``seed()``, once) and return the observations.

        Returns:
            (num_envs, input_size) float32.
        """
        seeds = self._fleet_seeds or [None] * self.num_fleets
        self._fleet_seeds = []
        obs = self.sim.reset(seeds=seeds)
        self.controller.reset()
        self._horizon[:] = self.scenario.max_steps
        if self.stagger and self._first_reset:
            spread = np.arange(self.num_fleets) * self.scenario.max_steps // self.num_fleets
            self._horizon -= spread
        self._first_reset = False
        self._inputs[:] = self.controller.observe(obs)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._flat(self._inputs).copy()

    def step_async(self, actions: NDArray[np.floating]) -> None:
        """Store the actions (num_envs, k) for ``step_wait``.

        Raises:
            ValueError: Another shape (a transposed array is not reshaped), complex
                or non-numeric values, or NaN/inf; nothing is stored.
        """
        raw = np.asarray(actions)
        expected = (self.num_envs, self.controller.action_size)
        if raw.shape != expected:
            raise ValueError(
                f"actions must have shape (num_envs, k) = {expected}, got {raw.shape}; "
                "one row per slot (slot = fleet * n + vessel)."
            )
        real = raw.dtype.kind in "fiu" or any(  # the kinds first: cheaper, same answer
            np.issubdtype(raw.dtype, kind) for kind in (np.floating, np.integer)
        )
        if not real:
            raise ValueError(f"actions must be real numbers, got dtype {raw.dtype}.")
        array = raw.astype(np.float64)
        if not np.isfinite(array).all():
            raise ValueError(
                "actions must be finite (no NaN or +-inf); they are clipped to [-1, 1]."
            )
        self._actions = array.reshape(self.num_fleets, self.n, -1)

    def step_wait(self) -> VecEnvStepReturn:
        """Step every fleet; reset the fleets that ended, in the same step.

        Returns:
            (observations (num_envs, input_size) float32, rewards (num_envs,) float32,
            dones (num_envs,) bool, infos (list of num_envs dicts)).
        """
        command = self.controller.compose(self._actions)
        self.last_base_actions = self.controller.base_actions.copy()
        self.last_residual = self.controller.residual.copy()
        obs = self.sim.step(command)
        a = self.sim.arrays
        rewards = a.reward.astype(np.float32).reshape(-1)
        self.last_reward_terms = a.reward_terms.copy()
        self.last_errors = a.errors.copy()
        terminated = a.terminated.copy()
        ended = terminated | (a.step >= self._horizon)
        self._inputs[:] = self.controller.observe(obs)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if ended.any():
            self._restart(np.flatnonzero(ended), terminated, infos)
        dones = np.repeat(ended, self.n)
        return self._flat(self._inputs).copy(), rewards, dones, infos

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

    def _restart(
        self, fleets: NDArray[np.int64], terminated: NDArray[np.bool_], infos: list[dict]
    ) -> None:
        """Record terminal observations of the ending fleets, then reset them and their base."""
        for b in fleets:
            truncated = not terminated[b]
            for i in range(self.n):
                slot = infos[b * self.n + i]
                slot["terminal_observation"] = self._inputs[b, i].copy()
                slot["TimeLimit.truncated"] = truncated
        obs = self.sim.reset(fleets=fleets)
        mask = np.zeros(self.num_fleets, dtype=bool)
        mask[fleets] = True
        self.controller.reset_fleets(mask)
        self._horizon[fleets] = self.scenario.max_steps
        self._inputs[fleets] = self.controller.observe(obs[fleets], fleets=fleets)

    def _flat(self, array: NDArray[np.float32]) -> NDArray[np.float32]:
        """(B, n, d) -> (B * n, d), slot k * n + i = vessel i of fleet k."""
        return array.reshape(self.num_envs, -1)

    def _slots(self, indices: VecEnvIndices) -> Sequence[int]:
        """Slot indices from SB3's ``indices`` argument (None, an int or an iterable)."""
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        assert isinstance(indices, Iterable)
        return list(indices)
