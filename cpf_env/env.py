"""PettingZoo ``ParallelEnv`` for cooperative path following of a vessel fleet.

================  ==============================================================
Agents            ``vessel_0`` ... ``vessel_{n-1}``, all present all episode
Action (each)     ``Box(4 + m)`` float32: [tau_u, tau_v, tau_r, theta_dot, msg...]
Observation       ``Box(18 + K (3 + m))`` float32, strictly local (``ObsLayout``)
State             ``Box(n * 10)``: eta, nu, theta, tau_applied of every vessel
Import            ``cpf_env.parallel_env(scenario="wang2014", **overrides)``
================  ==============================================================
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from cpf_env import kernels, scenarios
from cpf_env.observation import ObsLayout
from cpf_env.reward import REWARD_TERMS
from cpf_env.scenarios import Scenario
from cpf_env.sim import FleetSim
from cpf_env.views import FleetViews, check_render_mode

__all__ = ["CooperativePathFollowingEnv", "make_scenario"]


def make_scenario(scenario: str | Scenario = "wang2014", **overrides: Any) -> Scenario:
    """Resolve a scenario name or object and apply field overrides (``Scenario.replace``)."""
    if isinstance(scenario, str):
        scenario = scenarios.get(scenario)
    elif not isinstance(scenario, Scenario):
        raise TypeError(
            f"scenario must be a name from {scenarios.list_scenarios()} or a Scenario, "
            f"got {type(scenario).__name__}."
        )
    return scenario.replace(**overrides) if overrides else scenario


class CooperativePathFollowingEnv(ParallelEnv):
    """A fleet of surface vessels that follow their paths in step, one agent per vessel.

    ## Description

    Each vessel (3-DOF Cybership II dynamics with unmodeled dynamics, ocean
    disturbances and actuator saturation; Wang, Wang & Peng, Nonlinear
    Dynamics 77, 2014) must follow its own path eta_d(theta_i), keep its path
    variable theta_i synchronized with its neighbours' and advance it at the
    leader's speed v0, which only vessels with a leader link (b_i = 1) hear.
    Neighbours exchange theta and an m-float message over a communication
    graph whose links may lose and delay packets or switch.

    ## Action Space

    ``Box(4 + m)`` per vessel, float32:

    | idx | name | unit | bounds |
    |---|---|---|---|
    | 0-2 | tau0: surge, sway force; yaw moment | N, N, N m | the saturation limits (*) |
    | 3 | theta_dot, rate of the path variable | 1/s | +-theta_dot_max (clipped) |
    | 4.. | message broadcast to neighbours | - | +-message_max (clipped) |

    (*) Commands beyond the limits are allowed: the plant saturates them (PAPER.md eq. [6]).

    ## Observation Space

    ``Box(18 + K (3 + m))`` per vessel, float32; see ``cpf_env.observation``
    for the table and ``self.layout`` (``ObsLayout``) for named slices. No other
    vessel's pose, and no v0 unless b_i = 1.

    ## Rewards

    ``-dt (w_pos ||z1_xy||^2 + w_head z1_psi^2 + w_sync s_i^2 + w_speed (theta_dot_i - v0)^2
    + w_tau ||tau_i / tau_max||^2)``, weights in ``Scenario.reward`` (optionally a
    shared team reward).

    ## Starting State

    Drawn from ``Scenario.initial`` with the reset seed (``wang2014``: the
    paper's fixed poses, at rest, theta = 0).

    ## Episode End

    Terminated for all vessels when one is farther than ``max_path_error`` from
    its path; truncated after ``max_steps`` control steps (``dt`` each).

    ## Arguments

    ``scenario`` (name or ``Scenario``), ``render_mode`` (``"human"`` or
    ``"rgb_array"``) and any ``Scenario`` field as an override.

    ## Example

    >>> import cpf_env
    >>> env = cpf_env.parallel_env("wang2014", max_steps=10)
    >>> observations, infos = env.reset(seed=0)
    >>> actions = {agent: env.action_space(agent).sample() for agent in env.agents}
    >>> observations, rewards, terminations, truncations, infos = env.step(actions)

    ## Version History

    * v0: initial release.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - PettingZoo's class-level convention
        "name": "cooperative_path_following_v0",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 20,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.scenario = make_scenario(scenario, **overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.dt}
        self.sim = FleetSim(self.scenario, num_fleets=1)
        self.layout: ObsLayout = self.sim.layout
        self.possible_agents = [f"vessel_{i}" for i in range(self.scenario.n)]
        self.agents: list[str] = []
        self._index = {agent: i for i, agent in enumerate(self.possible_agents)}
        self._views = FleetViews(self.scenario, render_mode)
        self.np_random, _ = seeding.np_random()

    @functools.cache  # noqa: B019 - one space object per agent, by design
    def observation_space(self, agent: str) -> spaces.Box:
        """Local observation space of ``agent`` (the same object on every call)."""
        self._check_agent(agent)
        return spaces.Box(-np.inf, np.inf, shape=(self.layout.size,), dtype=np.float32)

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Box:
        """Action space of ``agent``: force limits, rate bound, message bound."""
        i = self._check_agent(agent)
        s = self.scenario
        m = s.message_size
        tau_min, tau_max = s.tau_limits
        low = np.concatenate([tau_min[i], [-s.theta_dot_max], np.full(m, -s.message_max)])
        high = np.concatenate([tau_max[i], [s.theta_dot_max], np.full(m, s.message_max)])
        return spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)

    @functools.cached_property
    def state_space(self) -> spaces.Box:
        """Global state for a centralized critic: (eta, nu, theta, tau_applied) of every vessel."""
        return spaces.Box(-np.inf, np.inf, shape=(self.scenario.n * 10,), dtype=np.float32)

    def _check_agent(self, agent: str) -> int:
        if agent not in self._index:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}.")
        return self._index[agent]

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict]]:
        """Start an episode; ``seed`` fixes initial state, models and all noise."""
        if seed is not None:
            self.np_random, _ = seeding.np_random(seed)
            self.sim.rngs[0] = self.np_random
        else:
            self.np_random = self.sim.rngs[0]
        obs = self.sim.reset(seeds=[None])
        self.agents = list(self.possible_agents)
        if self.render_mode == "human":
            self.render()
        return self._observations(obs), self._infos()

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Apply one action per live agent for one control period ``dt``.

        Raises:
            ValueError: Missing or extra agent, wrong shape, non-finite action;
                nothing is changed.
            RuntimeError: Step after the episode ended, or a non-finite state (a bug).
        """
        if not self.agents:
            raise RuntimeError("the episode is over (or never started); call reset().")
        batch = self._action_batch(actions)
        obs = self.sim.step(batch)
        a = self.sim.arrays
        terminated = bool(a.terminated[0])
        truncated = bool(self.sim.truncated[0])
        rewards = {agent: float(a.reward[0, i]) for i, agent in enumerate(self.agents)}
        observations = self._observations(obs)
        terminations = dict.fromkeys(self.agents, terminated)
        truncations = dict.fromkeys(self.agents, truncated)
        infos = self._infos()
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _action_batch(self, actions: dict[str, Any]) -> NDArray[np.float64]:
        """Validate the action dict and stack it as (1, n, 4 + m) before any state changes."""
        if not isinstance(actions, dict):
            raise ValueError(
                f"actions must be a dict agent -> array, got {type(actions).__name__}."
            )
        missing = [agent for agent in self.agents if agent not in actions]
        extra = [agent for agent in actions if agent not in self.agents]
        if missing or extra:
            raise ValueError(
                f"actions must have exactly one entry per live agent: missing {missing}, "
                f"unexpected {extra}."
            )
        batch = np.empty((1, self.scenario.n, self.sim.act_dim))
        for agent in self.agents:
            action = np.asarray(actions[agent], dtype=np.float64)
            if action.shape != (self.sim.act_dim,):
                raise ValueError(
                    f"action of {agent} has shape {action.shape}; expected ({self.sim.act_dim},) "
                    "= [tau_u, tau_v, tau_r, theta_dot, message...]."
                )
            if not np.all(np.isfinite(action)):
                raise ValueError(f"action of {agent} is not finite: {action.tolist()}.")
            batch[0, self._index[agent]] = action
        return batch

    def _observations(self, obs: NDArray[np.float32]) -> dict[str, NDArray[np.float32]]:
        return {agent: obs[0, i].copy() for i, agent in enumerate(self.possible_agents)}

    def _infos(self) -> dict[str, dict[str, Any]]:
        a = self.sim.arrays
        infos = {}
        for i, agent in enumerate(self.possible_agents):
            infos[agent] = {
                "path_error": float(a.errors[0, i, kernels.ERR_PATH]),
                "heading_error": float(a.errors[0, i, kernels.ERR_HEADING]),
                "sync_error": float(a.errors[0, i, kernels.ERR_SYNC]),
                "speed_error": float(a.errors[0, i, kernels.ERR_SPEED]),
                "tau_command": a.tau_command[0, i].copy(),
                "tau_applied": a.tau_applied[0, i].copy(),
                "saturated": a.tau_command[0, i] != a.tau_applied[0, i],
                "eta": a.eta[0, i].copy(),
                "nu": a.nu[0, i].copy(),
                "theta": float(a.theta[0, i]),
                "reward_terms": dict(zip(REWARD_TERMS, a.reward_terms[0, i].tolist(), strict=True)),
            }
        return infos

    def state(self) -> NDArray[np.float32]:
        """Global state (n * 10,): per vessel eta (3), nu (3), theta, tau_applied (3)."""
        a = self.sim.arrays
        per_vessel = np.concatenate(
            [a.eta[0], a.nu[0], a.theta[0][:, None], a.tau_applied[0]], axis=1
        )
        return per_vessel.reshape(-1).astype(np.float32)

    def render(self) -> NDArray[np.uint8] | None:
        """Top-down view: paths, vessels, virtual targets; see ``cpf_env.render``."""
        return self._views.draw(self.sim, fleet=0)

    def close(self) -> None:
        """Close the render window, if any (idempotent)."""
        self._views.close()
