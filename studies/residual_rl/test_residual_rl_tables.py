"""studies/residual_rl/residual_rl_tables.py: hand-computed cells, as docs/results.md shows."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
from conftest import ROOT

_SPEC = importlib.util.spec_from_file_location(
    "residual_rl_tables", ROOT / "studies" / "residual_rl" / "residual_rl_tables.py"
)
assert _SPEC is not None and _SPEC.loader is not None
tables = importlib.util.module_from_spec(_SPEC)
sys.modules["residual_rl_tables"] = tables
_SPEC.loader.exec_module(tables)

COLUMNS = "policy,seed,cost,path_error_rms_window,coordination_error_end,terminated\n"


def test_cells_on_a_constructed_evaluation(tmp_path: Path) -> None:
    """Two seeds; agent s0 costs 50 and 300 against nn_dsc's 100 and 200, s1 150 and 150."""
    path = tmp_path / "episodes.csv"
    path.write_text(
        COLUMNS
        + "nn_dsc,1,100,0.02,0.01,0\nnn_dsc,2,200,0.04,0.03,0\n"
        + "residual_ppo_bench_mild_s0,1,50,0.01,0.001,0\n"
        + "residual_ppo_bench_mild_s0,2,300,0.03,0.003,1\n"
        + "residual_ppo_bench_mild_s1,1,150,0.02,0.002,0\n"
        + "residual_ppo_bench_mild_s1,2,150,0.02,0.002,0\n"
    )
    episodes = tables.read_episodes(path)
    assert tables.row(episodes, "nn_dsc", "bench_mild") == ["1 (150)", "-", "0.03", "0.02", "0/2"]
    # s0: (50 + 300) / 2 / 150 = 1.1667, beats on 1 of 2 seeds; s1: 150 / 150 = 1, on 1 of 2.
    # Path RMS 0.02 and 0.02, coordination 0.002 and 0.002; one failure in 4 episodes.
    assert tables.row(episodes, "residual_ppo", "bench_mild") == [
        "1.00-1.17",
        "0.50",
        "0.02",
        "0.002",
        "1/4",
    ]


def test_unpaired_seeds_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "episodes.csv"
    path.write_text(COLUMNS + "nn_dsc,1,100,0.02,0.01,0\n"
                    + "backstepping,7,90,0.02,0.01,0\n")  # fmt: skip
    with pytest.raises(ValueError, match="nn_dsc's seeds"):
        tables.row(tables.read_episodes(path), "backstepping", "bench_mild")
