"""A permutation-invariant neighbour encoder (DeepSets) for the residual learner.

The learner's input is the vessel's own features (the first ``SLOTS`` = 18
components of the local observation), K neighbour slots of ``3 + m`` floats
``[a_ij, theta_j - theta_i, age, msg]`` and a tail of ``tail`` floats (the
residual's extras, and a history when ``HistoryVecEnv`` appends one). An MLP
over the flattened input ties the network to K and to the order of the
slots; ``NeighbourSetEncoder`` does not:

    phi_k = MLP(slot_k) * mask_k,   mask_k = 1 if a_ij of slot k is a link, else 0
    pooled = sum_k phi_k / max(1, sum_k mask_k)     (``pooling="mean"``; or the sum)
    features = [own, pooled, degree, tail]

The same weights run on any K (train with K slots, run with more: a
10-vessel star's centre has 9), and reordering the slots changes the
features only by float rounding of the pooled sum. Empty slots contribute
nothing (their terms are exact zeros); padding to more slots changes the
features only by float rounding (the slot MLP runs on more rows, for which
BLAS may pick another kernel).

Normalized inputs. SB3's ``VecNormalize`` maps an empty slot's ``a_ij = 0`` to
``(0 - mean) / sqrt(var + eps)``, not to 0. ``empty_weight`` is that value
(``empty_weight_after(statistics)`` computes it from statistics pooled across
slots, ``agents.envs.slot_statistics``); a slot is empty when its weight is within
``tolerance`` of it. A training run with ``TrainConfig(encoder="deepsets")``
keeps the weights' statistics at mean 0 and variance 1
(``SlotSharedVecNormalize(raw_weights=True)``), so an empty slot is an exact 0
throughout training and in the saved agent, and ``empty_weight`` stays 0.

This module needs torch only (an agent folder's reader uses it);
``agents.training.algorithms.DeepSetsExtractor`` wraps the encoder as an SB3 features
extractor::

    >>> encoder = NeighbourSetEncoder(slot_size=4, tail=3)
    >>> encoder(torch.zeros(5, 18 + 9 * 4 + 3)).shape  # 9 slots, as 2 or 20 would
    torch.Size([5, 54])
"""

from __future__ import annotations

import numpy as np
import torch

from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.sim.observation import SLOT_WEIGHT, SLOTS

__all__ = ["POOLINGS", "NeighbourSetEncoder", "empty_weight_after", "statistics_for_slots"]

#: Pooling operators over the neighbour slots.
POOLINGS = ("mean", "sum")


def empty_weight_after(statistics: InputStatistics, n_slots: int, slot_size: int) -> float:
    """The value an empty slot's ``a_ij = 0`` takes after ``statistics`` normalize it.

    Args:
        statistics: Observation statistics with slots pooled (``agents.envs.slot_statistics``).
        n_slots: K, the slots the statistics cover.
        slot_size: Floats per slot, 3 + m.

    Raises:
        ValueError: The statistics differ between the slots' weights (not pooled).
    """
    index = slice(SLOTS + SLOT_WEIGHT, SLOTS + n_slots * slot_size, slot_size)
    weights = statistics.mean[index], statistics.var[index]
    if weights[0].size == 0:
        return 0.0
    if not all(float(w.min()) == float(w.max()) for w in weights):
        raise ValueError(
            "the slots' a_ij statistics differ between slots; pool them first "
            "(agents.envs.slot_statistics.SlotSharedVecNormalize)."
        )
    scaled = -float(weights[0][0]) / float((weights[1][0] + statistics.epsilon) ** 0.5)
    return float(min(max(scaled, -statistics.clip), statistics.clip))


