"""Single-agent Gymnasium views of the fleet: one controller commands every vessel.

============  ==================================================================
Env           ``CentralizedFleetEnv``; vector form ``CentralizedFleetVectorEnv``
Action        ``Box(n (4 + m))`` float32: per vessel [tau_u, tau_v, tau_r, theta_dot, msg...]
Observation   ``Box(n obs_dim)`` float32: the n local observations, concatenated
Ids           ``cpf_env/CentralizedFleet-v0``, ``cpf_env/CentralizedFleet-<scenario>-v0``
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

from cpf_env.envs.parallel import as_seed, check_reset_options, make_scenario
from cpf_env.envs.views import FleetViews, check_render_mode
from cpf_env.scenarios import Scenario, list_scenarios
from cpf_env.sim import arrays
from cpf_env.sim.fleet import FleetSim, as_real_actions
from cpf_env.sim.observation import observation_box

__all__ = [
    "GYM_ID",
    "PETTINGZOO_ID",
    "CentralizedFleetEnv",
    "CentralizedFleetVectorEnv",
    "register_envs",
    "scenario_id",
]

GYM_ID = "cpf_env/CentralizedFleet-v0"
PETTINGZOO_ID = "cpf_env/cooperative_path_following-v0"
_RENDER_FPS = 20  # default; instances use 1 / dt


def _fleet_spaces(
    scenario: Scenario, obs_dim: int
) -> tuple[spaces.Box[np.float32], spaces.Box[np.float32]]:
    """Observation and action space of one fleet (the ParallelEnv's, vessel after vessel)."""
    n, m = scenario.n, scenario.message_size
    tau_min, tau_max = scenario.tau_limits
    rate = np.full((n, 1), scenario.theta_dot_max)
    message = np.full((n, m), scenario.message_max)
    low = np.hstack([tau_min, -rate, -message]).reshape(-1)
    high = np.hstack([tau_max, rate, message]).reshape(-1)
    return (
        observation_box(n * obs_dim),
        spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32),
    )


