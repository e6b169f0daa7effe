"""``ResidualWrapper``: a PettingZoo ParallelEnv in which agents learn corrections to a base policy.

================  ==============================================================
Agents            as the wrapped env: ``vessel_0`` ... ``vessel_{n-1}``
Action (each)     ``Box(-1, 1, (k,))`` float32, k = 3 (forces; default), 4 (forces
                  and path-variable rate) or 3 (kinematic offset)
Observation       ``Box(obs_dim + extras)`` float32: the vessel's local observation,
                  then the chosen extras (all local by construction)
Infos             the wrapped env's, plus ``base_command`` (the base's action,
                  (4 + m,)), ``residual`` (the correction in physical units, (k,))
================  ==============================================================

The applied command is composed by ``cpf_env.envs.residual.ResidualController``
(one implementation for this wrapper and the batched vector env of
``agents``): ``tau0 = tau_base + scale * tau_limit * a`` in physical units
before the plant's saturation. The base policy is any object with
``act_batch`` and ``reset`` (the analytic policies of ``baselines`` have
them); this module imports none. With a zero action the wrapped env follows
the base policy's trajectory bit for bit. See ``docs/residual_rl.md``.

Example:
    >>> import numpy as np
    >>> import cpf_env
    >>> from baselines import make_policy
    >>> env = cpf_env.parallel_env("wang2014", max_steps=20)
    >>> env = ResidualWrapper(env, make_policy("nn_dsc", env), scale=0.2)
    >>> observations, infos = env.reset(seed=0)
    >>> while env.agents:
    ...     actions = {agent: np.zeros(3, np.float32) for agent in env.agents}
    ...     observations, rewards, terminations, truncations, infos = env.step(actions)
    >>> infos["vessel_0"]["residual"]
    array([0., 0., 0.])
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from pettingzoo.utils.wrappers import BaseParallelWrapper

from cpf_env.envs.parallel import CooperativePathFollowingEnv
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig, ResidualController
from cpf_env.sim.observation import observation_box

__all__ = ["ResidualWrapper"]


class ResidualWrapper(BaseParallelWrapper):
    """Agents act through a bounded correction on top of a base policy.

    Args:
        env: A ``CooperativePathFollowingEnv`` (``cpf_env.parallel_env(...)``).
        base_policy: Any object with ``act_batch(obs (1, n, obs_dim))`` and ``reset()``.
        scale: Fraction of the limits per unit of action (``ResidualConfig.scale``).
        mode: ``"force"``, ``"force_and_rate"`` or ``"kinematic"``.
        extras: Names of ``cpf_env.envs.residual.EXTRAS`` appended to each observation.
        hide_residual_from_base: Show the base the applied force minus the residual.
        kinematic_scale: Offset (m, m, rad) per unit of action in ``kinematic`` mode.

    Attributes:
        controller: The ``ResidualController`` (B = 1) that composes the commands.
    """

    def __init__(
        self,
        env: CooperativePathFollowingEnv,
        base_policy: FleetPolicy,
        scale: float = 0.2,
        mode: str = "force",
        extras: tuple[str, ...] = (),
        hide_residual_from_base: bool = True,
        kinematic_scale: tuple[float, float, float] = (0.05, 0.05, 0.05),
    ) -> None:
        if not isinstance(env.unwrapped, CooperativePathFollowingEnv):
            raise TypeError(
                "ResidualWrapper wraps a cpf_env ParallelEnv (cpf_env.parallel_env(...)), "
                f"got {type(env).__name__}."
            )
        super().__init__(env)
        config = ResidualConfig(
            mode=mode,
            scale=scale,
            kinematic_scale=kinematic_scale,
            extras=tuple(extras),
            hide_residual_from_base=hide_residual_from_base,
        )
        self.controller = ResidualController(env.unwrapped.scenario, base_policy, 1, config)
        self._inputs = np.zeros((1, env.unwrapped.scenario.n, self.controller.input_size))
        # per-instance caches: a class-level functools.cache would keep every env alive
        self._observation_spaces: dict[str, spaces.Box] = {}
        self._action_spaces: dict[str, spaces.Box] = {}

    def observation_space(self, agent: str) -> spaces.Box:
        """Local observation plus extras, float32 with finite bounds (one object per agent)."""
        if agent not in self._observation_spaces:
            self.env.observation_space(agent)  # validates the agent name
            self._observation_spaces[agent] = observation_box(self.controller.input_size)
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The correction, ``Box(-1, 1, (k,))`` float32 (one object per agent)."""
        if agent not in self._action_spaces:
            self.env.action_space(agent)  # validates the agent name
            size = (self.controller.action_size,)
            self._action_spaces[agent] = spaces.Box(-1.0, 1.0, shape=size, dtype=np.float32)
        return self._action_spaces[agent]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict[str, Any]]]:
        """Reset the env and the base policy (with the same seed)."""
        observations, infos = self.env.reset(seed=seed, options=options)
        self.controller.reset(seed=seed)
        self._inputs = self.controller.observe(self._stack(observations))
        return self._split(self._inputs), infos

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, float], dict, dict, dict]:
        """Compose base command and correction, step the env, observe.

        Raises:
            ValueError: Missing or extra agent, wrong shape or non-finite action;
                nothing is changed.
        """
        correction = self._correction(actions)
        command = self.controller.compose(correction)
        used = (self.controller.base_actions[0].copy(), self.controller.residual[0].copy())
        env_actions = {
            agent: command[0, i]
            for i, agent in enumerate(self.env.agents)  # float64: exact
        }
        observations, rewards, terminations, truncations, infos = self.env.step(env_actions)
        self._inputs = self.controller.observe(self._stack(observations))
        return (
            self._split(self._inputs),
            rewards,
            terminations,
            truncations,
            self._annotate(infos, *used),
        )

    def _correction(self, actions: dict[str, Any]) -> NDArray[np.float64]:
        """Validate the correction dict and stack it as (1, n, k) before any state changes."""
        agents = self.env.agents
        if not agents:
            raise RuntimeError("the episode is over (or never started); call reset().")
        if not isinstance(actions, dict) or set(actions) != set(agents):
            given = sorted(actions) if isinstance(actions, dict) else type(actions).__name__
            raise ValueError(
                f"actions must be a dict with one entry per live agent {agents}, got {given}."
            )
        k = self.controller.action_size
        batch = np.zeros((1, len(agents), k))
        for i, agent in enumerate(agents):
            action = np.asarray(actions[agent])
            if action.shape != (k,) or not np.isrealobj(action):
                raise ValueError(
                    f"correction of {agent} must be {k} real numbers in [-1, 1], "
                    f"got shape {action.shape} ({action.dtype})."
                )
            if not np.all(np.isfinite(action)):
                raise ValueError(f"correction of {agent} is not finite: {action.tolist()}.")
            batch[0, i] = action
        return batch

    def _stack(self, observations: dict[str, NDArray[np.float32]]) -> NDArray[np.float32]:
        """Observation dict -> (1, n, obs_dim) in agent order."""
        agents = self.env.possible_agents
        return np.stack([observations[agent] for agent in agents])[None]

    def _split(self, inputs: NDArray[np.float64]) -> dict[str, NDArray[np.float32]]:
        """(1, n, input_size) -> dict of float32 inputs of the live agents."""
        return {
            agent: inputs[0, i].astype(np.float32)
            for i, agent in enumerate(self.env.possible_agents)
            if agent in self.env.agents or not self.env.agents
        }

    def _annotate(
        self,
        infos: dict[str, dict[str, Any]],
        base: NDArray[np.float64],
        residual: NDArray[np.float64],
    ) -> dict[str, dict[str, Any]]:
        """Add this step's base command (n, 4 + m) and correction (n, k) to the agents' infos."""
        for i, agent in enumerate(self.env.possible_agents):
            if agent in infos:
                infos[agent]["base_command"] = base[i]
                infos[agent]["residual"] = residual[i]
        return infos
