"""A vessel's own history: its last inputs and actions, kept row by row, newest first.

RMA-style adaptation infers what the vessel cannot observe (the current, the
wave and wind forces, its true model) from how it responded to what it did.
``OwnHistory(rows, length, own, action_size)`` keeps, for each of ``rows``
vessels, its last ``length`` entries, newest first::

    entry k (k = 1..length) = [own_{t-k} (own floats), action_{t-k} (a floats), valid]

where ``own_{t-k}`` is the first ``own`` floats of the vessel's input k steps
ago (by default the 18 own-vessel features of the local observation,
``cpf_env.sim.observation``), ``action_{t-k}`` the action taken on it, and
``valid`` 1 for a step of the current episode and 0 for the zero padding
before it. So the input is local by construction: a vessel's own past,
nothing from other vessels. ``clear`` empties rows whose episode restarts.

One implementation serves training and evaluation: ``agents.envs.history_env.HistoryVecEnv``
appends it to an SB3 vector env's observations, and ``agents.load_policy``'s
policy keeps it itself across ``act_batch`` calls (cleared by ``reset`` and
``reset_fleets``), so a trained agent sees in evaluation the history it
learned from. This module needs numpy only.

Example:
    >>> history = OwnHistory(rows=2, length=3, own=18, action_size=3)
    >>> inputs = np.ones((2, 26), dtype=np.float32)
    >>> history.append_to(inputs).shape, history.size
    ((2, 92), 66)
    >>> history.push(inputs, np.zeros((2, 3), dtype=np.float32))
    >>> history.entries[:, 0, -1]  # the newest entry is valid
    array([1., 1.], dtype=float32)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpf_env.sim.observation import SLOTS

__all__ = ["OwnHistory", "history_size"]


def history_size(length: int, action_size: int, own: int = SLOTS) -> int:
    """Floats ``length`` history entries append to an input: length x (own + action_size + 1).

    The one formula of the history's size, used by ``OwnHistory``, ``TrainConfig``'s
    learner layout and the agent-folder reader.

    Args:
        length: Entries H >= 0 (0: no history).
        action_size: Floats per action, a.
        own: Leading input floats recorded per entry (default the 18 own-vessel features).
    """
    return length * (own + action_size + 1)


class OwnHistory:
    """Each row's last ``length`` (own features, action, valid) entries, float32, newest first.

    Args:
        rows: Vessels (rows of the learner's input) kept.
        length: Entries H >= 1.
        own: Leading input floats recorded per entry (default the 18 own-vessel features).
        action_size: Floats per action, a.

    Raises:
        ValueError: ``length`` not an integer >= 1, or ``own`` or ``action_size`` < 1.
    """

    def __init__(self, rows: int, length: int, own: int = SLOTS, action_size: int = 3) -> None:
        if isinstance(length, bool) or not isinstance(length, int) or length < 1:
            raise ValueError(f"history length must be an integer >= 1, got {length!r}.")
        if own < 1 or action_size < 1:
            raise ValueError(f"own and action_size must be >= 1, got {own} and {action_size}.")
        self.length, self.own, self.action_size = length, own, action_size
        self.entry_size = history_size(1, action_size, own)
        self.entries = np.zeros((rows, length, self.entry_size), dtype=np.float32)

    @property
    def size(self) -> int:
        """Floats appended to each row's input, H (own + a + 1)."""
        return history_size(self.length, self.action_size, self.own)

    def append_to(self, inputs: ArrayLike, rows: ArrayLike | None = None) -> NDArray[np.float32]:
        """``inputs`` (R, D) with the history of ``rows`` (default all) appended: (R, D + size)."""
        values = np.asarray(inputs, dtype=np.float32)
        entries = self.entries if rows is None else self.entries[np.asarray(rows)]
        return np.concatenate([values, entries.reshape(values.shape[0], -1)], axis=1)

    def push(self, inputs: ArrayLike, actions: ArrayLike) -> None:
        """Record, for every row, the input (R, D) just acted on and its action (R, a)."""
        self.entries[:, 1:] = self.entries[:, :-1]
        self.entries[:, 0, : self.own] = np.asarray(inputs, dtype=np.float32)[:, : self.own]
        self.entries[:, 0, self.own : -1] = np.asarray(actions, dtype=np.float32).reshape(
            self.entries.shape[0], self.action_size
        )
        self.entries[:, 0, -1] = 1.0

    def clear(self, rows: ArrayLike | None = None) -> None:
        """Empty the history of ``rows`` (indices or a (R,) mask; default all)."""
        if rows is None:
            self.entries[:] = 0.0
        else:
            self.entries[np.asarray(rows)] = 0.0