def _as_actions(sim: FleetSim, actions: ArrayLike, batched: bool) -> NDArray[np.float64]:
    """Check flat actions, (n act_dim,) or (B, n act_dim), and return (B, n, act_dim) float64."""
    array = as_real_actions(actions)  # a copy: callers may edit the batch
    shape = (sim.num_fleets, sim.n * sim.act_dim) if batched else (sim.n * sim.act_dim,)
    if array.shape != shape:
        raise ValueError(
            f"action must have shape {shape} (n vessels x [tau_u, tau_v, tau_r, theta_dot, "
            f"message x {sim.act_dim - 4}] = {sim.n} x {sim.act_dim}), got {array.shape}."
        )
    return sim.validate_actions(array.reshape(sim.num_fleets, sim.n, sim.act_dim))


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

    ``path_error``, ``heading_error``, ``sync_error``, ``speed_error``: arrays (n,)
    after the step (or at reset), in m, rad, ~m and m/s.

    ## Arguments

    ``scenario`` (a name from ``cpf_env.scenarios.list_scenarios()`` or a
    ``Scenario``), ``render_mode`` (``"human"`` or ``"rgb_array"``) and any
    ``Scenario`` field as an override, e.g.
    ``gymnasium.make("cpf_env/CentralizedFleet-v0", scenario="lossy_links", max_steps=500)``.

    ## Example

    >>> import gymnasium, cpf_env
    >>> env = gymnasium.make("cpf_env/CentralizedFleet-v0", max_steps=10)
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
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.scenario = make_scenario(scenario, **overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.dt}
        self.sim = FleetSim(self.scenario, num_fleets=1)
        self.observation_space, self.action_space = _fleet_spaces(self.scenario, self.sim.obs_dim)
        self._views = FleetViews(self.scenario, render_mode)
        self._done = True

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Start an episode; ``seed`` fixes initial state, models and all noise. No options."""
        check_reset_options(options)
        super().reset(seed=as_seed(seed))
        self.sim.rngs[0] = self.np_random  # one generator: the simulator draws from np_random
        obs = self.sim.reset(seeds=[None])
        self._done = False
        if self.render_mode == "human":
            self.render()
        return obs[0].reshape(-1).copy(), self._info()

    def step(
        self, action: ArrayLike
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        """Apply every vessel's command for one control period ``dt``.

        Raises:
            ValueError: Wrong shape or a non-finite entry; nothing is changed.
            RuntimeError: Step before reset or after the episode ended.
        """
        if self._done:
            raise RuntimeError("the episode is over (or never started); call reset().")
        batch = _as_actions(self.sim, action, batched=False)
        obs = self.sim.step(batch)
        a = self.sim.arrays
        terminated = bool(a.terminated[0])
        truncated = bool(self.sim.truncated[0])
        self._done = terminated or truncated
        if self.render_mode == "human":
            self.render()
        reward = float(a.reward[0].mean())
        return obs[0].reshape(-1).copy(), reward, terminated, truncated, self._info()

    def _info(self) -> dict[str, Any]:
        errors = self.sim.arrays.errors[0]
        return {name: errors[:, k].copy() for name, k in arrays.ERROR_KEYS}

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
    ``reset(seed=s)`` seeds sub-environment k with s + k, so it reproduces
    ``CentralizedFleetEnv`` reset with seed s + k bit for bit, as ``SyncVectorEnv``.

    Autoreset is ``AutoresetMode.NEXT_STEP`` (Gymnasium's default): the step that
    ends an episode returns its last observation; on the next ``step`` that
    sub-environment ignores its action (which must still be finite), is reset
    (its generator continues, as in ``reset()`` without seed) and returns the
    reset observation with reward 0 and terminated = truncated = False.
    Underneath, the finished fleet takes one zero-action step with the others,
    then is reset.

    Infos hold the four error arrays of ``CentralizedFleetEnv`` stacked to
    (num_envs, n), each with its ``_name`` mask (all True).

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
        num_envs: int = 1,
        scenario: str | Scenario = "wang2014",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.scenario = make_scenario(scenario, **overrides)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.dt}
        self.sim = FleetSim(self.scenario, num_fleets=num_envs)
        self.num_envs = self.sim.num_fleets
        single_obs, single_act = _fleet_spaces(self.scenario, self.sim.obs_dim)
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
                seed (or None) per sub-environment.
            options: None (no options are supported).
        """
        check_reset_options(options)
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
            seed = [int(seed) + k for k in range(self.num_envs)]
        obs = self.sim.reset(seeds=seed)  # checks one seed per fleet
        self._autoreset[:] = False
        return obs.reshape(self.num_envs, -1).copy(), self._infos()

    def step(
        self, actions: ArrayLike
    ) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], Any]:
        """Step every fleet; fleets that ended on the previous step are reset instead.

        Raises:
            ValueError: Wrong shape or a non-finite entry; nothing is changed.
            RuntimeError: Step before reset, or the plant diverged (see ``FleetSim.step``).
        """
        batch = _as_actions(self.sim, actions, batched=True)
        restart = self._autoreset.copy()
        batch[restart] = 0.0
        obs = self.sim.step(batch)
        a = self.sim.arrays
        terminated = a.terminated.copy()
        truncated = self.sim.truncated.copy()
        rewards = a.reward.mean(axis=1)
        if restart.any():
            obs = self.sim.reset(fleets=np.flatnonzero(restart))
            rewards[restart] = 0.0
            terminated[restart] = False
            truncated[restart] = False
        self._autoreset = terminated | truncated
        infos = self._infos()
        return obs.reshape(self.num_envs, -1).copy(), rewards, terminated, truncated, infos

    def _infos(self) -> dict[str, Any]:
        errors = self.sim.arrays.errors
        infos: dict[str, Any] = {}
        for name, k in arrays.ERROR_KEYS:
            infos[name] = errors[:, :, k].copy()
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


def scenario_id(scenario: str) -> str:
    """Gymnasium id of the centralized env preset to a named scenario."""
    return f"cpf_env/CentralizedFleet-{scenario}-v0"


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
