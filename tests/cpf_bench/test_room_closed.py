"""The score against the room: 0 at the best deployable design, 1 at the bound."""

from __future__ import annotations

import numpy as np
import pytest

from cpf_bench.headroom import room_closed, room_table
from cpf_bench.report import CellResult
from cpf_bench.stats import iqm

SEEDS = (0, 1, 2, 3)


def _cell(policy: str, scenario: str, costs: list[float]) -> CellResult:
    return CellResult(policy, scenario, SEEDS, True, {"cost": np.array(costs)})


def _cells(agent_a: list[float], agent_b: list[float]) -> list[CellResult]:
    """Scenario a: best deployable mpc 10, bound 6; b: best mpc_tuned_ekf 20, bound 20 (none)."""
    return [
        _cell("nn_dsc", "a", [12.0] * 4),
        _cell("mpc", "a", [10.0] * 4),
        _cell("oracle", "a", [6.0] * 4),
        _cell("agent", "a", agent_a),
        _cell("mpc_tuned_ekf", "b", [20.0] * 4),
        _cell("oracle", "b", [20.0] * 4),
        _cell("agent", "b", agent_b),
    ]


def test_the_score_reads_the_best_deployable_design_as_0_and_the_bound_as_1() -> None:
    scored = room_closed(_cells([10.0, 8.0, 6.0, 12.0], [1.0] * 4))
    assert set(scored) == {"agent"}  # the analytic designs and the bound are the scale
    agent = scored["agent"]
    assert agent.scenarios == {"a": pytest.approx(0.25)}  # mean 9; b has no room: left out
    episodes = np.array([0.0, 0.5, 1.0, -0.5])
    assert agent.iqm == pytest.approx(float(iqm(episodes)))
    low, high = agent.interval
    assert low <= agent.iqm <= high


def test_the_table_has_a_row_per_scored_policy() -> None:
    lines = room_table(_cells([8.0] * 4, [20.0] * 4))
    assert lines[0].startswith("| policy | IQM") and lines[2].startswith("| agent | 0.50")
    assert room_table(_cells([8.0] * 4, [20.0] * 4)[:3]) == []  # no policy to score
