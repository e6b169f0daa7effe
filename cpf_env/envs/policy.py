"""The policy contract: what every policy of B fleets offers, analytic or learned.

This is the one definition. It lives in the lowest layer that needs it (the
residual composition of this package steps a base policy) and every other
layer uses it: ``baselines.interface.PolicyInterface`` is the base class that
implements it and derives the PettingZoo and Stable-Baselines3 methods from
it, ``agents.load_policy`` returns an implementation, and the commands'
resolver (``cpf_commands.common.policies.resolve_policy``) accepts any object
that has it.

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
- ``reset_fleets(mask)``: forget the states of the fleets in a (B,) mask or
  index list. Required only by batched vector envs that restart single
  fleets (``agents.FleetVecEnv``, ``ResidualController.reset_fleets``), which
  say so when it is missing; so is ``act_batch``'s ``fleets`` argument. The
  commands call ``act_batch(obs)`` and ``reset(seed)`` only;
- optional ``bind_simulator(sim, fleets)``: a privileged reference
  (``baselines.privileged``, not deployable) reads the true state of the
  FleetSim fleets it acts for; the commands' rollout calls it when present.

``isinstance(x, FleetPolicy)`` checks that ``act_batch``, ``reset`` and
``diagnostics`` are present (Python checks presence, not signatures).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FleetPolicy"]


@runtime_checkable
class FleetPolicy(Protocol):
    """A policy of B fleets (see the module docstring for the whole contract)."""

    diagnostics: dict[str, NDArray[np.float64]]

    def act_batch(self, obs: ArrayLike, fleets: ArrayLike | None = None) -> NDArray[np.float64]:
        """Actions (rows, n, 4 + m) of B fleets, or of the listed ``fleets``."""
        ...

    def reset(self, seed: int | None = None) -> None:
        """Forget all internal states; they restart on the next act."""
        ...
