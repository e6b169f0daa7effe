"""Single-agent Gymnasium views of the fleet: one controller commands every vessel.

============  ==================================================================
Env           ``CentralizedFleetEnv``; vector form ``CentralizedFleetVectorEnv``
Action        ``Box(n (4 + m))`` float32: per vessel [tau_u, tau_v, tau_r, theta_dot, msg...]
Observation   ``Box(n obs_dim)`` float32: the n local observations, concatenated
Ids           ``cpf_env/CentralizedFleet-v0``, ``cpf_env/CentralizedFleet-<scenario>-vN``
PettingZoo    ``cpf_env/cooperative_path_following-v0`` ("parallel" and "aec")
============  ==================================================================
"""

from __future__ import annotations

from typing import Any, cast

import gymnasium
import numpy as np
import pettingzoo
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from cpf_env.envs.core import DEFAULT_INFO_LEVEL, EpisodeCore, check_info_level
from cpf_env.envs.parallel import check_reset_options
from cpf_env.envs.policy import FleetPolicy
from cpf_env.envs.residual import ResidualConfig
from cpf_env.envs.views import FleetViews, check_render_mode
from cpf_env.scenarios import Scenario, list_scenarios, make_scenario
from cpf_env.sim.observation import observation_box

__all__ = [
    "GYM_ID",
    "ID_VERSIONS",
    "PETTINGZOO_ID",
    "CentralizedFleetEnv",
    "CentralizedFleetVectorEnv",
    "register_envs",
    "scenario_id",
]

GYM_ID = "cpf_env/CentralizedFleet-v0"
PETTINGZOO_ID = "cpf_env/cooperative_path_following-v0"
_RENDER_FPS = 20  # default; instances use 1 / dt


def _fleet_spaces(core: EpisodeCore) -> tuple[spaces.Box[np.float32], spaces.Box[np.float32]]:
    """Observation and action space of one fleet (the ParallelEnv's, vessel after vessel)."""
    low, high = core.action_bounds()
    return (
        observation_box(core.n * core.input_size),
        spaces.Box(low.reshape(-1), high.reshape(-1), dtype=np.float32),
    )


def _as_actions(core: EpisodeCore, actions: ArrayLike, batched: bool) -> NDArray[Any]:
    """Flat actions, (n a,) or (B, n a), checked whole and returned as (B, n, a) float64."""
    array = np.asarray(actions)
    per_fleet = core.n * core.action_size
    shape = (core.num_fleets, per_fleet) if batched else (per_fleet,)
    if array.shape != shape:
        raise ValueError(
            f"action must have shape {shape} (n vessels x {core.action_size} = {core.n} x "
            f"{core.action_size}: [tau_u, tau_v, tau_r, theta_dot, message...] raw, the "
            f"correction in [-1, 1] residual), got {array.shape}."
        )
    return core.check_actions(array.reshape(core.num_fleets, core.n, core.action_size))


