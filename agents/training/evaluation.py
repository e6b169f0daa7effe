"""The evaluation a training run makes of itself: the validation seeds, by ``cpf_bench``.

``ValidationEvaluator`` turns an agent folder into its mean episode cost per
scenario over the validation seeds ``VALIDATION_SEED + k`` (k < seeds; one
episode on a scenario in which nothing is random; ``cpf_env.scenarios.splits``):
the training scenarios on seeds training never draws and the benchmark never
reports. ``cpf-train`` keeps its best agent by these costs and ``cpf-curves``
draws them, so choosing an agent never sees the ``test`` seeds;
``cpf-bench --policies FOLDER --scenarios NAME --split test`` then measures
the agent on seeds nothing was chosen on. ``cpf-train`` and ``cpf-distill``
hand it to ``agents.training.trainer.train`` and ``agents.distill.dagger.distill``.

Example::

    evaluate = ValidationEvaluator(["bench_lossy_links"], num_seeds=10)
    evaluate(Path("runs/ppo/best"))  # {"bench_lossy_links": 41.7}
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.folder.loading import load_policy
from cpf_bench import evaluate
from cpf_env.scenarios.splits import EVALUATION_SEED, VALIDATION_SEED

__all__ = ["DEFAULT_EVAL_NUM_SEEDS", "ValidationEvaluator"]

#: Evaluation episodes per scenario (``cpf-bench``'s default ``--num-seeds``).
DEFAULT_EVAL_NUM_SEEDS = 10


class ValidationEvaluator:
    """Agent folder -> mean cost per scenario on the validation seeds (module docstring).

    Args:
        scenarios: Registered scenario names.
        num_seeds: Episodes per scenario (paired seeds ``VALIDATION_SEED + k``).
        max_steps: Horizon override (``cpf-bench --max-steps``); None: each scenario's own.

    Attributes:
        settings: The arguments and the seeds, JSON-ready (``train`` records them in
            ``run.json``; ``cpf-curves`` runs its lines to beat on the same seeds).

    Raises:
        ValueError: Fewer than one seed, more than the validation seeds, or no scenario.
    """

    def __init__(
        self,
        scenarios: Sequence[str],
        num_seeds: int = DEFAULT_EVAL_NUM_SEEDS,
        max_steps: int | None = None,
    ) -> None:
        available = EVALUATION_SEED - VALIDATION_SEED
        if isinstance(num_seeds, bool) or int(num_seeds) != num_seeds or num_seeds < 1:
            raise ValueError(f"num_seeds must be an integer >= 1, got {num_seeds!r}.")
        if num_seeds > available:
            raise ValueError(
                f"num_seeds = {num_seeds} is more than the {available} validation seeds; "
                f"evaluate on at most {available}."
            )
        if not scenarios:
            raise ValueError("give at least one evaluation scenario.")
        self.scenarios, self.num_seeds, self.max_steps = tuple(scenarios), int(num_seeds), max_steps
        self.settings = {
            "split": "validation",
            "seed": VALIDATION_SEED,
            "scenarios": list(self.scenarios),
            "num_seeds": self.num_seeds,
            "max_steps": max_steps,
        }

    def __call__(self, folder: Path) -> dict[str, float]:
        """Mean episode cost per scenario of the agent in ``folder``."""
        result = evaluate(
            {"agent": lambda task: load_policy(Path(folder), task)},
            self.scenarios,
            num_seeds=self.num_seeds,
            seed=VALIDATION_SEED,
            max_steps=self.max_steps,
        )
        return {cell.scenario: float(np.mean(cell.metrics["cost"])) for cell in result.cells}
