"""Bases that act on whole batches only, run fleet by fleet for the learners' vector envs.

The vector envs (``agents.envs.vec_env.FleetVecEnv``, ``agents.envs.mixture_env``) restart
single fleets and then ask the base to act for them alone
(``act_batch(obs, fleets)``); ``mpc`` (and ``mpc_tuned``) acts for every
row it is given and refuses a subset. ``make_core`` (``agents.envs.resolve``), through which
``cpf-train`` and ``cpf-distill`` build their envs, runs the names of
``WHOLE_BATCH_BASES`` as a ``FleetwiseBase``: one instance per fleet.
Evaluation (``agents.load_policy``, ``cpf-bench``) acts for all fleets at once
and keeps the batched policy.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from baselines import DEPLOYABLE, MPCPolicy, make_policy
from cpf_env.envs.policy import FleetPolicy, fleet_mask
from cpf_env.scenarios import Scenario

__all__ = ["WHOLE_BATCH_BASES", "FleetwiseBase"]


def _innermost(cls: type[FleetPolicy]) -> type[FleetPolicy]:
    """The design a filter wraps (``inner``, through every layer), or ``cls`` itself."""
    while hasattr(cls, "inner"):
        cls = cls.inner
    return cls


#: Bases that act for every row they are given (no ``act_batch(obs, fleets)``): ``mpc`` and
#: every deployable design built on it (``mpc_tuned``, and it under the navigation filter,
#: the safety filter or both).
WHOLE_BATCH_BASES = tuple(
    name for name, cls in DEPLOYABLE.items() if issubclass(_innermost(cls), MPCPolicy)
)


class FleetwiseBase(FleetPolicy):
    """A base policy that acts on whole batches only, run as one instance per fleet.

    Each fleet has its own instance (B = 1); ``mpc``'s plans depend on the
    fleet's own episode alone, so the actions are bit for bit those of one
    batched instance (``tests/agents/test_fleetwise.py``). Slower than one
    batched call (B calls a step); for training only.

    Args:
        name: A policy name of ``baselines.DEPLOYABLE``.
        scenario: The scenario the fleets run.
        num_fleets: B.
        options: Options (gains) for ``baselines.make_policy``.
    """

    def __init__(
        self, name: str, scenario: Scenario, num_fleets: int, options: dict[str, Any] | None = None
    ) -> None:
        self._build = lambda: make_policy(name, scenario, **(options or {}))
        self.policies = [self._build() for _ in range(num_fleets)]
        first = self.policies[0]
        self.name, self.n, self.obs_dim = name, first.n, first.obs_dim
        self.act_dim, self.agents = first.act_dim, first.agents
        self.message_entries = first.message_entries
        self.diagnostics: dict[str, NDArray[np.float64]] = {}

    def act_batch(self, obs: Any, fleets: Any = None) -> NDArray[np.float64]:
        """Actions (rows, n, 4 + m) of all fleets, or of the listed ``fleets`` (index array).

        A whole batch of another size than the last starts that many fresh instances,
        as a batched policy starts fresh states (the input statistics of a learner's
        env are estimated on a batch of their own before its fleets run).
        """
        given = np.asarray(obs, dtype=np.float64)
        if fleets is None and given.shape[0] != len(self.policies):
            self.policies = [self._build() for _ in range(given.shape[0])]
        rows = range(len(self.policies)) if fleets is None else np.asarray(fleets).tolist()
        actions = [self.policies[k].act_batch(given[i : i + 1]) for i, k in enumerate(rows)]
        keys = self.policies[0].diagnostics.keys()
        self.diagnostics = {
            key: np.concatenate([self.policies[k].diagnostics[key] for k in rows]) for key in keys
        }
        return np.concatenate(actions)

    def reset(self, seed: int | None = None) -> None:
        """Forget every fleet's states."""
        for policy in self.policies:
            policy.reset(seed)

    def reset_fleets(self, fleets: Any) -> None:
        """Forget the states of the fleets in a (B,) mask or index list."""
        for k in np.flatnonzero(fleet_mask(fleets, len(self.policies))):
            self.policies[int(k)].reset()
