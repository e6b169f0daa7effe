"""cpf-run's output folder: refused without --force, locked, written whole, never through a link."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from fault_injection import killed_at, small_disk

from cpf_commands.run import reproduce as reproduce_module
from cpf_commands.run.cli import run_main
from cpf_commands.run.reproduce import reproduce
from cpf_env.infra import atomic

QUICK = ["--scenario", "wang2014", "--max-steps", "3", "--quiet", "--no-figures"]
FOLDER = "wang2014_nn_dsc"


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as raised:
        run_main(argv)
    assert raised.value.code == 2
    return capsys.readouterr().err


def _results(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _write(out: Path, seed: int, force: bool = False) -> None:
    replace = {"force": True} if force else {}
    reproduce("wang2014", "nn_dsc", seed=seed, max_steps=3, out=out, figures=False, **replace)


def test_an_existing_output_needs_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_main([*QUICK, "--out", str(tmp_path)]) == 0
    before = _results(tmp_path / FOLDER)
    assert "pass --force" in _refused([*QUICK, "--out", str(tmp_path), "--seed", "1"], capsys)
    assert _results(tmp_path / FOLDER) == before
    assert run_main([*QUICK, "--out", str(tmp_path), "--seed", "1", "--force"]) == 0
    assert _results(tmp_path / FOLDER) != before


def test_a_run_killed_at_any_stage_leaves_old_or_new_whole(tmp_path: Path) -> None:
    """Never a new metrics.json beside an old or half-written trajectory.npz."""
    _write(tmp_path / "new", seed=1)
    _write(tmp_path / "old", seed=0)
    new, old = _results(tmp_path / "new" / FOLDER), _results(tmp_path / "old" / FOLDER)
    assert sorted(new) == ["metrics.json", "trajectory.npz"] and new != old
    out = tmp_path / "out"
    stages = 0
    for stage in range(1, 40):
        shutil.copytree(tmp_path / "old", out)
        killed = killed_at(stage, lambda: _write(out, seed=1, force=True))
        with pytest.raises(ValueError, match="pass --force"):  # recovered first, then refused
            _write(out, seed=1)
        assert _results(out / FOLDER) in (old, new), stage
        assert sorted(p.name for p in out.iterdir()) == [f".{FOLDER}.lock", FOLDER]
        if not killed:
            assert _results(out / FOLDER) == new
            break
        stages += 1
        shutil.rmtree(out)
    assert stages >= 7  # metrics.json (flush, rename, flush the folder) + the swap


_HOLD = """
import sys, time
from cpf_env.infra import atomic
with atomic.FolderLock(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(60)
"""


def test_a_second_run_on_the_same_output_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(tmp_path / FOLDER)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        err = _refused([*QUICK, "--out", str(tmp_path)], capsys)
        assert "being written by another cpf-run" in err
    finally:
        holder.kill()
        holder.wait()
    assert not (tmp_path / FOLDER).exists()


def test_two_concurrent_runs_on_one_output_one_wins(tmp_path: Path) -> None:
    """Two processes at once: one writes, the other is refused (locked, or results exist)."""
    children = []
    for seed in (0, 1):
        pid = os.fork()
        if pid == 0:
            code = 0
            try:
                _write(tmp_path, seed=seed)
            except ValueError:
                code = 3
            except BaseException:
                code = 1
            os._exit(code)
        children.append(pid)
    codes = sorted(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) for pid in children)
    assert codes == [0, 3]
    assert sorted(p.name for p in (tmp_path / FOLDER).iterdir()) == [
        "metrics.json",
        "trajectory.npz",
    ]


def test_a_linked_metrics_file_is_not_followed(tmp_path: Path) -> None:
    victim = tmp_path / "victim.json"
    victim.write_text("keep me")
    (tmp_path / FOLDER).mkdir()
    (tmp_path / FOLDER / "metrics.json").symlink_to(victim)
    with pytest.raises(ValueError, match="pass --force"):  # it holds results (a link to some)
        _write(tmp_path, seed=0)
    assert victim.read_text() == "keep me"
    _write(tmp_path, seed=1, force=True)  # replaced whole: the link goes, its target stays
    assert victim.read_text() == "keep me"
    assert not (tmp_path / FOLDER / "metrics.json").is_symlink()


def test_an_output_that_is_a_link_is_refused_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    ran: list[object] = []
    monkeypatch.setattr(reproduce_module, "run_episode", lambda *a, **k: ran.append(a))
    (tmp_path / "real").mkdir()
    (tmp_path / FOLDER).symlink_to(tmp_path / "real")
    assert "is a symbolic link" in _refused([*QUICK, "--out", str(tmp_path)], capsys)
    assert ran == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["real", FOLDER]  # no .NAME.old-*


def test_a_full_disk_while_writing_is_one_line_and_keeps_the_old_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    with small_disk(tmp_path, monkeypatch) as full_disk:
        out = full_disk.root
        real = reproduce_module.run_episode
        filled = []

        def then_fill(*args: object, **kwargs: object) -> object:
            trajectory = real(*args, **kwargs)
            if filled:
                full_disk.fill()  # after the checks, before the outputs are written
            return trajectory

        monkeypatch.setattr(reproduce_module, "run_episode", then_fill)
        assert run_main([*QUICK, "--out", str(out)]) == 0
        before = _results(out / FOLDER)
        filled.append(True)
        err = _refused([*QUICK, "--out", str(out / "fresh")], capsys)  # no traceback
        assert "could not write the results" in err and "No space left" in err
        assert list((out / "fresh").iterdir()) == [out / "fresh" / f".{FOLDER}.lock"]  # no half
        full_disk.empty()
        err = _refused([*QUICK, "--out", str(out), "--seed", "1", "--force"], capsys)
        assert "could not write the results" in err and "No space left" in err
        assert _results(out / FOLDER) == before
        assert full_disk.entries() == [f".{FOLDER}.lock", "fresh", FOLDER]


def test_too_little_space_is_refused_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    ran: list[object] = []
    monkeypatch.setattr(reproduce_module, "run_episode", lambda *a, **k: ran.append(a))
    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda path: type("U", (), {"free": 10}))
    assert "MiB free" in _refused([*QUICK, "--out", str(tmp_path)], capsys)
    assert ran == []


_KILLED_RUN = """
import sys
sys.path.insert(0, sys.argv[1])
from fault_injection import KillingOs
from cpf_commands.run.cli import run_main
from cpf_env.infra import atomic
atomic.os = KillingOs(int(sys.argv[2]))
run_main(sys.argv[3:])
"""


def test_a_fresh_process_killed_between_the_two_renames_is_restored(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A real cpf-run process, SIGKILLed after the old folder was renamed away."""
    assert run_main([*QUICK, "--out", str(tmp_path)]) == 0
    before = _results(tmp_path / FOLDER)
    # stages: metrics.json (flush, rename, flush the folder), the swap (flush, rename, rename)
    argv = [*QUICK, "--out", str(tmp_path), "--seed", "1", "--force"]
    here = str(Path(__file__).parent)
    killed = subprocess.run([sys.executable, "-c", _KILLED_RUN, here, "6", *argv], check=False)
    assert killed.returncode == -9
    assert not (tmp_path / FOLDER).exists()
    assert [p.name[: len(FOLDER) + 6] for p in tmp_path.glob(".*.old-*")] == [f".{FOLDER}.old-"]
    assert "pass --force" in _refused([*QUICK, "--out", str(tmp_path), "--seed", "1"], capsys)
    assert _results(tmp_path / FOLDER) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [f".{FOLDER}.lock", FOLDER]
