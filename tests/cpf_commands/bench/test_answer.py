"""The bench's answer: ranked tables in the terminal, the normalized score, report.html."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

from baselines import HEADROOM_REFERENCE
from cpf_bench.report import CellResult, normalized_score, summarize
from cpf_commands.bench.cli import bench_main
from cpf_commands.bench.ranking import ranked_tables, terminal_report
from cpf_env.evaluation.fleet_metrics import METRICS

SEEDS = tuple(range(10))
SPREAD = np.linspace(-1.0, 1.0, len(SEEDS))


def _cell(policy: str, scenario: str, cost: float) -> CellResult:
    metrics = {name: np.full(len(SEEDS), 0.01) for name in METRICS}
    metrics["progress_window"] = np.full(len(SEEDS), 0.9)
    metrics["terminated"] = np.zeros(len(SEEDS))
    metrics["cost"] = cost + SPREAD
    return CellResult(policy, scenario, SEEDS, False, metrics)


def _cells(with_headroom: bool = True) -> list[CellResult]:
    """Reference 100, a policy 90 and a worse one 110 on two scenarios; headroom 80."""
    costs = {"nn_dsc": 100.0, "better": 90.0, "worse": 110.0}
    if with_headroom:
        costs[HEADROOM_REFERENCE] = 80.0
    return [
        _cell(policy, scenario, cost * scale)
        for policy, cost in costs.items()
        for scenario, scale in (("bench_mild", 1.0), ("bench_lossy_links", 2.0))
    ]


def _column(table, heading: str) -> list[str]:
    k = table.header.index(heading)
    return [row[k] for row in table.rows]


def test_tables_rank_by_mean_cost_with_ratio_score_and_verdict_and_name_the_best():
    cells = _cells()
    tables = ranked_tables(summarize(cells, "nn_dsc"), cells, "nn_dsc")
    assert [t.title for t in tables] == [
        "bench_mild (10 episodes)",
        "bench_lossy_links (10 episodes)",
        "all 2 scenarios",
    ]
    mild, lossy, suite = tables
    assert [t.suite for t in tables] == [False, False, True]
    assert _column(mild, "policy") == [
        f"{HEADROOM_REFERENCE} (privileged)",
        "better",
        "nn_dsc (reference)",
        "worse",
    ]
    assert _column(mild, "mean cost [95 %]")[1].startswith("90 [")
    assert _column(lossy, "mean cost [95 %]")[1].startswith("180 [")  # absolute, not relative
    assert _column(mild, "/ nn_dsc [95 %]")[1] == "0.900 [0.900, 0.900]"
    # (100 - 90) / (100 - 80) = 0.5 on each scenario and over the suite; the headroom is 1
    assert _column(mild, "score [95 %]") == [
        "1",
        "0.500 [0.500, 0.500]",
        "0",
        "-0.500 [-0.500, -0.500]",
    ]
    assert _column(suite, "score [95 %]")[1] == "0.500 [0.500, 0.500]"
    assert _column(mild, "verdict") == ["beats", "beats", "reference", "loses"]
    assert _column(suite, "verdicts on 2 scenarios")[1] == "beats 2"
    assert _column(suite, "mean cost (all episodes)")[1] == "135"  # (90 + 180) / 2
    for table in tables:  # the privileged headroom ranks first but is never named best
        assert table.best.startswith("best deployable: better, mean cost 0.900")
        assert table.best.endswith("verdict: beats" if table is not suite else "beats 2")


def test_the_score_is_read_from_the_summary_rows_and_is_na_without_the_headroom():
    cells = _cells(with_headroom=False)
    rows = summarize(cells, "nn_dsc")
    assert all(normalized_score(row) is None for row in rows)
    for table in ranked_tables(rows, cells, "nn_dsc"):
        assert _column(table, "score [95 %]") == ["n/a", "0", "n/a"]
    rows = summarize(_cells(), "nn_dsc")
    (suite,) = [r for r in rows if r["policy"] == "better" and r["metric"] == "cost_normalized"]
    assert normalized_score(suite) == pytest.approx((0.5, 0.5, 0.5))


def test_no_gap_where_the_headroom_reference_is_not_better():
    cells = [c for c in _cells() if c.policy != HEADROOM_REFERENCE]
    cells += [
        _cell(HEADROOM_REFERENCE, name, 100.0 * s)
        for name, s in (("bench_mild", 1), ("bench_lossy_links", 2))
    ]
    mild = ranked_tables(summarize(cells, "nn_dsc"), cells, "nn_dsc")[0]
    assert _column(mild, "policy")[2] == f"{HEADROOM_REFERENCE} (privileged)"
    assert _column(mild, "score [95 %]") == ["no gap", "0", "no gap", "no gap"]


def _read_summary(folder: Path) -> dict[tuple[str, str], float]:
    with open(folder / "summary.csv") as handle:
        return {
            (row["policy"], row["scenario"]): float(row["mean"])
            for row in csv.DictReader(handle)
            if row["metric"] == "cost"
        }


def test_cpf_bench_prints_its_answer_and_writes_one_html_report(tmp_path, capsys):
    out = tmp_path / "bench"
    argv = ["--policies", "nn_dsc", "backstepping", "dsc", "--scenarios", "bench_mild"]
    argv += [
        "bench_lossy_links",
        "--num-seeds",
        "2",
        "--max-steps",
        "15",
        "--quiet",
        "--out",
        str(out),
    ]
    assert bench_main(argv) == 0
    printed = capsys.readouterr().out
    assert "cost difference" not in printed  # not the 49 rows of differences any more
    means = _read_summary(out)
    for scenario in ("bench_mild", "bench_lossy_links"):
        block = printed.split(f"{scenario} (2 episodes):")[1].split("\n\n")[0]
        ranked = re.findall(r"^  \d  (\S+)", block, flags=re.MULTILINE)
        assert ranked == sorted(ranked, key=lambda p: means[(p, scenario)])
        for policy in ranked:  # the absolute mean cost of every policy
            assert f"{means[(policy, scenario)]:.4g} [" in block
        assert "n/a" in block  # the headroom reference did not run
        assert "best deployable: " in block
    assert "all 2 scenarios:" in printed
    assert printed.count("best deployable: ") == 3
    page = (out / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and page.count("<table>") == 3
    assert page.index("all 2 scenarios") < page.index("bench_mild (2 episodes)")  # suite first
    assert page.count("data:image/png;base64,") == len(list(out.glob("*.png")))
    assert "best deployable: " in page and str(tmp_path) not in page
    assert bench_main([*argv[:-1], str(tmp_path / "quiet"), "--no-figures"]) == 0
    assert "data:image" not in (tmp_path / "quiet" / "report.html").read_text()


def test_terminal_report_is_empty_without_the_reference():
    cells = [c for c in _cells() if c.policy != "nn_dsc"]
    assert terminal_report(summarize(cells, "nn_dsc"), cells, "nn_dsc") == ""


def test_a_ratio_below_the_axis_floor_is_marked_clipped():
    from cpf_commands.bench.views import figure

    cells = [_cell("nn_dsc", "bench_mild", 100.0), _cell("tiny", "bench_mild", 0.0)]
    cells[1].metrics["cost"][:] = 0.05  # 0.0005 x the reference: below the 0.001 floor
    cells.append(_cell("fine", "bench_mild", 90.0))
    ax = figure(summarize(cells, "nn_dsc"), cells, "cost", "cost").axes[0]
    assert [text.get_text() for text in ax.texts] == ["< 0.001: clipped"]
    assert ax.get_xlim()[0] == pytest.approx(1e-3)
    markers = [line.get_marker() for line in ax.lines if line.get_marker() not in (None, "None")]
    assert "<" in markers and "o" in markers  # the clipped mean and the one drawn where it is
