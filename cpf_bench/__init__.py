"""The benchmark as a library: ``evaluate(policies, scenarios, num_seeds)`` and what it measures.

``evaluate`` runs policies x scenarios x paired seeds, batched
(``cpf_bench.evaluate``); ``rollout`` and ``episodes`` run the episodes and
reduce each to its physical metrics; ``stats`` holds the interval
estimators, ``report`` the summary rows, ``verdict`` the guarded verdicts and
``headroom`` the room left to the bound; ``cache`` keeps the
receding-horizon planners' cells, keyed on the code ``sources`` finds they
come from. The commands (``cpf-bench``, ``cpf-train``'s evaluation) and
training call it; presentation (tables, figures, the report page) is
``cpf_commands.bench``'s.

What it may import: ``cpf_env`` and ``baselines``; nothing that learns.
"""

from __future__ import annotations

from cpf_bench.evaluate import Evaluation, evaluate
from cpf_bench.report import CellResult

__all__ = ["CellResult", "Evaluation", "evaluate"]
