"""Atomic files and folders, and the writer's lock: killed or failed writes leave the old state."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cpf_env.infra import atomic


def test_a_failed_write_leaves_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "summary.md"
    target.write_text("old")

    def disk_full(*args: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", disk_full)
    with pytest.raises(OSError, match="No space"):
        atomic.write_text(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["summary.md"]


def test_a_symlink_is_replaced_not_followed(tmp_path: Path) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    link = tmp_path / "summary.md"
    link.symlink_to(victim)
    atomic.write_text(link, "results")
    assert victim.read_text() == "keep me"
    assert not link.is_symlink() and link.read_text() == "results"


def test_a_failed_staged_folder_leaves_the_old_folder(tmp_path: Path) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "a.csv").write_text("old")
    with pytest.raises(RuntimeError), atomic.staged_folder(folder) as staging:
        (staging / "a.csv").write_text("new")
        raise RuntimeError("killed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert (folder / "a.csv").read_text() == "old"
    with atomic.staged_folder(folder) as staging:
        (staging / "b.csv").write_text("new")
    assert sorted(p.name for p in folder.iterdir()) == ["b.csv"]  # whole, nothing stale


_KILLED_WHILE_STAGING = """
import os, signal, sys
from cpf_env.infra import atomic
with atomic.FolderLock(sys.argv[1]), atomic.staged_folder(sys.argv[1]) as staging:
    (staging / "half.csv").write_text("half")
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_killed_writer_leaves_the_old_folder_and_the_next_one_cleans_up(tmp_path: Path) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "a.csv").write_text("old")
    run = subprocess.run([sys.executable, "-c", _KILLED_WHILE_STAGING, str(folder)], check=False)
    assert run.returncode == -signal.SIGKILL
    assert (folder / "a.csv").read_text() == "old" and not (folder / "half.csv").exists()
    assert any(p.name.startswith(".out.new-") for p in tmp_path.iterdir())
    with atomic.FolderLock(folder):
        pass
    assert not any(p.name.startswith(".out.new-") for p in tmp_path.iterdir())


def test_a_folder_killed_between_the_two_renames_is_restored(tmp_path: Path) -> None:
    retired = tmp_path / ".out.old-x1"
    retired.mkdir()
    (retired / "a.csv").write_text("old")
    atomic.recover_folder(tmp_path / "out")
    assert (tmp_path / "out" / "a.csv").read_text() == "old"


_HOLD_LOCK = """
import sys, time
from cpf_env.infra import atomic
with atomic.FolderLock(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(60)
"""


def test_a_second_writer_is_refused(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD_LOCK, str(tmp_path / "out")], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        with pytest.raises(atomic.FolderLockedError, match="being written"):
            atomic.FolderLock(tmp_path / "out").acquire()
    finally:
        holder.kill()
        holder.wait()
    with atomic.FolderLock(tmp_path / "out"):  # free again once the holder is gone
        pass


def test_check_writable_reports_an_unusable_location(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ValueError, match="cannot write"):
        atomic.check_writable(blocker / "out")
    with pytest.raises(ValueError, match="MiB free"):
        atomic.check_writable(tmp_path / "out", needed_bytes=2**62)
