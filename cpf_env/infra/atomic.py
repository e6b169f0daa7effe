"""Files and folders that are never half-written, and a lock that refuses a second writer.

Every output of the package (an agent folder, a benchmark's results) is
written through these helpers, so a run killed at any moment leaves either
the old output or the new one, never a mix:

- ``write_bytes`` / ``write_text``: the data go to a temporary file beside
  the target, are flushed to disk, and the temporary file is renamed onto the
  target (``os.replace`` is atomic on POSIX and Windows). A target that is a
  symbolic link is replaced by a regular file; the link's target is left alone.
- ``staged_folder``: a context manager yielding an empty temporary sibling of
  the destination; on success the destination is replaced by it, on an error
  the sibling is removed and the destination is left as it was. Replacing an
  existing folder takes two renames (old -> ``.NAME.old-*``, new -> NAME);
  ``recover_folder`` (called by ``staged_folder`` and ``FolderLock``) restores
  the old folder if a process died between them; under the lock it also
  removes the staging folders of killed runs.
- ``FolderLock``: an advisory ``flock`` on ``.NAME.lock`` beside the folder
  (not inside it, since the folder itself is replaced); a second writer gets
  ``FolderLockedError`` at once instead of waiting. POSIX only.

This module imports nothing of the package, so every layer may use it.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import IO

__all__ = [
    "FolderLock",
    "FolderLockedError",
    "check_writable",
    "recover_folder",
    "staged_folder",
    "write_bytes",
    "write_text",
]


class FolderLockedError(RuntimeError):
    """Another process is writing the same folder."""


def _fsync_directory(directory: Path) -> None:
    """Flush a directory's entries (the renames) to disk where the OS allows it."""
    with contextlib.suppress(OSError):
        descriptor = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(descriptor)
        finally:
            os.close(descriptor)


def _umask() -> int:
    """The process's file-creation mask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary sibling, fsync, rename).

    Raises:
        OSError: The folder is not writable or the disk is full; ``path`` is then
            unchanged and no temporary file is left behind.
    """
    target = Path(path)
    descriptor, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        os.fchmod(descriptor, 0o666 & ~_umask())  # as open() would create it, not mkstemp's 0600
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(name, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(name)
        raise
    _fsync_directory(target.parent)


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically; see ``write_bytes``."""
    write_bytes(path, text.encode("utf-8"))


def _siblings(destination: Path, kind: str) -> list[Path]:
    """Leftover ``.NAME.<kind>-*`` siblings of ``destination``."""
    return sorted(destination.parent.glob(f".{destination.name}.{kind}-*"))


def recover_folder(destination: str | Path, remove_leftovers: bool = False) -> None:
    """Undo what a process killed while replacing ``destination`` left behind.

    If ``destination`` is missing but its previous version survives as
    ``.NAME.old-*`` (killed between the two renames), the old version is put
    back.

    Args:
        destination: The folder.
        remove_leftovers: Also delete leftover staging and retired folders
            (``.NAME.new-*``, ``.NAME.old-*``); only safe while holding the
            folder's ``FolderLock``, since another writer may be staging.
    """
    folder = Path(destination)
    if not folder.parent.is_dir():
        return
    old = _siblings(folder, "old")
    if old and not folder.exists():
        os.replace(old[-1], folder)
        old = old[:-1]
    if not remove_leftovers:
        return
    for leftover in [*old, *_siblings(folder, "new")]:
        shutil.rmtree(leftover, ignore_errors=True)


@contextlib.contextmanager
def staged_folder(destination: str | Path) -> Iterator[Path]:
    """Build a folder beside ``destination`` and swap it in only when complete.

    Args:
        destination: The folder to create or replace. Its parent is created.

    Yields:
        An empty temporary folder on the same file system; write everything there.

    Raises:
        OSError: The parent is not writable. On any error inside the block the
            staging folder is removed and ``destination`` is unchanged.
    """
    folder = Path(destination)
    folder.parent.mkdir(parents=True, exist_ok=True)
    recover_folder(folder)
    staging = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.new-"))
    try:
        staging.chmod(0o777 & ~_umask())  # as mkdir would create it, not mkdtemp's 0700
        yield staging
        _fsync_directory(staging)
        if folder.exists():
            retired = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.old-"))
            os.replace(folder, retired)  # an empty directory is replaced by rename
            os.replace(staging, folder)
            shutil.rmtree(retired, ignore_errors=True)
        else:
            os.replace(staging, folder)
        _fsync_directory(folder.parent)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def check_writable(destination: str | Path, needed_bytes: int = 0) -> None:
    """Fail before a long run if ``destination`` cannot be written.

    Creates the parent folders, writes and removes a probe file beside
    ``destination`` and checks the free space.

    Args:
        destination: The output folder that will be created or replaced.
        needed_bytes: Free space the outputs need (0: do not check).

    Raises:
        ValueError: The location is not writable or has too little free space,
            with what to do about it.
    """
    folder = Path(destination)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder.parent, prefix=f".{folder.name}.probe-"):
            pass
    except OSError as error:
        raise ValueError(
            f"cannot write to {folder}: {error.strerror or error}; choose a writable output folder."
        ) from error
    free = shutil.disk_usage(folder.parent).free
    if needed_bytes and free < needed_bytes:
        raise ValueError(
            f"{folder.parent} has {free / 2**20:.1f} MiB free but the outputs need about "
            f"{needed_bytes / 2**20:.1f} MiB; free some space or choose another output folder."
        )


class FolderLock:
    """Exclusive advisory lock on a folder, held as ``.NAME.lock`` beside it.

    Example:
        >>> import tempfile
        >>> root = Path(tempfile.mkdtemp())
        >>> with FolderLock(root / "out"):
        ...     FolderLock(root / "out").acquire()
        Traceback (most recent call last):
        ...
        cpf_env.infra.atomic.FolderLockedError: ...

    Args:
        folder: The folder a writer is about to create or replace.
        what: How the error message names the writer (e.g. ``"cpf-bench"``).
    """

    def __init__(self, folder: str | Path, what: str = "another process") -> None:
        self.folder = Path(folder)
        self.what = what
        self.path = self.folder.parent / f".{self.folder.name}.lock"
        self._handle: IO[str] | None = None

    def acquire(self) -> None:
        """Take the lock (creating the parent folders).

        Raises:
            FolderLockedError: Another process holds it.
        """
        import fcntl

        self.folder.parent.mkdir(parents=True, exist_ok=True)
        handle = open(self.path, "a")  # held until release()
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            raise FolderLockedError(
                f"{self.folder} is being written by {self.what} (it holds {self.path}); wait "
                "for it to finish or choose another folder."
            ) from None
        self._handle = handle
        recover_folder(self.folder, remove_leftovers=True)

    def release(self) -> None:
        """Release the lock (the lock file stays; it is empty)."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None

    def __enter__(self) -> FolderLock:
        self.acquire()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.release()
