"""Files and folders that are never half-written, and a lock that refuses a second writer.

Every output of the package (an agent folder, a benchmark's results) is
written through these helpers, so a run killed at any moment leaves either
the old output or the new one, never a mix:

- ``write_bytes`` / ``write_text``: the data go to a temporary file beside
  the target, are flushed to disk, and the temporary file is renamed onto the
  target (``os.replace`` is atomic on POSIX and Windows). A target that is a
  symbolic link is replaced by a regular file; the link's target is left alone.
- ``staged_folder``: a context manager yielding an empty temporary sibling of
  the destination (``.NAME.new-*``, ``new_staging_folder``); on success the
  destination is replaced by it (``swap_in``), on an error the sibling is
  removed and the destination is left as it was. Replacing an existing
  folder takes two renames (old -> ``.NAME.old-*``, new -> NAME);
  ``recover_folder`` restores the old folder if a process died between them
  and removes the staging folders of killed writers.
- ``FolderLock``: an advisory ``flock`` on ``.NAME.lock`` beside the folder
  (not inside it, since the folder itself is replaced); a second writer gets
  ``FolderLockedError`` at once instead of waiting. As soon as it holds the
  lock it runs ``recover_folder``, so a command sees the folder as the last
  complete writer left it before it decides anything about it (whether
  ``--force`` is needed, whether a run can be resumed). POSIX only.
- ``check_writable``: what a command checks before it starts working: the
  destination is not a symbolic link, its parent is writable and has the
  free space the outputs need.

Nothing is written through a symbolic link: a destination that is one is
refused (``refuse_link``, called by ``check_writable``, ``staged_folder`` and
``swap_in``), the lock file is opened with ``O_NOFOLLOW``, and a link left
inside an old folder goes with that folder, its target untouched.

This module imports nothing of the package, so every layer may use it.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import IO

__all__ = [
    "FolderLock",
    "FolderLockedError",
    "check_writable",
    "new_staging_folder",
    "recover_folder",
    "refuse_link",
    "staged_folder",
    "swap_in",
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
    """Leftover ``.NAME.<kind>-*`` siblings of ``destination`` (oldest first)."""
    return sorted(destination.parent.glob(f".{destination.name}.{kind}-*"))


def recover_folder(destination: str | Path, remove_leftovers: bool = False) -> None:
    """Undo what a process killed while replacing ``destination`` left behind.

    If ``destination`` is missing but its previous version survives as
    ``.NAME.old-*`` (killed between the two renames of ``swap_in``), the old
    version is put back.

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
    if old and not os.path.lexists(folder):
        os.rename(old[-1], folder)
        old = old[:-1]
        _fsync_directory(folder.parent)
    if not remove_leftovers:
        return
    for leftover in [*old, *_siblings(folder, "new")]:
        if leftover.is_dir() and not leftover.is_symlink():
            shutil.rmtree(leftover, ignore_errors=True)
        else:
            leftover.unlink(missing_ok=True)


def refuse_link(path: str | Path) -> None:
    """Refuse an output location that is a symbolic link: nothing is written through one.

    Raises:
        ValueError: ``path`` is a symbolic link, with what to do about it.
    """
    target = Path(path)
    if target.is_symlink():
        raise ValueError(
            f"{target} is a symbolic link (to {os.readlink(target)}); outputs are never "
            "written through a link: give the real path, or another one."
        )


def _refuse_file(folder: Path) -> None:
    """Refuse a folder destination that is a link or an existing file."""
    refuse_link(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{folder} is a file; give a folder (it is created if needed).")


def new_staging_folder(destination: str | Path) -> Path:
    """An empty ``.NAME.new-*`` sibling of ``destination`` to build its next version in.

    ``swap_in`` makes it the destination; the staging folder of a killed writer
    is removed by the next ``FolderLock`` on the destination. The parent is created.
    """
    folder = Path(destination)
    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.new-"))
    staging.chmod(0o777 & ~_umask())  # as mkdir would create it, not mkdtemp's 0700
    return staging


def swap_in(staging: str | Path, destination: str | Path) -> None:
    """Make the complete folder ``staging`` the ``destination``, replacing the old one whole.

    Two renames (old -> ``.NAME.old-<time>-<pid>``, staging -> NAME); a
    process killed between them leaves the old version as ``.NAME.old-*``,
    which ``recover_folder`` puts back. The old version is then deleted.

    Raises:
        ValueError: ``destination`` is a symbolic link or a file; nothing is renamed.
    """
    new, folder = Path(staging), Path(destination)
    _refuse_file(folder)
    _fsync_directory(new)
    if folder.exists():
        retired = folder.parent / f".{folder.name}.old-{time.time_ns()}-{os.getpid()}"
        os.rename(folder, retired)
        os.rename(new, folder)
        _fsync_directory(folder.parent)
        shutil.rmtree(retired, ignore_errors=True)
    else:
        os.rename(new, folder)
        _fsync_directory(folder.parent)


@contextlib.contextmanager
def staged_folder(destination: str | Path) -> Iterator[Path]:
    """Build a folder beside ``destination`` and swap it in only when complete.

    Args:
        destination: The folder to create or replace. Its parent is created.

    Yields:
        An empty temporary folder on the same file system; write everything there.

    Raises:
        ValueError: ``destination`` is a symbolic link or a file (refused before
            anything is built).
        OSError: The parent is not writable. On any error inside the block the
            staging folder is removed and ``destination`` is unchanged.
    """
    folder = Path(destination)
    _refuse_file(folder)
    recover_folder(folder)
    staging = new_staging_folder(folder)
    try:
        yield staging
        swap_in(staging, folder)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def check_writable(destination: str | Path, needed_bytes: int = 0) -> None:
    """Fail before a long run if ``destination`` cannot be written.

    Refuses a destination that is a symbolic link, creates the parent folders,
    writes and removes a probe file beside ``destination`` and checks the free
    space.

    Args:
        destination: The output (a folder or a file) that will be created or replaced.
        needed_bytes: Free space the outputs need (0: do not check).

    Raises:
        ValueError: The location is a link, is not writable or has too little free
            space, with what to do about it.
    """
    folder = Path(destination)
    refuse_link(folder)
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

        Then, holding it, puts back a folder whose replacement was killed
        between its two renames and removes the staging folders of killed
        writers (``recover_folder``).

        Raises:
            FolderLockedError: Another process holds it.
            ValueError: The lock file cannot be opened (or is a symbolic link).
        """
        import fcntl

        self.folder.parent.mkdir(parents=True, exist_ok=True)
        try:  # never through a link
            descriptor = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o666)
        except OSError as error:
            raise ValueError(
                f"cannot open the lock file {self.path}: {error.strerror or error} (a symbolic "
                "link is refused); remove it or choose another folder."
            ) from error
        handle = os.fdopen(descriptor, "w")  # held until release()
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            raise FolderLockedError(
                f"{self.folder} is being written by {self.what} (it holds {self.path}); wait "
                "for it to finish or choose another folder."
            ) from None
        self._handle = handle
        try:
            recover_folder(self.folder, remove_leftovers=True)
        except BaseException:
            self.release()
            raise

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
