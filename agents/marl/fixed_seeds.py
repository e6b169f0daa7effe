"""A residual actor against its base policy on fixed training seeds: the learned part of a curve.

The return of a training episode depends mostly on its random start (the
first seconds' transient), and each batch draws other starts, so a training
curve of returns hides what the residual changes. ``FixedSeedEvaluation``
plays one episode on each of ``fleets`` fixed training seeds, unstaggered,
with the actor's deterministic action (BenchMARL's ``tanh(loc)``) and with a
zero action (the base policy alone, bit for bit), and reports the actor's
numbers and their difference to the base's, over the whole episode, over its
second half (the steady state after the transient) and per reward term
(``REWARD_TERMS``). The episodes may be longer than the training ones (the
scenario's own length, as ``cpf-bench`` plays them). The same actor gives the
same numbers on every call.

Example (``examples/marl_residual.py`` does this every few iterations)::

    evaluation = FixedSeedEvaluation(task.config, statistics=env.input_statistics)
    row = evaluation.evaluate(experiment.policy)
    row["return_minus_base"]  # > 0: the actor earns more than the base on these seeds
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from agents.marl.envs import make_env
from agents.marl.tasks import CpfTaskConfig, checked_config
from cpf_env.envs.input_statistics import InputStatistics
from cpf_env.envs.torchrl_env import GROUP
from cpf_env.scenarios import make_scenario
from cpf_env.scenarios.reward_weights import REWARD_TERMS
from cpf_env.scenarios.splits import check_training

__all__ = ["EVALUATION_FIELDS", "FixedSeedEvaluation"]

#: The numbers ``FixedSeedEvaluation.evaluate`` returns, in reward units (per vessel).
EVALUATION_FIELDS = (
    "return",
    "return_minus_base",
    "late_reward",
    "late_reward_minus_base",
    *(f"return_{term}" for term in REWARD_TERMS),
)


class FixedSeedEvaluation:
    """One episode per fixed training seed, an actor against its base policy.

    Args:
        config: The task config (a ``CpfTaskConfig`` or its dict, e.g. BenchMARL's
            ``task.config``): its scenario, base, residual, statistics and overrides.
        fleets: Episodes, one per fleet: fleet k plays seed ``seed + k``.
        seed: The first seed; every seed must be a training seed.
        statistics: The training env's ``InputStatistics`` (else estimated as the task does).
        max_steps: Episode length in control periods; None: the scenario's own (with
            the task's overrides), not the task's training ``max_steps``.

    Raises:
        ValueError: A bad config, a held-out scenario or evaluation seeds
            (``cpf_env.scenarios.splits.check_training``).

    Attributes:
        env: The unstaggered residual ``TorchRLFleetEnv`` of ``fleets`` fleets.
        max_steps: The episode length T.
        base: ``evaluate``'s numbers for the base policy alone (its ``*_minus_base`` are 0).
    """

    def __init__(
        self,
        config: CpfTaskConfig | dict[str, Any],
        fleets: int = 16,
        seed: int = 0,
        statistics: InputStatistics | None = None,
        max_steps: int | None = None,
    ) -> None:
        task = config if isinstance(config, CpfTaskConfig) else checked_config(dict(config))
        check_training(task.scenario, range(seed, seed + fleets))
        if max_steps is None:
            max_steps = make_scenario(task.scenario, **task.overrides).max_steps
        self.seed, self.max_steps = seed, int(max_steps)
        self.env = make_env(
            task.scenario,
            fleets,
            task.base_policy,
            task.residual(),
            False,
            normalize=task.normalize if statistics is None else statistics,
            normalization_steps=task.normalization_steps,
            shared_slot_statistics=task.shared_slot_statistics and statistics is None,
            state=False,
            **{**task.overrides, "max_steps": self.max_steps},
        )
        self._base = self._play(None)
        self.base = self._summary(*self._base)

    def _play(self, policy: TensorDictModuleBase | None) -> tuple[NDArray[Any], NDArray[Any]]:
        """One episode per fleet from the fixed seeds, no reset within it.

        Returns:
            (reward terms [T, B, n, 6] float64, zero once the fleet's episode is over;
            alive [T, B] bool: the step belongs to the episode).
        """
        env, steps = self.env, self.max_steps
        terms = np.zeros((steps, env.num_fleets, env.n, len(REWARD_TERMS)))
        alive = np.zeros((steps, env.num_fleets), dtype=bool)
        running = np.ones(env.num_fleets, dtype=bool)
        env.set_seed(self.seed)
        zero = torch.zeros(env.full_action_spec[GROUP, "action"].shape)
        td: TensorDictBase = env.reset()
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            for t in range(steps):
                td = td.set((GROUP, "action"), zero.clone()) if policy is None else policy(td)
                td = env.step(td)
                alive[t] = running
                terms[t] = env.sim.arrays.reward_terms * running[:, None, None]
                running &= ~td["next", "done"].squeeze(-1).numpy()
                td = step_mdp(td)
        return terms, alive

    def _summary(self, terms: NDArray[Any], alive: NDArray[Any]) -> dict[str, float]:
        """The numbers of ``EVALUATION_FIELDS`` for these reward terms, against the base's."""
        base_terms, base_alive = self._base
        late = self.max_steps // 2

        def returns(part: NDArray[Any]) -> NDArray[Any]:
            """Per-term return per vessel, (6,)."""
            return part.sum(axis=0).mean(axis=(0, 1))

        def late_reward(part: NDArray[Any], mask: NDArray[Any]) -> float:
            """Reward per vessel-step over the second half, while the episode lasts."""
            return float(part[late:].sum() / (mask[late:].sum() * part.shape[2]))

        per_term = returns(terms)
        row = {
            "return": float(per_term.sum()),
            "return_minus_base": float(per_term.sum() - returns(base_terms).sum()),
            "late_reward": late_reward(terms, alive),
            "late_reward_minus_base": late_reward(terms, alive)
            - late_reward(base_terms, base_alive),
        }
        for term, value in zip(REWARD_TERMS, per_term, strict=True):
            row[f"return_{term}"] = float(value)
        return row

    def evaluate(self, policy: TensorDictModuleBase) -> dict[str, float]:
        """The actor's numbers on the fixed seeds (``EVALUATION_FIELDS``).

        Args:
            policy: A TorchRL policy reading ``("vessel", "observation")`` and writing
                ``("vessel", "action")`` (BenchMARL's ``experiment.policy``); run with
                ``ExplorationType.DETERMINISTIC``.

        Returns:
            ``return``: the mean per-vessel return of the episodes; ``late_reward``: the
            mean reward per vessel-step over their second half (steps ``max_steps // 2``
            on, while the episode lasts); each also minus the base policy's on the same
            seeds (> 0: better than the base); ``return_<term>``: the return's part of
            each reward term (they sum to ``return``).
        """
        return self._summary(*self._play(policy))