class CentralizedFleetEnv(gymnasium.Env[NDArray[np.float32], NDArray[np.float32]]):
    """The whole fleet as one agent: observe every vessel, command every vessel.

    ## Description

    The cooperative path-following task of ``cpf_env.envs.parallel`` (n surface vessels
    each follow their path eta_d(theta_i) while synchronizing theta_i and
    advancing it at the leader's speed v0) under a central controller. It is
    the same simulator as the ParallelEnv (``FleetSim`` with one fleet); only
    the interface differs. Useful as a single-agent RL baseline and for
    controllers that are allowed global information.

    ## Action Space

    ``Box(n (4 + m))`` float32: vessel i owns ``action[i (4 + m) : (i + 1) (4 + m)]``:

    | idx in block | name | unit | bounds |
    |---|---|---|---|
    | 0-2 | tau0: surge, sway force; yaw moment | N, N, N m | [tau_min_i, tau_max_i] (*) |
    | 3 | theta_dot_i, rate of the path variable | 1/s | +-theta_dot_max (clipped) |
    | 4.. | message to neighbours | - | +-message_max (clipped) |

    (*) Commands beyond the limits are allowed: the plant saturates them. The
    bounds are physical, so ``check_env`` recommends a normalized space; wrap
    with ``gymnasium.wrappers.RescaleAction(env, -1, 1)`` for that.

    ## Observation Space

    ``Box(n obs_dim)`` float32, ``obs_dim = 18 + K (3 + m)``: vessel i's local
    observation (table in ``cpf_env.sim.observation``; named slices in
    ``env.unwrapped.sim.layout``) at ``obs[i obs_dim : (i + 1) obs_dim]``:

    | idx in block | name | unit |
    |---|---|---|
    | 0-2 | nu = (u, v, r) | m/s, m/s, rad/s |
    | 3-5 | z1, body-frame path error | m, m, rad |
    | 6-11 | t1, t2: body-frame path derivatives | m, rad per unit theta (squared) |
    | 12 | theta_i | ~m |
    | 13-15 | applied (saturated) force | N, N, N m |
    | 16, 17 | b_i, v0 as heard (0 if b_i = 0) | -, m/s |
    | 18.. | K neighbour slots [a_ij, theta_j - theta_i, age, msg_j] | -, ~m, steps, - |

    The bounds are +-``OBS_BOUND`` (``cpf_env.sim.observation``): finite, the same rule as
    the ParallelEnv's, not a physical range (a non-finite state raises).

    ## Rewards

    The mean over vessels of the ParallelEnv's per-vessel reward (``cpf_env.sim.reward``);
    the mean, not the sum, keeps the scale independent of n and equals the team reward.

    ## Starting State

    Drawn from ``Scenario.initial`` with ``self.np_random`` (``wang2014``: the
    paper's fixed poses, at rest, theta = 0).

    ## Episode End

    Terminated when a vessel is farther than ``max_path_error`` from its path;
    truncated (and not terminated) after ``max_steps`` control steps of ``dt``.
    Step after the end raises ``RuntimeError``; call ``reset()``.

    ## Info

    At ``info_level="none"`` (the default) an empty dict; ``"minimal"``: ``path_error``,
    ``heading_error``, ``sync_error``, ``speed_error``, arrays (n,) after the step
    (or at reset), in m, rad, ~m and m/s; ``"full"``: every array of
    ``EpisodeCore.info_arrays`` for this fleet, (n, ...).

    ## Arguments

    The routes' shared arguments (``cpf_env.envs.core``): ``scenario`` (a name from
    ``cpf_env.scenarios.list_scenarios()`` or a ``Scenario``), ``info_level``,
    ``base_policy`` and ``residual`` (the residual form: the action is every
    vessel's correction in [-1, 1], the observation every vessel's learner
    input) and any ``Scenario`` field as an override, e.g.
    ``gymnasium.make("cpf_env/CentralizedFleet-v0", scenario="lossy_links", max_steps=500)``;
    plus Gymnasium's ``render_mode`` (``"human"`` or ``"rgb_array"``). One fleet:
    no ``num_fleets`` and no stagger.

    ## Example

    >>> import gymnasium, cpf_env
    >>> env = gymnasium.make("cpf_env/CentralizedFleet-v0", max_steps=10, info_level="minimal")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_space.shape
    ((130,), (25,))
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> info["path_error"].shape
    (5,)

    ## Version History

    * v0: initial release.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - Gymnasium's class-level convention
        "render_modes": ["human", "rgb_array"],
        "render_fps": _RENDER_FPS,
    }

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        render_mode: str | None = None,
        info_level: str = DEFAULT_INFO_LEVEL,
        base_policy: FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.info_level = check_info_level(info_level)
        self.scenario = make_scenario(scenario, **overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.dt}
        self.core = EpisodeCore(self.scenario, 1, base_policy, residual, stagger=False)
        self.sim = self.core.sim
        self.observation_space, self.action_space = _fleet_spaces(self.core)
        self._views = FleetViews(self.scenario, render_mode)
        self._done = True

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start an episode; ``seed`` (an integer >= 0) fixes everything drawn. No options."""
        check_reset_options(options)
        checked = self.core.fleet_seeds(seed, np.zeros(1, dtype=np.int64))[0]  # refuse first
        super().reset(seed=checked)
        self.sim.rngs[0] = self.np_random  # one generator: the simulator draws from np_random
        inputs = self.core.reset()
        self._done = False
        if self.render_mode == "human":
            self.render()
        return inputs[0].reshape(-1).copy(), self._info()

    def step(
        self, action: ArrayLike
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        """Apply every vessel's command (or correction) for one control period ``dt``.

        Raises:
            ValueError: Wrong shape, not real numbers or a non-finite entry; nothing changes.
            RuntimeError: Step before reset or after the episode ended.
        """
        if self._done:
            raise RuntimeError("the episode is over (or never started); call reset().")
        self.core.step(_as_actions(self.core, action, batched=False), checked=True)
        terminated = bool(self.core.terminated[0])
        truncated = bool(self.core.truncated[0])
        self._done = terminated or truncated
        if self.render_mode == "human":
            self.render()
        reward = float(self.core.reward[0].mean())
        obs = self.core.inputs[0].reshape(-1).copy()
        return obs, reward, terminated, truncated, self._info()

    def _info(self) -> dict[str, Any]:
        return {key: value[0] for key, value in self.core.info_arrays(self.info_level).items()}

    def render(self) -> NDArray[np.uint8] | None:
        """Top-down view of the fleet (see ``cpf_env.envs.render``); None in human mode."""
        return self._views.draw(self.sim, fleet=0)

    def close(self) -> None:
        """Close the render window, if any (idempotent)."""
        self._views.close()


class CentralizedFleetVectorEnv(VectorEnv[NDArray[np.float32], NDArray[np.float32], NDArray[Any]]):
    """``num_envs`` copies of ``CentralizedFleetEnv`` stepped as one batched ``FleetSim``.

    Spaces, rewards and episode ends are those of ``CentralizedFleetEnv``; fleet k
    of the simulator is sub-environment k (error messages say "fleet k").
    ``reset(seed=s)`` seeds sub-environment k with s + k (``EpisodeCore``), so it
    reproduces ``CentralizedFleetEnv`` reset with seed s + k bit for bit, as
    ``SyncVectorEnv``, up to the stagger: with ``stagger=True`` (the default of
    every batched route) each reset of all sub-environments truncates env k's
    episode after ``max_steps - k * max_steps // num_envs`` steps.

    Arguments: those of every route, ``(scenario, num_envs, ..., info_level,
    base_policy, residual, stagger, **overrides)``. Gymnasium forces the name
    ``num_envs`` for the number of fleets (``gymnasium.make_vec`` passes it).

    Autoreset is ``AutoresetMode.NEXT_STEP`` (Gymnasium's default): the step that
    ends an episode returns its last observation; on the next ``step`` that
    sub-environment ignores its action (which must still be finite), is reset
    (its generator continues, as in ``reset()`` without seed) and returns the
    reset observation with reward 0 and terminated = truncated = False.
    Underneath, the finished fleet takes one zero-action step with the others,
    then is reset.

    Infos hold the arrays of ``CentralizedFleetEnv``'s ``info_level`` stacked to
    (num_envs, n, ...), each with its ``_name`` mask (all True).

    Example:
        >>> import gymnasium, cpf_env
        >>> envs = gymnasium.make_vec("cpf_env/CentralizedFleet-v0", num_envs=4)
        >>> obs, infos = envs.reset(seed=0)
        >>> obs.shape
        (4, 130)
        >>> obs, rewards, terminations, truncations, infos = envs.step(envs.action_space.sample())
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - Gymnasium's class-level convention
        "render_modes": ["rgb_array"],
        "render_fps": _RENDER_FPS,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        scenario: str | Scenario = "wang2014",
        num_envs: int = 1,
        render_mode: str | None = None,
        info_level: str = DEFAULT_INFO_LEVEL,
        base_policy: FleetPolicy | None = None,
        residual: ResidualConfig | None = None,
        stagger: bool = True,
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.info_level = check_info_level(info_level)
        self.scenario = make_scenario(scenario, **overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.dt}
        self.core = EpisodeCore(self.scenario, num_envs, base_policy, residual, stagger)
        self.sim = self.core.sim
        self.num_envs = self.core.num_fleets
        single_obs, single_act = _fleet_spaces(self.core)
        self.single_observation_space, self.single_action_space = single_obs, single_act
        self.observation_space = batch_space(single_obs, self.num_envs)
        self.action_space = batch_space(single_act, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._views = FleetViews(self.scenario, render_mode)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Reset every sub-environment.

        Args:
            seed: None (generators continue), an int s (env k gets s + k) or one
                seed (or None) per sub-environment; checked whole before any is reset.
            options: None (no options are supported).
        """
        check_reset_options(options)
        seeds = self.core.fleet_seeds(seed, np.arange(self.num_envs))  # refuse before changes
        if isinstance(seed, int | np.integer):
            super().reset(seed=int(seed))
        inputs = self.core.reset(seeds=seeds)
        self._autoreset[:] = False
        return inputs.reshape(self.num_envs, -1).copy(), self._infos()

    def step(
        self, actions: ArrayLike
    ) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], Any]:
        """Step every fleet; fleets that ended on the previous step are reset instead.

        Raises:
            ValueError: Wrong shape, not real numbers or a non-finite entry; nothing changes.
            RuntimeError: Step before reset, or the plant diverged (see ``FleetSim.step``).
        """
        batch = _as_actions(self.core, actions, batched=True)
        restart = self._autoreset.copy()
        if restart.any():
            batch = batch.copy()  # not the caller's array
            batch[restart] = 0.0
        self.core.step(batch, checked=True)
        terminated, truncated = self.core.terminated, self.core.truncated
        rewards = self.core.reward.mean(axis=1)
        if restart.any():
            self.core.reset(fleets=np.flatnonzero(restart))
            rewards[restart] = 0.0
            terminated[restart] = False
            truncated[restart] = False
        self._autoreset = terminated | truncated
        obs = self.core.inputs.reshape(self.num_envs, -1).copy()
        return obs, rewards, terminated, truncated, self._infos()

    def _infos(self) -> dict[str, Any]:
        infos: dict[str, Any] = {}
        for name, value in self.core.info_arrays(self.info_level).items():
            infos[name] = value
            infos[f"_{name}"] = np.ones(self.num_envs, dtype=bool)
        return infos

    def render(self) -> tuple[NDArray[np.uint8], ...] | None:
        """One top-down frame per sub-environment (``render_mode="rgb_array"``)."""
        if self.render_mode is None:
            self._views.draw(self.sim)  # warns once
            return None
        frames = (self._views.draw(self.sim, fleet=k) for k in range(self.num_envs))
        return tuple(cast(NDArray[np.uint8], frame) for frame in frames)

    def close_extras(self, **kwargs: Any) -> None:
        """Close the renderers."""
        self._views.close()


