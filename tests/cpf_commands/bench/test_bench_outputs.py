"""cpf-bench's output folder: refused before the run when it cannot be written, replaced whole."""

from __future__ import annotations

import errno
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cpf_commands.bench import cli
from cpf_commands.bench.cli import bench_main
from cpf_env.infra import atomic
from cpf_env.scenarios.suite import HARD_VERSION, list_suite

QUICK = ["--policies", "nn_dsc", "--scenarios", "wang2014", "--num-seeds", "1", "--max-steps", "3",
         "--quiet"]  # fmt: skip


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as raised:
        bench_main(argv)
    assert raised.value.code == 2
    return capsys.readouterr().err


def test_results_are_replaced_only_with_force_and_stale_figures_go(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bench"
    assert bench_main([*QUICK, "--out", str(out)]) == 0
    figures = sorted(p.name for p in out.glob("*.png"))
    assert figures
    assert "--force" in _refused([*QUICK, "--out", str(out), "--no-figures"], capsys)
    assert sorted(p.name for p in out.glob("*.png")) == figures  # refused: untouched
    assert bench_main([*QUICK, "--out", str(out), "--no-figures", "--force"]) == 0
    assert not list(out.glob("*.png"))
    names = sorted(p.name for p in out.iterdir())
    assert names == ["episodes.csv", "report.html", "summary.csv", "summary.md"]


def test_a_symlinked_summary_is_not_followed(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    assert bench_main([*QUICK, "--out", str(out), "--no-figures"]) == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    (out / "summary.md").unlink()
    (out / "summary.md").symlink_to(victim)
    assert bench_main([*QUICK, "--out", str(out), "--no-figures", "--force"]) == 0
    assert victim.read_text() == "keep me"
    assert not (out / "summary.md").is_symlink()


def test_a_folder_with_other_files_is_never_replaced(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "thesis.tex").write_text("precious")
    assert "did not write (thesis.tex)" in _refused(
        [*QUICK, "--out", str(tmp_path), "--force"], capsys
    )
    assert (tmp_path / "thesis.tex").read_text() == "precious"


def test_an_unwritable_out_and_too_many_seeds_are_refused_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    ran: list[object] = []
    monkeypatch.setattr(cli, "run_bench", lambda *a, **k: ran.append(a))
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert "cannot write" in _refused([*QUICK, "--out", str(blocker / "out")], capsys)
    start = time.perf_counter()
    message = _refused(["--policies", "nn_dsc", "dsc", "--num-seeds", "1000000", "--scenarios",
                        "bench_mild", "--out", str(tmp_path / "o"), "--quiet"], capsys)  # fmt: skip
    assert time.perf_counter() - start < 5.0
    # batch: 2 policies x 1e6 fleets x (2000 steps x 256 B + 5 vessels x 32 KiB) = 1.35e12 B;
    # summary: 1e6 seeds x 62 metrics x 2000 replicates x 24 B = 2.976e12 B, the larger
    assert "2 policies x --num-seeds 1000000 need about 2771.6 GiB" in message
    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda path: type("U", (), {"free": 10}))
    assert "MiB free" in _refused([*QUICK, "--out", str(tmp_path / "o")], capsys)
    assert ran == []


def test_disk_full_while_writing_keeps_the_old_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "bench"
    assert bench_main([*QUICK, "--out", str(out), "--no-figures"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    real = atomic.write_text

    def full(path: Path, text: str) -> None:
        if Path(path).name == "summary.md":
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, text)

    monkeypatch.setattr(atomic, "write_text", full)
    err = _refused(
        [*QUICK, "--out", str(out), "--no-figures", "--force", "--num-seeds", "2"], capsys
    )
    assert "could not write the results" in err and "No space" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [".bench.lock", "bench"]


_HOLD = """
import sys, time
from cpf_env.infra import atomic
from cpf_env.scenarios.suite import list_suite
with atomic.FolderLock(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(60)
"""


def test_a_second_bench_on_the_same_out_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bench"
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(out)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        assert "being written by another cpf-bench" in _refused([*QUICK, "--out", str(out)], capsys)
    finally:
        holder.kill()
        holder.wait()


def test_episodes_csv_reads_back_bit_for_bit() -> None:
    """``read_episodes_csv`` inverts ``episodes_csv``: every cell, seed and metric (NaN too)."""
    import numpy as np

    from cpf_bench.episodes import METRICS
    from cpf_bench.report import CellResult, episodes_csv, read_episodes_csv

    rng = np.random.default_rng(0)
    cells = [
        CellResult(
            policy, scenario, seeds, False, {m: rng.normal(size=len(seeds)) for m in METRICS}
        )
        for policy, scenario, seeds in (
            ("mpc", "bench_mild", (10000, 10001)),
            ("a/agents/s0", "bench_mild", (10000, 10001)),
            ("mpc", "wang2014", (7,)),
        )
    ]
    cells[1].metrics["progress"][0] = np.nan
    back = read_episodes_csv(episodes_csv(cells))
    assert [(c.policy, c.scenario, c.seeds) for c in back] == [
        (c.policy, c.scenario, c.seeds) for c in cells
    ]
    for mine, theirs in zip(cells, back, strict=True):
        for metric in METRICS:
            np.testing.assert_array_equal(mine.metrics[metric], theirs.metrics[metric])
    with pytest.raises(ValueError, match="missing column"):
        read_episodes_csv("policy,scenario,seed,cost\nmpc,bench_mild,0,1.0\n")


def test_a_table_from_before_the_separation_metrics_reads_with_their_values() -> None:
    """An older episodes.csv (no scenario of its time had a separation) reads; a damaged one not."""
    import csv
    import io
    import math

    import numpy as np

    from cpf_bench.episodes import METRICS
    from cpf_bench.report import CellResult, episodes_csv, read_episodes_csv
    from cpf_env.evaluation.fleet_metrics import UNSEPARATED

    cell = CellResult("nn_dsc", "bench_mild", (10000,), False, {m: np.ones(1) for m in METRICS})

    def without(names: set[str]) -> str:
        rows = list(csv.reader(io.StringIO(episodes_csv([cell]))))
        keep = [k for k, name in enumerate(rows[0]) if name not in names]
        return "\n".join(",".join(row[k] for k in keep) for row in rows) + "\n"

    (old,) = read_episodes_csv(without(set(UNSEPARATED)))
    assert old.metrics["cost"][0] == 1.0 and old.metrics["cost_separation"][0] == 0.0
    assert math.copysign(1.0, old.metrics["cost_separation"][0]) == -1.0
    assert math.isnan(old.metrics["separation_min_window"][0])
    with pytest.raises(ValueError, match=r"missing column\(s\) \['separation_min'\]"):
        read_episodes_csv(without({"separation_min"}))


def test_track_hard_runs_the_hard_scenarios_and_names_the_track(tmp_path: Path) -> None:
    argv = ["--policies", "nn_dsc", "nn_dsc_ekf", "--track", "hard", "--num-seeds", "1",
            "--max-steps", "5", "--out", str(tmp_path), "--quiet", "--no-figures"]  # fmt: skip
    assert bench_main(argv) == 0
    summary = (tmp_path / "summary.md").read_text()
    assert f"hard track version {HARD_VERSION}" in summary
    assert "benchmark suite version" not in summary
    rows = (tmp_path / "episodes.csv").read_text().splitlines()[1:]
    assert sorted({row.split(",")[1] for row in rows}) == sorted(list_suite("hard"))


def test_track_and_scenarios_together_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        bench_main(["--track", "hard", "--scenarios", "bench_mild", "--out", "x"])
    assert "give --track for a whole track, or --scenarios" in capsys.readouterr().err
