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
from gymnasium.utils import seeding
from numpy.typing import NDArray
from pettingzoo import ParallelEnv

from cpf_env import scenarios
from cpf_env.envs.views import FleetViews, check_render_mode
from cpf_env.scenarios import Scenario
from cpf_env.sim import arrays
from cpf_env.sim.fleet import FleetSim, as_real_actions
from cpf_env.sim.observation import ObsLayout, observation_box

__all__ = [
    "INFO_LEVELS",
    "CooperativePathFollowingEnv",
    "as_seed",
    "check_reset_options",
    "make_scenario",
    "warn_reset_options",
]


#: Detail levels of the per-step infos, most to least: every diagnostic, the
#: four errors, nothing. Wrappers that convert every info entry to a tensor each
#: step (TorchRL's, RLlib's) spend much of their time there; take less for speed.
INFO_LEVELS = ("full", "minimal", "none")


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


def as_seed(seed: object) -> int | None:
    """A reset seed as Gymnasium's seeding wants it: None or a python int (numpy ints welcome)."""
    if isinstance(seed, np.integer):
        return int(seed)
    return seed  # type: ignore[return-value]  # anything else: Gymnasium's own check raises


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

    ``scenario`` (name or ``Scenario``), ``render_mode`` (``"human"`` or
    ``"rgb_array"``), ``max_cycles`` (PettingZoo's name for the episode
    length: sets ``max_steps``; give one of the two), ``info_level``
    (``"full"``, the default: every diagnostic; ``"minimal"``: the four
    errors; ``"none"``: empty dicts, for wrappers that convert infos to
    tensors each step) and any ``Scenario`` field as an override. ``render``
    also accepts RLlib's positional mode if it equals ``render_mode``.
    ``reset`` takes a seed (python or numpy int); it has
    no options and warns if given some.

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
        info_level: str = "full",
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        if info_level not in INFO_LEVELS:
            raise ValueError(
                f"info_level must be one of {INFO_LEVELS}, got {info_level!r}: 'full' "
                "for all diagnostics, 'minimal' for the four errors, 'none' for empty infos."
            )
        self.info_level = info_level
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
        self.sim = FleetSim(self.scenario, num_fleets=1)
        self.layout: ObsLayout = self.sim.layout
        self.possible_agents = [f"vessel_{i}" for i in range(self.scenario.n)]
        self.agents: list[str] = []
        self._index = {agent: i for i, agent in enumerate(self.possible_agents)}
        self._views = FleetViews(self.scenario, render_mode)
        self.np_random, _ = seeding.np_random()
        # per-instance caches: a class-level functools.cache would keep every env alive
        self._observation_spaces: dict[str, spaces.Box] = {}
        self._action_spaces: dict[str, spaces.Box] = {}

    def observation_space(self, agent: str) -> spaces.Box:
        """Local observation space of ``agent`` (the same object on every call)."""
        if agent not in self._observation_spaces:
            self._check_agent(agent)
            self._observation_spaces[agent] = observation_box(self.layout.size)
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """Action space of ``agent`` (the same object on every call): forces, rate, message."""
        if agent not in self._action_spaces:
            self._action_spaces[agent] = self._make_action_space(agent)
        return self._action_spaces[agent]

    def _make_action_space(self, agent: str) -> spaces.Box:
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
            UserWarning: (a warning) for any ``options``: this env takes none and
                ignores them (PettingZoo's API test passes some, so it cannot raise).
        """
        warn_reset_options(options)
        seed = as_seed(seed)
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
            ValueError: Missing or extra agent, wrong shape, complex or non-finite
                action; nothing is changed.
            RuntimeError: Step after the episode ended, or the plant diverged (the
                message says where and what to change; the episode is then over).
        """
        if not self.agents:
            raise RuntimeError("the episode is over (or never started); call reset().")
        batch = self._action_batch(actions)
        try:
            obs = self.sim.step(batch)
        except RuntimeError:
            self.agents = []  # no live agents over a diverged (NaN) state
            raise
        a = self.sim.arrays
        terminated = bool(a.terminated[0])
        truncated = bool(self.sim.truncated[0])
        rewards = dict(zip(self.agents, a.reward[0].tolist(), strict=False))
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
        if actions.keys() != set(self.agents):
            missing = [agent for agent in self.agents if agent not in actions]
            extra = [agent for agent in actions if agent not in self.agents]
            raise ValueError(
                f"actions must have exactly one entry per live agent: missing {missing}, "
                f"unexpected {extra}."
            )
        batch = np.empty((1, self.scenario.n, self.sim.act_dim))
        shape = (self.sim.act_dim,)
        for agent in self.agents:  # the cheap checks of check_action; the rest on the batch
            array = np.asarray(actions[agent])
            if array.dtype.kind not in "biuf" or array.shape != shape:
                return self._checked_batch(actions)
            batch[0, self._index[agent]] = array
        if not np.isfinite(batch).all():
            return self._checked_batch(actions)
        return batch

    def _checked_batch(self, actions: dict[str, Any]) -> NDArray[np.float64]:
        """The batch built with ``check_action`` per agent, which raises on the first bad one."""
        batch = np.empty((1, self.scenario.n, self.sim.act_dim))
        for agent in self.agents:
            batch[0, self._index[agent]] = self.check_action(agent, actions[agent])
        return batch

    def check_action(self, agent: str, action: Any) -> NDArray[np.float64]:
        """Validate one agent's action and return it as float64 (4 + m,); changes nothing.

        Raises:
            ValueError: Unknown agent, wrong shape, a complex or non-finite entry.
        """
        self._check_agent(agent)
        array = as_real_actions(action, f"action of {agent}")
        if array.shape != (self.sim.act_dim,):
            raise ValueError(
                f"action of {agent} has shape {array.shape}; expected ({self.sim.act_dim},) "
                "= [tau_u, tau_v, tau_r, theta_dot, message...]."
            )
        if not np.all(np.isfinite(array)):
            raise ValueError(f"action of {agent} is not finite: {array.tolist()}.")
        return array

    def _observations(self, obs: NDArray[np.float32]) -> dict[str, NDArray[np.float32]]:
        """Each agent's row of one copy of ``obs[0]`` (no later step writes to it)."""
        return dict(zip(self.possible_agents, obs[0].copy(), strict=True))

    def _infos(self) -> dict[str, dict[str, Any]]:
        """Per-agent infos at the detail level ``self.info_level``.

        Array entries are rows of one copy per quantity and step, so no later step
        writes to them.
        """
        if self.info_level == "none":
            return {agent: {} for agent in self.possible_agents}
        a = self.sim.arrays
        errors = a.errors[0].tolist()
        infos = {
            agent: {key: row[k] for key, k in arrays.ERROR_KEYS}
            for agent, row in zip(self.possible_agents, errors, strict=True)
        }
        if self.info_level == "minimal":
            return infos
        tau_command, tau_applied = a.tau_command[0].copy(), a.tau_applied[0].copy()
        saturated = tau_command != tau_applied
        eta, nu, theta = a.eta[0].copy(), a.nu[0].copy(), a.theta[0].tolist()
        reward_terms = a.reward_terms[0].copy()
        for i, agent in enumerate(self.possible_agents):
            infos[agent] |= {
                "tau_command": tau_command[i],
                "tau_applied": tau_applied[i],
                "saturated": saturated[i],
                "eta": eta[i],
                "nu": nu[i],
                "theta": theta[i],
                "reward_terms": reward_terms[i],
            }
        return infos

    def state(self) -> NDArray[np.float32]:
        """Global state (n * 10,): per vessel eta (3), nu (3), theta, tau_applied (3)."""
        a = self.sim.arrays
        per_vessel = np.concatenate(
            [a.eta[0], a.nu[0], a.theta[0][:, None], a.tau_applied[0]], axis=1
        )
        return per_vessel.reshape(-1).astype(np.float32)

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
