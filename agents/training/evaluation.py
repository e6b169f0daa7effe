"""The held-out evaluation a training run makes: the benchmark's ``test`` split, by ``cpf_bench``.

``TestSplitEvaluator`` turns an agent folder into its mean episode cost per
scenario over the evaluation seeds ``EVALUATION_SEED + k`` (k < seeds; one
episode on a scenario in which nothing is random), through
``cpf_bench.evaluate`` and ``agents.load_policy``: the number
``cpf-bench --policies FOLDER --scenarios NAME --split test --num-seeds S`` reports
as the mean cost of that folder. ``cpf-train`` and ``cpf-distill`` hand it to
``agents.training.trainer.train`` and ``agents.distill.dagger.distill``.

Example::

    evaluate = TestSplitEvaluator(["bench_lossy_links"], num_seeds=10)
    evaluate(Path("runs/ppo/best"))  # {"bench_lossy_links": 41.7}
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agents.folder.loading import load_policy
from cpf_bench import evaluate

__all__ = ["DEFAULT_EVAL_NUM_SEEDS", "TestSplitEvaluator"]

#: Evaluation episodes per scenario (``cpf-bench``'s default ``--num-seeds``).
DEFAULT_EVAL_NUM_SEEDS = 10


class TestSplitEvaluator:
    """Agent folder -> mean cost per scenario on the ``test`` split (see the module docstring).

    Args:
        scenarios: Registered scenario names.
        num_seeds: Episodes per scenario (paired evaluation seeds, as ``cpf-bench --num-seeds``).
        max_steps: Horizon override (``cpf-bench --max-steps``); None: each scenario's own.

    Attributes:
        settings: The arguments, JSON-ready (``train`` records them in ``run.json``).

    Raises:
        ValueError: Fewer than one seed or no scenario.
    """

    __test__ = False  # not a pytest class despite its name

    def __init__(
        self,
        scenarios: Sequence[str],
        num_seeds: int = DEFAULT_EVAL_NUM_SEEDS,
        max_steps: int | None = None,
    ) -> None:
        if isinstance(num_seeds, bool) or int(num_seeds) != num_seeds or num_seeds < 1:
            raise ValueError(f"num_seeds must be an integer >= 1, got {num_seeds!r}.")
        if not scenarios:
            raise ValueError("give at least one evaluation scenario.")
        self.scenarios, self.num_seeds, self.max_steps = tuple(scenarios), int(num_seeds), max_steps
        self.settings = {
            "split": "test",
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
            max_steps=self.max_steps,
            split="test",
        )
        return {cell.scenario: float(np.mean(cell.metrics["cost"])) for cell in result.cells}
