"""The interface every policy offers, analytic or learned, and the plumbing derived from it.

A policy maps local observations of B fleets to actions and keeps its own
internal states, one set per fleet. Subclasses give the batched core; this
class derives the rest:

- ``act_batch(obs (B, n, obs_dim), fleets=None) -> (B, n, 4 + m)``: the core;
- ``reset(seed=None)`` / ``reset_fleets(mask)``: forget all / some fleets' states;
- ``act(observations: dict) -> dict`` for the PettingZoo ``ParallelEnv`` (B = 1);
- ``predict(obs, state, episode_start, deterministic)`` in the Stable-Baselines3
  style, so ``stable_baselines3.common.evaluation.evaluate_policy`` runs it.

This is the base class of the policy contract ``cpf_env.envs.policy.FleetPolicy``
(documented there once: shapes, units, the optional members). Trained agents
(``agents.load_policy``) derive from it too, so every command evaluates
analytic and learned policies through the same code.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PolicyInterface"]

Array = NDArray[np.float64]


class PolicyInterface(abc.ABC):
    """Base of every policy: ``act`` and ``predict`` from ``act_batch``.

    Subclasses set ``name`` (a label), ``n`` (vessels), ``obs_dim``, ``act_dim``
    (4 + m), ``agents`` (``vessel_0`` ...) and ``diagnostics`` (name -> (B, n, ...)
    arrays of the last ``act_batch``), and implement the abstract methods.
    """

    n: int
    obs_dim: int
    act_dim: int
    agents: list[str]
    diagnostics: dict[str, Array]

    @abc.abstractmethod
    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> Array:
        """Actions (rows, n, 4 + m) float64 of B fleets (or of the listed ``fleets``)."""

    @abc.abstractmethod
    def reset(self, seed: int | None = None) -> None:
        """Forget all internal states; they restart on the next act."""

    @abc.abstractmethod
    def reset_fleets(self, fleets: ArrayLike) -> None:
        """Forget the internal states of the fleets in a (B,) mask (or index list)."""

    def act(self, observations: Mapping[str, ArrayLike]) -> dict[str, NDArray[np.float64]]:
        """Actions for the ParallelEnv: one float64 array (4 + m,) per agent.

        float64, not the action space's float32: the env applies float64 commands
        exactly, so a loop over ``env.step(policy.act(obs))`` follows the same
        trajectory as ``FleetSim`` driven by ``act_batch``, bit for bit (rounding
        to float32 would move the fleet by about 1e-11 m per step;
        ``docs/environment.md``, "Precision").

        Raises:
            ValueError: Missing or unexpected agents, or a bad observation.
        """
        missing = [agent for agent in self.agents if agent not in observations]
        extra = [agent for agent in observations if agent not in self.agents]
        if missing or extra:
            raise ValueError(
                f"observations must have one entry per vessel {self.agents}: missing {missing}, "
                f"unexpected {extra}."
            )
        actions = self.act_batch(np.stack([np.asarray(observations[a]) for a in self.agents])[None])
        return {a: actions[0, i].copy() for i, a in enumerate(self.agents)}

    def predict(
        self,
        observation: ArrayLike,
        state: object = None,
        episode_start: ArrayLike | None = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[np.float32], None]:
        """Stable-Baselines3-style prediction over any of four layouts.

        Accepted ``observation`` layouts and the matching action layouts:

        - (n * obs_dim,) one fleet, local observations concatenated -> (n * act_dim,);
        - (N, n * obs_dim) one fleet per row (centralized view) -> (N, n * act_dim);
        - (B * n, obs_dim) one vessel per row, a fleet's vessels consecutive -> (B * n, act_dim);
        - (B, n, obs_dim) -> (B, n, act_dim).

        Args:
            observation: Observations in one of the layouts above.
            state: Ignored (SB3 recurrent state); the internal states are the policy's own.
            episode_start: Bool per row (per fleet, or per vessel row): True resets
                the internal states of that fleet before acting. All True resets
                everything (the batch size may then change).
            deterministic: Ignored by the analytic policies (they are deterministic);
                trained agents act on their mean action either way.

        Returns:
            (actions float32 in the matching layout, None).
        """
        del state, deterministic
        batch, restore = self._to_batch(np.asarray(observation))
        if episode_start is not None:
            self._episode_start(np.asarray(episode_start, dtype=bool).reshape(-1), batch.shape[0])
        return restore(self.act_batch(batch)).astype(np.float32), None

    def _episode_start(self, starts: NDArray[np.bool_], num_fleets: int) -> None:
        """Reset the fleets flagged in ``starts`` (one flag per fleet or per vessel row)."""
        if starts.shape[0] == num_fleets * self.n:
            starts = np.any(starts.reshape(num_fleets, self.n), axis=1)
        elif starts.shape[0] != num_fleets:
            raise ValueError(
                f"episode_start must have one flag per fleet ({num_fleets}) or per vessel "
                f"row ({num_fleets * self.n}), got {starts.shape[0]}."
            )
        if starts.all():
            self.reset()
        elif starts.any():
            self.reset_fleets(starts)

    def _to_batch(self, obs: NDArray[Any]) -> tuple[Array, Callable[[Array], Array]]:
        """Bring a ``predict`` layout to (B, n, obs_dim) and return the inverse map for actions."""
        n, d, a = self.n, self.obs_dim, self.act_dim
        if obs.shape == (n * d,):
            return obs.reshape(1, n, d), lambda act: act.reshape(n * a)
        if obs.ndim == 2 and obs.shape[1] == n * d:
            rows = obs.shape[0]
            return obs.reshape(rows, n, d), lambda act: act.reshape(rows, n * a)
        if obs.ndim == 2 and obs.shape[1] == d and obs.shape[0] % n == 0:
            rows = obs.shape[0]
            return obs.reshape(rows // n, n, d), lambda act: act.reshape(rows, a)
        if obs.ndim == 3:
            return obs, lambda act: act
        raise ValueError(
            f"predict accepts observations of shape (n*obs_dim,) = ({n * d},), (N, {n * d}), "
            f"(B*n, {d}) with rows a multiple of n = {n}, or (B, {n}, {d}); got {obs.shape}."
        )
