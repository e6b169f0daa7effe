"""The policy contract: what every policy of B fleets offers, analytic or learned, under one name.

``FleetPolicy`` is the one definition, in the lowest layer that needs it
(the episode core steps a base policy). It is both the contract every layer
checks (``isinstance(x, FleetPolicy)`` holds for any object with
``act_batch``, ``reset`` and ``diagnostics``, as a structural check) and the
base class that derives the PettingZoo and Stable-Baselines3 methods from
the batched core: ``baselines.AnalyticPolicy`` and ``agents.TrainedPolicy``
derive from it, ``agents.load_policy`` returns one, and the commands'
resolver (``cpf_commands.common.policies.resolve_policy``) accepts any
object that meets it.

A policy maps the local observations of B fleets to actions and keeps its
own internal states, one set per fleet:

- ``act_batch(obs, fleets=None) -> actions``: obs (B, n, obs_dim), actions
  (B, n, 4 + m) float64: force command (N, N, N m), path-variable rate
  theta_dot (1/s), message (m values). With ``fleets`` (an index array), obs
  holds only those fleets' rows and only their states advance;
- ``reset(seed=None)``: forget every fleet's states;
- ``diagnostics``: name -> (B, n, ...) arrays of the last ``act_batch`` (may
  be empty), e.g. ``speed_estimate``, ``nn_output``, ``aux_state``;
- optional ``name``: the label in tables and file names;
- optional ``message_entries``: how many leading message entries the policy
  writes (the rest it leaves zero); a residual learner's own messages
  (``cpf_env.envs.residual``) go after them. Absent: all m;
- ``reset_fleets(mask)``: forget the states of the fleets in a (B,) mask or
  index list (``fleet_mask`` reads either). Required only by batched routes
  that restart single fleets (``cpf_env.envs.core.EpisodeCore``), which say so
  when it is missing; so is ``act_batch``'s ``fleets`` argument. The
  commands call ``act_batch(obs)`` and ``reset(seed)`` only;
- optional ``bind_simulator(sim, fleets)``: a privileged reference
  (``baselines.privileged``, not deployable) reads the true state of the
  FleetSim fleets it acts for; the commands' rollout calls it when present.

Derived for subclasses: ``act(observations: dict) -> dict`` for the
PettingZoo ``ParallelEnv`` (B = 1) and ``predict(obs, state, episode_start,
deterministic)`` in the Stable-Baselines3 style, so
``stable_baselines3.common.evaluation.evaluate_policy`` runs it.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FleetPolicy", "fleet_mask"]

Array = NDArray[np.float64]


def fleet_mask(fleets: ArrayLike, num_fleets: int) -> NDArray[np.bool_]:
    """The (B,) bool mask of ``reset_fleets``' argument: a (B,) mask, or fleet indices.

    Args:
        fleets: A (B,) bool mask, or a 1-D list of indices in [0, B).
        num_fleets: B, the fleets the policy holds states for.

    Raises:
        ValueError: ``fleets`` is a mask of another length, or not indices in [0, B).
    """
    chosen = np.asarray(fleets)
    if chosen.dtype == bool:
        if chosen.shape != (num_fleets,):
            raise ValueError(
                f"fleets must be a bool mask of shape ({num_fleets},), one entry per fleet "
                f"the policy holds states for, or indices; got a mask of shape {chosen.shape}."
            )
        return chosen.copy()
    if chosen.size == 0:
        return np.zeros(num_fleets, dtype=bool)
    if (
        chosen.ndim != 1
        or not np.issubdtype(chosen.dtype, np.integer)
        or np.any((chosen < 0) | (chosen >= num_fleets))
    ):
        raise ValueError(
            f"fleets must be indices in [0, {num_fleets}) of the fleets the policy holds "
            f"states for, or a ({num_fleets},) bool mask; got {chosen.tolist()!r}."
        )
    mask = np.zeros(num_fleets, dtype=bool)
    mask[chosen] = True
    return mask


#: What an object needs to meet the contract (``isinstance(x, FleetPolicy)``).
_REQUIRED = ("act_batch", "reset", "diagnostics")


class _Contract(abc.ABCMeta):
    """ABCMeta whose ``isinstance`` also accepts any object that has ``_REQUIRED``."""

    def __instancecheck__(cls, instance: object) -> bool:
        if super().__instancecheck__(instance):
            return True
        return cls is FleetPolicy and all(hasattr(instance, name) for name in _REQUIRED)


class FleetPolicy(abc.ABC, metaclass=_Contract):
    """A policy of B fleets (see the module docstring for the whole contract).

    Subclasses set ``name`` (a label), ``n`` (vessels), ``obs_dim``, ``act_dim``
    (4 + m), ``agents`` (``vessel_0`` ...) and ``diagnostics`` (name -> (B, n, ...)
    arrays of the last ``act_batch``), and implement the abstract methods;
    ``act`` and ``predict`` come from ``act_batch``.
    """

    n: int
    obs_dim: int
    act_dim: int
    message_entries: int
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
