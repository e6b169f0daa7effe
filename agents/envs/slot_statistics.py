"""Observation normalization with one set of statistics for every neighbour slot.

SB3's ``VecNormalize`` keeps a mean and variance per input component. Over
padded neighbour slots (``ResidualConfig.neighbour_slots``) that is a poor fit:
a slot position that is filled only on one scenario's graph (the fourth slot
of ``bench_switching``'s star, say) is zero almost always, its variance is
tiny, and the few real values it sees are scaled by a hundredfold and then
clipped at ``clip_obs``: the learner meets inputs it never learned from
exactly where that scenario needs them (measured: the neighbour-theta
difference of slot 3 had a standard deviation of 1e-4 after mixture training,
against 0.1 in slot 0).

``SlotSharedVecNormalize`` pools the statistics of the K slots, component by
component (weight a_ij, theta difference, age, message): each slot's running
mean and variance are replaced by the mean over slots of the means and the
pooled variance (the variance of the K slots' values taken together), before
every normalization. Every slot is then scaled alike, as a
permutation-invariant reading of the slots would need; the own-vessel
components and the extras keep their own statistics. The statistics stay in
``obs_rms`` (mean, var per component), so the agent folder stores and applies
them as it does ``VecNormalize``'s.

With ``raw_weights=True`` (the runs with a neighbour encoder,
``TrainConfig(encoder="deepsets")``) the slots' weights a_ij keep mean 0 and
variance 1, so an empty slot's ``a_ij = 0`` is exactly 0 after normalization,
whatever the statistics are at that step: the encoder's mask
(``agents.folder.encoder``) tells empty slots from links by that value alone.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from cpf_env.sim.observation import SLOT_WEIGHT, SLOTS

__all__ = ["SlotSharedVecNormalize", "pool_slot_statistics", "shared_slot_statistics"]


def pool_slot_statistics(
    mean: NDArray[np.float64], var: NDArray[np.float64], n_slots: int, slot_size: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Means and variances with the K slots' statistics pooled, component by component.

    Args:
        mean: (k,) per-component means of the learner's input.
        var: (k,) per-component variances.
        n_slots: K, the slots starting at index ``SLOTS``.
        slot_size: Components per slot (3 + m).

    Returns:
        (mean, var), shape (k,): each slot's components hold the mean over the K
        slots of their means, and the variance of all K slots' values together
        (mean of the variances plus the variance of the means).
    """
    stop = SLOTS + n_slots * slot_size
    slot_mean = mean[SLOTS:stop].reshape(n_slots, slot_size)
    slot_var = var[SLOTS:stop].reshape(n_slots, slot_size)
    pooled_mean = slot_mean.mean(axis=0)
    pooled_var = slot_var.mean(axis=0) + slot_mean.var(axis=0)
    mean, var = mean.copy(), var.copy()
    mean[SLOTS:stop] = np.tile(pooled_mean, n_slots)
    var[SLOTS:stop] = np.tile(pooled_var, n_slots)
    return mean, var


def shared_slot_statistics(
    mean: NDArray[np.float64],
    var: NDArray[np.float64],
    n_slots: int,
    slot_size: int,
    raw_weights: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The statistics ``SlotSharedVecNormalize`` normalizes with: pooled, weights kept raw.

    Args:
        mean: (k,) per-component means of the learner's input.
        var: (k,) per-component variances.
        n_slots: K, the slots starting at index ``SLOTS``.
        slot_size: Components per slot (3 + m).
        raw_weights: Give the slots' weights a_ij mean 0 and variance 1.

    Returns:
        (mean, var), shape (k,) (``pool_slot_statistics``, then the raw weights).
    """
    mean, var = pool_slot_statistics(mean, var, n_slots, slot_size)
    if raw_weights:
        weights = slice(SLOTS + SLOT_WEIGHT, SLOTS + n_slots * slot_size, slot_size)
        mean[weights], var[weights] = 0.0, 1.0
    return mean, var


class SlotSharedVecNormalize(VecNormalize):
    """``VecNormalize`` (observations) whose neighbour slots share their statistics.

    Args:
        venv: The vector env (its observations: ``ObsLayout`` with K slots, then extras).
        n_slots: K.
        slot_size: Components per slot (3 + m).
        gamma: Discount (``VecNormalize``'s; rewards are not normalized).
        raw_weights: Keep the slots' weights a_ij at mean 0 and variance 1 (an empty
            slot stays exactly 0).
    """

    def __init__(
        self,
        venv: VecEnv,
        n_slots: int,
        slot_size: int,
        gamma: float = 0.99,
        raw_weights: bool = False,
    ) -> None:
        super().__init__(venv, norm_obs=True, norm_reward=False, gamma=gamma)
        self.n_slots, self.slot_size = int(n_slots), int(slot_size)
        self.raw_weights = raw_weights

    def normalize_obs(self, obs: NDArray | dict[str, NDArray]) -> NDArray | dict[str, NDArray]:
        """Pool the slots' running statistics, then normalize as ``VecNormalize`` does."""
        rms = self.obs_rms
        assert isinstance(rms, RunningMeanStd)
        rms.mean, rms.var = shared_slot_statistics(
            rms.mean, rms.var, self.n_slots, self.slot_size, self.raw_weights
        )
        return super().normalize_obs(obs)
