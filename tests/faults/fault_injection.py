"""Fault injection for the writers: kills at every file-system stage, a full disk.

A plain module (not a conftest: ``tests/conftest.py`` is imported by name), so the
tests import what they use. ``killed_at(k, write)`` runs ``write`` in a forked child
whose ``cpf_env.infra.atomic``
sees a stand-in ``os`` module that SIGKILLs the process just before its k-th
file-system stage (an ``fsync``, ``replace`` or ``rename``: a file written but
not flushed, flushed but not renamed into place, a folder between the two
renames of its swap, ...). Counting k up until the child finishes visits
every stage of a writer; the child is really killed (no ``finally``, no
cleanup), so the parent sees what a crash leaves on disk. ``KillingOs`` is
importable by a subprocess driver for the kills of a fresh process.

``small_disk(tmp_path, monkeypatch)`` gives a folder on a small file system: a
16 MiB tmpfs mounted for the test where the machine allows it (root on Linux),
whose ``fill()`` then takes all of its free space, so writes fail with a real
ENOSPC; where mounting is not allowed, ``fill()`` makes
``cpf_env.infra.atomic.write_bytes`` raise ENOSPC instead (``FullDisk.real`` says which).
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from cpf_env.infra import atomic

#: The calls of ``os`` in ``cpf_env.infra.atomic`` that a kill is injected before.
STAGES = frozenset({"fsync", "replace", "rename"})


class KillingOs:
    """``os`` for ``cpf_env.infra.atomic`` that SIGKILLs the process before its ``at``-th stage."""

    def __init__(self, at: int) -> None:
        self.at, self.count = at, 0

    def __getattr__(self, name: str) -> Any:
        real = getattr(os, name)
        if name not in STAGES:
            return real

        def stage(*args: Any, **kwargs: Any) -> Any:
            self.count += 1
            if self.count == self.at:
                os.kill(os.getpid(), signal.SIGKILL)
            return real(*args, **kwargs)

        return stage


def killed_at(at: int, write: Callable[[], object]) -> bool:
    """Run ``write`` in a child killed at its ``at``-th stage; False if it finished first."""
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code = 0
        try:
            atomic.os = KillingOs(at)
            write()
        except BaseException:
            traceback.print_exc()
            code = 1
        os._exit(code)
    deadline = time.monotonic() + 120.0
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            pytest.fail(f"the writer killed at stage {at} hung")
        time.sleep(0.005)
    if os.WIFSIGNALED(status):
        assert os.WTERMSIG(status) == signal.SIGKILL
        return True
    assert os.WEXITSTATUS(status) == 0, f"the writer failed (not killed) at stage {at}"
    return False


class FullDisk:
    """A folder on a small file system, and a way to fill it."""

    def __init__(self, root: Path, real: bool, monkeypatch: pytest.MonkeyPatch) -> None:
        self.root, self.real, self._monkeypatch = root, real, monkeypatch

    def fill(self) -> None:
        """Take all the free space (real), or make every atomic write fail (fallback)."""
        if not self.real:
            self._monkeypatch.setattr(atomic, "write_bytes", _no_space)
            return
        with open(self.root / "filler", "wb", buffering=0) as handle:
            block = b"\0" * 2**16
            try:
                while True:
                    handle.write(block)
            except OSError as error:
                assert error.errno == errno.ENOSPC
        while True:  # the last partial blocks too
            try:
                with open(self.root / f"filler-{time.monotonic_ns()}", "wb", buffering=0) as handle:
                    handle.write(b"\0")
            except OSError:
                break

    def empty(self) -> None:
        """Give the space back (or the writes)."""
        if not self.real:
            self._monkeypatch.setattr(atomic, "write_bytes", _WRITE_BYTES)
        for filler in self.root.glob("filler*"):
            filler.unlink()

    def entries(self) -> list[str]:
        """Names in the root, the filler left out."""
        return sorted(p.name for p in self.root.iterdir() if not p.name.startswith("filler"))


_WRITE_BYTES = atomic.write_bytes


def _no_space(path: object, data: bytes) -> None:
    raise OSError(errno.ENOSPC, "No space left on device")


def _mount_tmpfs(root: Path) -> bool:
    if sys.platform != "linux" or os.geteuid() != 0:
        return False
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=16m", "tmpfs", str(root)],
        capture_output=True,
        check=False,
    )
    return mounted.returncode == 0


@contextlib.contextmanager
def small_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[FullDisk]:
    """A 16 MiB tmpfs (or the ENOSPC fallback) to fill while a writer runs."""
    root = tmp_path / "small"
    root.mkdir()
    real = _mount_tmpfs(root)
    try:
        yield FullDisk(root, real, monkeypatch)
    finally:
        if real:
            subprocess.run(["umount", "-l", str(root)], check=False)
