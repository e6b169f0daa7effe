"""``HistoryVecEnv``: each slot's input carries a short history of its own inputs and actions.

``HistoryVecEnv(venv, length)`` appends, to every slot's observation, its last
``length`` entries ``[own_{t-k}, action_{t-k}, valid]``, newest first
(``agents.envs.history.OwnHistory``, which ``agents.load_policy``'s policy keeps
the same way in evaluation).

Episode boundaries. When a slot's episode ends, the observation returned is
the first of the next episode, and its history is empty (all zero): nothing
leaks across episodes. Its ``terminal_observation`` gets the history of the
ended episode (up to and including the last action), so SB3 bootstraps the
truncated value on the input the policy would have seen.

Wrap below ``VecNormalize`` (the history is normalized with the rest), as
``cpf-train`` does with ``TrainConfig(history=H)``; the
``NeighbourSetEncoder``'s ``tail`` then counts the extras and the history
(``env.history.size``, ``agents.envs.history.history_size``).

Example:
    >>> from agents import FleetVecEnv
    >>> base = FleetVecEnv("wang2014", num_fleets=1, base_policy="nn_dsc", max_steps=20)
    >>> env = HistoryVecEnv(base, length=4)
    >>> env.reset().shape, env.history.size
    ((5, 114), 88)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from agents.envs.history import OwnHistory
from cpf_env.sim.observation import SLOTS, observation_box

__all__ = ["HistoryVecEnv"]


class HistoryVecEnv(VecEnvWrapper):
    """Append each slot's last ``length`` (own features, action, valid) entries to its input.

    Its ``history`` (an ``OwnHistory``) holds the entries and their layout: ``length``,
    ``own``, ``action_size``, ``entry_size`` and ``size`` (the floats appended).

    Args:
        venv: A vector env with Box observations (S, D) and Box actions (S, a).
        length: History entries H >= 1.
        own: Leading observation floats recorded per entry (default the 18
            own-vessel features); 1 <= own <= D.
    """

    def __init__(self, venv: VecEnv, length: int, own: int = SLOTS) -> None:
        obs_shape = venv.observation_space.shape
        act_shape = venv.action_space.shape
        if obs_shape is None or len(obs_shape) != 1 or act_shape is None or len(act_shape) != 1:
            raise ValueError("HistoryVecEnv needs flat Box observations and actions.")
        if not 1 <= own <= obs_shape[0]:
            raise ValueError(f"own must be in [1, {obs_shape[0]}] (observation floats), got {own}.")
        self.history = OwnHistory(venv.num_envs, length, own, int(act_shape[0]))
        super().__init__(venv, observation_space=observation_box(obs_shape[0] + self.history.size))
        self._last_obs = np.zeros((venv.num_envs, obs_shape[0]), dtype=np.float32)
        self._actions = np.zeros((venv.num_envs, self.history.action_size), dtype=np.float32)

    def reset(self) -> NDArray[np.float32]:
        """Reset every slot; histories start empty."""
        obs = self.venv.reset()
        assert isinstance(obs, np.ndarray)
        self.history.clear()
        self._last_obs = np.asarray(obs, dtype=np.float32).copy()
        return self.history.append_to(obs)

    def step_async(self, actions: NDArray[np.floating]) -> None:
        """Record the actions (S, a) taken on the last observations, and pass them on."""
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1).copy()
        self.venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        """Step, push the last (own, action) entry, and clear the histories of ended episodes."""
        obs, rewards, dones, infos = self.venv.step_wait()
        assert isinstance(obs, np.ndarray)
        self.history.push(self._last_obs, self._actions)
        for slot in np.flatnonzero(dones):
            terminal = infos[slot].get("terminal_observation")
            if terminal is not None:
                infos[slot]["terminal_observation"] = self.history.append_to(
                    np.asarray(terminal)[None], [slot]
                )[0]
            self.history.clear([slot])
        self._last_obs = np.asarray(obs, dtype=np.float32).copy()
        return self.history.append_to(obs), rewards, dones, infos