#: Scenarios whose dynamics changed since their id was first registered -> their id's
#: version (the version policy of CHANGELOG.md): suite version 2 changed bench_switching;
#: hard-track version 2 made hard_large_fleet five crossing pairs; version 4 moved the
#: crossing pairs' formation (``hard.CROSSING_OFFSET``).
ID_VERSIONS = {
    "bench_switching": 1,
    "bench_switching_shift": 1,
    "hard_crossing": 1,
    "hard_crossing_shift": 1,
    "hard_large_fleet": 2,
    "hard_large_fleet_shift": 2,
}


def scenario_id(scenario: str) -> str:
    """Gymnasium id of the centralized env preset to a named scenario.

    The ``-vN`` suffix is ``ID_VERSIONS``'s (0 for a scenario that never
    changed); Gymnasium answers an older version's id by naming the current
    one.

    Example:
        >>> scenario_id("wang2014"), scenario_id("bench_switching")
        ('cpf_env/CentralizedFleet-wang2014-v0', 'cpf_env/CentralizedFleet-bench_switching-v1')
    """
    return f"cpf_env/CentralizedFleet-{scenario}-v{ID_VERSIONS.get(scenario, 0)}"


def register_envs() -> None:
    """Register the Gymnasium ids and the PettingZoo envs; calling again is a no-op.

    Gymnasium: ``GYM_ID`` (scenario from kwargs, default ``wang2014``) and
    ``scenario_id(name)`` for every scenario registered so far (call again
    after ``cpf_env.scenarios.register`` to add new ones); all with the vector
    entry point and no ``max_episode_steps`` (the env truncates at the
    scenario's ``max_steps``). PettingZoo: ``PETTINGZOO_ID`` as "parallel"
    (``cpf_env.parallel_env``) and "aec" (``cpf_env.env``).
    """
    presets: dict[str, dict[str, Any]] = {GYM_ID: {}}
    presets.update({scenario_id(name): {"scenario": name} for name in list_scenarios()})
    for env_id, kwargs in presets.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point="cpf_env.envs.gym_envs:CentralizedFleetEnv",
                vector_entry_point="cpf_env.envs.gym_envs:CentralizedFleetVectorEnv",
                kwargs=kwargs,
            )
    if PETTINGZOO_ID not in pettingzoo.parallel_registry:
        pettingzoo.register("parallel", PETTINGZOO_ID, "cpf_env:parallel_env")
    if PETTINGZOO_ID not in pettingzoo.aec_registry:
        pettingzoo.register("aec", PETTINGZOO_ID, "cpf_env:env")