def statistics_for_slots(
    statistics: InputStatistics, n_slots: int, slot_size: int, new_slots: int
) -> InputStatistics:
    """Statistics of an input of K = ``n_slots`` slots, for the same input with ``new_slots``.

    The own features and the tail keep their statistics; every slot gets the
    slots' shared ones (``agents.envs.slot_statistics`` pools them), so an encoder
    trained on K slots is normalized alike on K' (a 10-vessel star's centre: 9).

    Args:
        statistics: Statistics of inputs of 18 + K (3 + m) + tail floats, slots pooled.
        n_slots: K.
        slot_size: Floats per slot, 3 + m.
        new_slots: K' >= 0.

    Raises:
        ValueError: Statistics shorter than 18 + K slots, or that differ between slots.
    """
    stop = SLOTS + n_slots * slot_size
    if n_slots < 1 or new_slots < 0 or statistics.mean.size < stop:
        raise ValueError(
            f"need statistics of 18 + K x {slot_size} + tail inputs with K >= 1 and K' >= 0; "
            f"got {statistics.mean.size} inputs, K = {n_slots}, K' = {new_slots}."
        )
    parts = []
    for values in (statistics.mean, statistics.var):
        slots = values[SLOTS:stop].reshape(n_slots, slot_size)
        if not np.all(slots == slots[0]):
            raise ValueError(
                "the slots' statistics differ between slots; an encoder's slots share one set "
                "(train with shared_slot_statistics, agents.envs.slot_statistics)."
            )
        parts.append(np.concatenate([values[:SLOTS], np.tile(slots[0], new_slots), values[stop:]]))
    return InputStatistics(parts[0], parts[1], statistics.epsilon, statistics.clip)


class NeighbourSetEncoder(torch.nn.Module):
    """DeepSets over the neighbour slots: (..., 18 + K (3 + m) + tail) -> (..., features).

    Args:
        slot_size: Floats per slot, 3 + m.
        tail: Floats after the slots (extras, history), passed through.
        hidden: Width of the per-slot MLP (two layers, tanh).
        pooling: ``"mean"`` (over the linked slots) or ``"sum"``.
        empty_weight: Value of an empty slot's weight in the inputs (0 for raw inputs).
        tolerance: A slot is empty when |a_ij - empty_weight| <= tolerance.
    """

    empty_weight: torch.Tensor
    tolerance: torch.Tensor

    def __init__(
        self,
        slot_size: int,
        tail: int = 0,
        hidden: int = 32,
        pooling: str = "mean",
        empty_weight: float = 0.0,
        tolerance: float = 1e-6,
    ) -> None:
        super().__init__()
        if pooling not in POOLINGS:
            raise ValueError(f"pooling must be one of {POOLINGS}, got {pooling!r}.")
        if slot_size < 3 or tail < 0 or hidden < 1 or tolerance < 0.0:
            raise ValueError(
                f"need slot_size >= 3, tail >= 0, hidden >= 1, tolerance >= 0; got "
                f"{slot_size}, {tail}, {hidden}, {tolerance}."
            )
        self.slot_size, self.tail, self.hidden, self.pooling = slot_size, tail, hidden, pooling
        self.phi = torch.nn.Sequential(
            torch.nn.Linear(slot_size, hidden),
            torch.nn.Tanh(),
            torch.nn.Linear(hidden, hidden),
            torch.nn.Tanh(),
        )
        self.register_buffer("empty_weight", torch.tensor(float(empty_weight)))
        self.register_buffer("tolerance", torch.tensor(float(tolerance)))

    @property
    def features_dim(self) -> int:
        """Length of the output: own (18) + pooled (hidden) + degree (1) + tail."""
        return SLOTS + self.hidden + 1 + self.tail

    def slots_in(self, size: int) -> int:
        """K for an input of ``size`` floats, or a ValueError naming the layout."""
        body = size - SLOTS - self.tail
        if body < 0 or body % self.slot_size:
            raise ValueError(
                f"an input of {size} floats is not 18 + K x {self.slot_size} + {self.tail} "
                "(own features, K neighbour slots, tail) for any K >= 0."
            )
        return body // self.slot_size

    def forward(self, rows: torch.Tensor) -> torch.Tensor:
        """Features (..., ``features_dim``) of inputs (..., 18 + K (3 + m) + tail), any K."""
        k = self.slots_in(int(rows.shape[-1]))
        stop = SLOTS + k * self.slot_size
        own, tail = rows[..., :SLOTS], rows[..., stop:]
        slots = rows[..., SLOTS:stop].reshape(*rows.shape[:-1], k, self.slot_size)
        gap = (slots[..., SLOT_WEIGHT] - self.empty_weight).abs()
        mask = (gap > self.tolerance).to(rows.dtype)
        degree = mask.sum(dim=-1, keepdim=True)
        encoded = self.phi(slots) * mask.unsqueeze(-1)
        pooled = encoded.sum(dim=-2)
        if self.pooling == "mean":
            pooled = pooled / degree.clamp(min=1.0)
        return torch.cat([own, pooled, degree, tail], dim=-1)
