"""``studies/student/student_tables.py``: verdicts against mpc and the normalized score."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

from conftest import ROOT


def _tables() -> ModuleType:
    path = ROOT / "studies/student/student_tables.py"
    spec = importlib.util.spec_from_file_location("student_tables", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _bench(folder: Path, costs: dict[str, list[float]]) -> None:
    folder.mkdir(parents=True)
    rows = ["policy,scenario,seed,cost"]
    for policy, values in costs.items():
        rows += [f"{policy},bench_mild,{10000 + k},{v}" for k, v in enumerate(values)]
    (folder / "episodes.csv").write_text("\n".join(rows) + "\n")
    (folder / "summary.md").write_text(
        "| policy | scenario | N | cost difference [95 %] | P(beats) [95 %] | verdict |\n"
        "|---|---|---|---|---|---|\n"
        "| r/agents/student_s0 | bench_mild | 4 | -1 [-2, -0.5] | 1.00 [0.5, 1.00] | beats |\n"
    )


#: Four episodes of bench_mild per policy: the student between mpc and the oracle.
COSTS = {
    "nn_dsc": (100.0, 110.0, 90.0, 100.0),
    "mpc": (40.0, 44.0, 36.0, 40.0),
    "oracle": (20.0, 22.0, 18.0, 20.0),
    "r/agents/student_s0": (30.0, 33.0, 27.0, 30.0),
}


def test_tables_count_wins_over_mpc_and_the_score(tmp_path: Path) -> None:
    costs = {name: list(values) for name, values in COSTS.items()}
    _bench(tmp_path / "bench_test", costs)
    lines = _tables()._table(tmp_path / "bench_test")
    summary = "beats mpc on 1/1 (bench_mild); loses or is mixed against nn_dsc on none; not run"
    assert summary in lines[-1]
    assert lines[-1].endswith("IQM normalized score 0.875")  # (100 - 30) / (100 - 20)
    costs["r/agents/student_s0"] = [41.0, 45.0, 37.0, 41.0]
    _bench(tmp_path / "again" / "bench_test", costs)
    worse = _tables()._table(tmp_path / "again" / "bench_test")
    assert "beats mpc on 0/1 (none)" in worse[-1]
    assert "loses" in worse[-3]


def test_guarded_verdicts_flag_a_physical_regression_and_read_the_deployable_table(
    tmp_path: Path,
) -> None:
    """Cheaper than mpc but with 3x its final-window heading error: mixed, not beats; against
    mpc_tuned (from another table, paired on the seeds both ran) it loses.
    """
    import numpy as np

    from cpf_bench.episodes import METRICS
    from cpf_bench.report import CellResult, episodes_csv

    seeds = tuple(range(10000, 10008))
    rng = np.random.default_rng(1)

    def cell(policy: str, cost: float, heading: float, on: tuple[int, ...] = seeds) -> CellResult:
        metrics = {m: np.full(len(on), 1e-3) for m in METRICS}
        metrics["progress"] = np.ones(len(on))
        metrics["cost"] = cost + rng.normal(0.0, 0.1, len(on))
        metrics["heading_error_rms_window"] = np.full(len(on), heading)
        return CellResult(policy, "bench_mild", on, False, metrics)

    folder = tmp_path / "bench_test"
    folder.mkdir()
    student = "r/agents/student_s0"
    text = episodes_csv([cell("mpc", 50.0, 0.01), cell(student, 45.0, 0.03)])
    (folder / "episodes.csv").write_text(text)
    tuned = [cell("mpc_tuned", 40.0, 0.01, seeds + (10008, 10009))]
    lines = _tables()._guarded(folder, tuned, ["mpc_tuned"])
    assert "| bench_mild | mpc | mixed (worse: heading) (N 8) |" in lines
    assert "| bench_mild | mpc_tuned | loses (N 8) |" in lines


def test_an_oracle_in_the_deployable_table_replaces_the_folders(tmp_path: Path) -> None:
    import numpy as np

    from cpf_bench.episodes import METRICS
    from cpf_bench.report import CellResult

    costs = {name: list(values) for name, values in COSTS.items()}
    _bench(tmp_path / "bench_test", costs)
    seeds = tuple(range(10000, 10006))  # a superset of the folder's seeds
    metrics = {m: np.zeros(len(seeds)) for m in METRICS}
    metrics["cost"] = np.array([40.0, 44.0, 36.0, 40.0, 1.0, 1.0])
    newer = [CellResult("oracle", "bench_mild", seeds, False, metrics)]
    lines = _tables()._table(tmp_path / "bench_test", newer)
    assert lines[-1].endswith("IQM normalized score 1.167")  # (100 - 30) / (100 - 40)
    assert "| 100.0 | 40.0 | 40.0 |" in lines[4]
