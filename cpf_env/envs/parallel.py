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
import warnings
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from cpf_env.envs.core import DEFAULT_INFO_LEVEL, EpisodeCore, check_info_level
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.views import FleetViews, check_render_mode
from cpf_env.scenarios import Scenario, make_scenario
from cpf_env.sim.fleet import check_seed
from cpf_env.sim.observation import ObsLayout, observation_box

__all__ = ["CooperativePathFollowingEnv", "check_reset_options", "warn_reset_options"]

_NO_OPTIONS = (
    "this env takes no reset options (the scenario fixes the task); change the scenario "
    "instead, e.g. parallel_env(scenario, max_steps=...) or Scenario.replace(...)"
)


def check_reset_options(options: dict[str, Any] | None) -> None:
    """Raise ``ValueError`` for any reset option (the Gymnasium views take none)."""
    if options:
        raise ValueError(f"reset takes no options, got {sorted(options)}: {_NO_OPTIONS}.")


def warn_reset_options(options: dict[str, Any] | None) -> None:
    """Warn that reset options are ignored (the PettingZoo envs must accept and take none).

    PettingZoo's ``api_test`` calls ``reset(seed=0, options={"options": 1})`` and
    requires it to succeed, so the PettingZoo forms warn where the Gymnasium
    views raise.
    """
    if options:
        warnings.warn(
            f"reset ignores options {sorted(options)}: {_NO_OPTIONS}.", UserWarning, stacklevel=3
        )


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

    (*) Commands beyond the limits are allowed: the plant saturates them
    (``docs/model.md``, "Input saturation").

    ## Observation Space

    ``Box(18 + K (3 + m))`` per vessel, float32; see ``cpf_env.sim.observation``
    for the table and ``self.layout`` (``ObsLayout``) for named slices. No other
    vessel's pose, and no v0 unless b_i = 1. Bounds +-``OBS_BOUND`` (finite, not
    physical; ``cpf_env.sim.observation``).

    ## Rewards

    A per-vessel sum of non-positive terms (path, heading, synchronization,
    speed, effort) with weights in ``Scenario.reward``, optionally shared as a
    team reward; the exact forms are in ``cpf_env.sim.reward`` and
    ``docs/environment.md``.

    ## Starting State

    Drawn from ``Scenario.initial`` with the reset seed (``wang2014``: the
    paper's fixed poses, at rest, theta = 0).

    ## Episode End

    Terminated for all vessels when one is farther than ``max_path_error`` from
    its path (latched until reset); truncated after ``max_steps`` control steps
    (``dt`` each). If the plant diverges (a non-finite state) ``step`` raises
    ``RuntimeError`` naming fleet, vessel and quantity, and the episode is over
    (``agents`` is empty): call ``reset()``.

    ## Arguments

    The routes' shared arguments (``cpf_env.envs.core``): ``scenario`` (name or
    ``Scenario``), ``info_level`` (``"none"``, the default of every route: empty
    dicts; ``"minimal"``: the four errors; ``"full"``: every diagnostic),
    ``base_policy`` and ``residual`` (a ``FleetPolicy`` object underneath and a
    ``ResidualConfig``: the agents then act through the bounded correction
    ``Box(-1, 1, (k,))`` and observe the learner's input, and the ``"full"``
    infos add ``base_command`` and ``residual``; neither: the raw command), and
    any ``Scenario`` field as an override. Differences PettingZoo forces: one
    fleet (no ``num_fleets``; stagger, which spreads fleets, has nothing to
    spread), ``render_mode``, and ``max_cycles`` (PettingZoo's name for the
    episode length: sets ``max_steps``; give one of the two). ``render`` also
    accepts RLlib's positional mode if it equals ``render_mode``. ``reset``
    takes a seed (an integer >= 0); it has no options and warns if given some.

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
        max_cycles: int | None = None,
        info_level: str = DEFAULT_INFO_LEVEL,
        base_policy: FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.info_level = check_info_level(info_level)
        if max_cycles is not None:
            if "max_steps" in overrides:
                raise ValueError(
                    "give the episode length once: max_cycles (PettingZoo's name) or "
                    f"max_steps, not both (got max_cycles={max_cycles!r}, "
                    f"max_steps={overrides['max_steps']!r})."
                )
            overrides["max_steps"] = max_cycles
        self.scenario = make_scenario(scenario, **overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.dt}
        self.core = EpisodeCore(self.scenario, 1, base_policy, residual, stagger=False)
        self.sim = self.core.sim
        self.layout: ObsLayout = self.sim.layout
        self.possible_agents = [f"vessel_{i}" for i in range(self.scenario.n)]
        self.agents: list[str] = []
        self._index = {agent: i for i, agent in enumerate(self.possible_agents)}
        self._views = FleetViews(self.scenario, render_mode)
        self.np_random = self.sim.rngs[0]
        # per-instance caches: a class-level functools.cache would keep every env alive
        self._observation_spaces: dict[str, spaces.Box] = {}
        self._action_spaces: dict[str, spaces.Box] = {}

    def observation_space(self, agent: str) -> spaces.Box:
        """Local observation (or learner input) space of ``agent`` (the same object each call)."""
        if agent not in self._observation_spaces:
            self._check_agent(agent)
            self._observation_spaces[agent] = observation_box(self.core.input_size)
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """Action space of ``agent`` (the same object each call): the command, or the correction."""
        if agent not in self._action_spaces:
            i = self._check_agent(agent)
            low, high = (bound[i] for bound in self.core.action_bounds())
            self._action_spaces[agent] = spaces.Box(low, high, dtype=np.float32)
        return self._action_spaces[agent]

    @functools.cached_property
    def state_space(self) -> spaces.Box:
        """Global state for a centralized critic: (eta, nu, theta, tau_applied) of every vessel."""
        return observation_box(self.scenario.n * 10)

    def _check_agent(self, agent: str) -> int:
        if agent not in self._index:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}.")
        return self._index[agent]

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, dict]]:
        """Start an episode; ``seed`` fixes initial state, models and all noise.

        Raises:
            ValueError: ``seed`` is not an integer >= 0 or None (nothing is changed).
            UserWarning: (a warning) for any ``options``: this env takes none and
                ignores them (PettingZoo's API test passes some, so it cannot raise).
        """
        seed = check_seed(seed)
        warn_reset_options(options)
        inputs = self.core.reset(seeds=[seed])
        self.np_random = self.sim.rngs[0]
        self.agents = list(self.possible_agents)
        if self.render_mode == "human":
            self.render()
        return self._observations(inputs), self._infos()

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Apply one action per live agent for one control period ``dt``.

        Raises:
            ValueError: Missing or extra agent, wrong shape, a bool, complex or
                non-finite action; nothing is changed.
            RuntimeError: Step after the episode ended, or the plant diverged (the
                message says where and what to change; the episode is then over).
        """
        if not self.agents:
            raise RuntimeError("the episode is over (or never started); call reset().")
        batch = self._action_batch(actions)
        try:
            self.core.step(batch, checked=True)
        except RuntimeError:
            self.agents = []  # no live agents over a diverged (NaN) state
            raise
        terminated = bool(self.core.terminated[0])
        truncated = bool(self.core.truncated[0])
        rewards = dict(zip(self.agents, self.core.reward[0].tolist(), strict=False))
        observations = self._observations(self.core.inputs)
        terminations = dict.fromkeys(self.agents, terminated)
        truncations = dict.fromkeys(self.agents, truncated)
        infos = self._infos()
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _action_batch(self, actions: dict[str, Any]) -> NDArray[np.float64]:
        """Validate the action dict and stack it as (1, n, a) before any state changes."""
        if not isinstance(actions, dict):
            raise ValueError(
                f"actions must be a dict agent -> array, got {type(actions).__name__}."
            )
        if actions.keys() != set(self.agents):
            missing = [agent for agent in self.agents if agent not in actions]
            extra = [agent for agent in actions if agent not in self.agents]
            raise ValueError(
                f"actions must have exactly one entry per live agent: missing {missing}, "
                f"unexpected {extra}."
            )
        batch = np.empty((1, self.scenario.n, self.core.action_size))
        shape = (self.core.action_size,)
        for agent in self.agents:  # the cheap checks of check_action; the rest on the batch
            array = np.asarray(actions[agent])
            if array.dtype.kind not in "iuf" or array.shape != shape:
                return self._checked_batch(actions)
            batch[0, self._index[agent]] = array
        if not np.isfinite(batch).all():
            return self._checked_batch(actions)
        return batch

    def _checked_batch(self, actions: dict[str, Any]) -> NDArray[np.float64]:
        """The batch built with ``check_action`` per agent, which raises on the first bad one."""
        batch = np.empty((1, self.scenario.n, self.core.action_size))
        for agent in self.agents:
            batch[0, self._index[agent]] = self.check_action(agent, actions[agent])
        return batch

    def check_action(self, agent: str, action: Any) -> NDArray[np.float64]:
        """Validate one agent's action and return it as float64 (a,); changes nothing.

        Raises:
            ValueError: Unknown agent, wrong shape, a bool, complex or non-finite entry.
        """
        self._check_agent(agent)
        array = np.asarray(action)
        if array.dtype.kind not in "iuf":
            raise ValueError(
                f"action of {agent} must be real numbers, got dtype {array.dtype}"
                + (" (bools are not commands)." if array.dtype.kind == "b" else ".")
            )
        shape = (self.core.action_size,)
        if array.shape != shape:
            form = "[tau_u, tau_v, tau_r, theta_dot, message...]"
            form = form if self.core.controller is None else "the correction in [-1, 1]"
            raise ValueError(
                f"action of {agent} has shape {array.shape}; expected {shape} = {form}."
            )
        checked = array.astype(np.float64)
        if not np.all(np.isfinite(checked)):
            raise ValueError(f"action of {agent} is not finite: {checked.tolist()}.")
        return checked

    def _observations(self, inputs: NDArray[np.float32]) -> dict[str, NDArray[np.float32]]:
        """Each agent's row of one copy of ``inputs[0]`` (no later step writes to it)."""
        return dict(zip(self.possible_agents, inputs[0].copy(), strict=True))

    def _infos(self) -> dict[str, dict[str, Any]]:
        """Per-agent infos at ``self.info_level`` (``EpisodeCore.vessel_infos`` of fleet 0)."""
        if self.info_level == "none":  # the hot path: no list to build and zip
            return {agent: {} for agent in self.possible_agents}
        infos = self.core.vessel_infos(self.info_level, fleet=0)
        return dict(zip(self.possible_agents, infos, strict=True))

    def state(self) -> NDArray[np.float32]:
        """Global state (n * 10,): per vessel eta (3), nu (3), theta, tau_applied (3)."""
        return self.core.state()[0]

    def render(self, mode: str | None = None) -> NDArray[np.uint8] | None:
        """Top-down view: paths, vessels, virtual targets; see ``cpf_env.envs.render``.

        Args:
            mode: Accepted for wrappers that still pass the pre-Gymnasium-0.26
                render mode (RLlib's ``ParallelPettingZooEnv`` calls
                ``render(self.render_mode)``); it must equal ``render_mode`` or be
                None. The mode is fixed at construction, as Gymnasium prescribes.

        Raises:
            ValueError: ``mode`` differs from the construction-time ``render_mode``.
            RuntimeError: Before the first ``reset()`` (there is no fleet to draw).
        """
        if mode is not None and mode != self.render_mode:
            raise ValueError(
                f"render mode {mode!r} differs from this env's render_mode "
                f"{self.render_mode!r}; the mode is fixed at construction: make the env "
                f"with render_mode={mode!r}."
            )
        return self._views.draw(self.sim, fleet=0)

    def close(self) -> None:
        """Close the render window, if any (idempotent)."""
        self._views.close()
