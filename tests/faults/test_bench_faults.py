"""cpf-bench's output folder under kills, a full disk, links and a run too large for memory."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fault_injection import killed_at, small_disk

from cpf_commands.bench import cli
from cpf_commands.bench.cli import bench_main

QUICK = ["--policies", "nn_dsc", "--scenarios", "wang2014", "--quiet", "--no-figures"]
FILES = ["episodes.csv", "report.html", "summary.csv", "summary.md"]


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as raised:
        bench_main(argv)
    assert raised.value.code == 2
    return capsys.readouterr().err


def _results(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _leftovers(parent: Path, name: str) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith(f".{name}.") and
                  not p.name.endswith(".lock"))  # fmt: skip


def test_a_bench_killed_at_any_stage_leaves_old_or_new_and_the_next_run_sees_it(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Every stage, the two renames of the swap included: the next run without --force is
    refused (the recovery runs before the --force check) and finds old or new results whole."""
    old_run, new_run = [*QUICK, "--max-steps", "3"], [*QUICK, "--max-steps", "4"]
    assert bench_main([*new_run, "--out", str(tmp_path / "new")]) == 0
    assert bench_main([*old_run, "--out", str(tmp_path / "old")]) == 0
    new, old = _results(tmp_path / "new"), _results(tmp_path / "old")
    assert new != old and sorted(new) == FILES
    out = tmp_path / "out"
    stages = 0
    for stage in range(1, 60):
        shutil.copytree(tmp_path / "old", out)
        killed = killed_at(stage, lambda: bench_main([*new_run, "--out", str(out), "--force"]))
        # the next run without --force: refused, the folder whole (old, or new if swapped in)
        assert "--force" in _refused([*old_run, "--out", str(out)], capsys)
        assert _results(out) in (old, new), stage
        assert _leftovers(tmp_path, "out") == []
        if not killed:
            assert _results(out) == new
            break
        stages += 1
        shutil.rmtree(out)
    assert stages >= 16  # 4 files x (flush, rename, flush the folder) + the swap


def test_a_bench_killed_between_the_two_renames_is_restored_before_the_force_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert bench_main([*QUICK, "--max-steps", "3", "--out", str(out)]) == 0
    before = _results(out)
    out.rename(tmp_path / ".out.old-1764660000000000000-42")  # killed after the first rename
    assert "already holds cpf-bench results; pass --force" in _refused(
        [*QUICK, "--max-steps", "4", "--out", str(out)], capsys
    )
    assert _results(out) == before and _leftovers(tmp_path, "out") == []


def test_an_out_that_is_a_link_is_refused_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    ran: list[object] = []
    monkeypatch.setattr(cli, "run_bench", lambda *a, **k: ran.append(a))
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    assert "is a symbolic link" in _refused([*QUICK, "--out", str(tmp_path / "link")], capsys)
    assert ran == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]  # no .link.old-*


def test_a_lock_file_that_is_a_link_is_not_followed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    victim = tmp_path / "victim"
    (tmp_path / ".out.lock").symlink_to(victim)
    assert "symbolic link is refused" in _refused([*QUICK, "--out", str(tmp_path / "out")], capsys)
    assert not victim.exists()


def test_the_memory_check_counts_policies_x_seeds_x_series(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The probe's case: 8 policies x 5000 seeds of bench_large_fleet need about 31 GiB, not
    the 1.6 GiB once counted for one policy; with 8 GiB available it is refused at once."""
    ran: list[object] = []
    monkeypatch.setattr(cli, "run_bench", lambda *a, **k: ran.append(a) or [])
    monkeypatch.setattr(cli, "_available_memory", lambda: 8 * 2**30)
    policies = ["nn_dsc", "dsc", "nn_dsc_no_aux", "nn_dsc_global_v0", "backstepping",
                "nn_dsc_delay_comp", "backstepping_delay_comp", "nn_dsc_privileged"]  # fmt: skip
    argv = ["--policies", *policies, "--scenarios", "bench_large_fleet", "--num-seeds", "5000",
            "--out", str(tmp_path / "out"), "--quiet"]  # fmt: skip
    message = _refused(argv, capsys)
    # 8 x 5000 fleets x (2000 steps x 256 B + 10 vessels x 32 KiB) = 3.35872e10 B
    assert "8 policies x --num-seeds 5000 need about 31.3 GiB" in message
    assert ran == []
    monkeypatch.setattr(cli, "_available_memory", lambda: 32 * 2**30)
    assert bench_main(argv) == 0 and len(ran) == 1


def test_a_full_disk_while_writing_keeps_the_old_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    with small_disk(tmp_path, monkeypatch) as full_disk:
        out = full_disk.root / "out"
        assert bench_main([*QUICK, "--max-steps", "3", "--out", str(out)]) == 0
        before = _results(out)
        real = cli.run_bench

        def then_fill(*args: object, **kwargs: object) -> object:
            full_disk.fill()  # after the checks, before the outputs are written
            return real(*args, **kwargs)

        monkeypatch.setattr(cli, "run_bench", then_fill)
        err = _refused([*QUICK, "--max-steps", "4", "--out", str(out), "--force"], capsys)
        assert "could not write the results" in err and "No space left" in err
        assert _results(out) == before
        assert full_disk.entries() == [".out.lock", "out"]
