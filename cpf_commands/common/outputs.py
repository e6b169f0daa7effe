"""A command's output folder: checked before the run, locked during it, replaced at once.

A command that writes a folder of results (``cpf-bench --out``, ``cpf-run
--out``) calls ``claim_output_folder`` before it starts working, so that every
reason the outputs could not be written is reported at once rather than after
the run: the path is a file or a symbolic link, the folder holds files the
command did not write (it would replace them), it holds results and
``--force`` was not given, it is not writable, or its disk is too full. It
takes the folder's lock first: a second writer is refused, and a folder whose
replacement was killed between its two renames is put back before the
``--force`` decision is made on it. The returned lock refuses a second
writer until the command ends. The outputs are then written with
``cpf_env.infra.atomic.staged_folder``: the folder is replaced by a complete new
one, so stale files of an earlier run (figures a ``--no-figures`` run does not
draw) disappear and a symbolic link in the old folder is never followed.
"""

from __future__ import annotations

from collections.abc import Collection
from fnmatch import fnmatchcase
from pathlib import Path

from cpf_env.infra import atomic

__all__ = ["claim_output_folder", "foreign_files"]


def foreign_files(folder: Path, owned: Collection[str]) -> list[str]:
    """Names in ``folder`` that the command does not write (sorted; [] if it does not exist).

    Args:
        folder: The output folder.
        owned: The names the command writes, or shell patterns of them (``fig*.png``).
    """
    if not folder.is_dir():
        return []
    return sorted(
        entry.name
        for entry in folder.iterdir()
        if not any(fnmatchcase(entry.name, pattern) for pattern in owned)
    )


def claim_output_folder(
    out: str | Path,
    owned: Collection[str],
    force: bool,
    command: str,
    needed_bytes: int = 0,
) -> atomic.FolderLock:
    """Check that ``out`` can take the command's outputs, and lock it.

    Args:
        out: The output folder (created when the outputs are written).
        owned: File names (or shell patterns) the command writes there.
        force: Replace earlier results (``--force``).
        command: The command's name, for the messages.
        needed_bytes: Free space the outputs need.

    Returns:
        The acquired lock; release it when the outputs are written.

    Raises:
        ValueError: ``out`` is empty, a file or a symbolic link, holds other
            files, holds results without ``force``, is not writable or lacks
            space; or another ``command`` writes it now (each message says what
            to do).
    """
    if not str(out).strip():
        raise ValueError(f"--out is empty; give {command} an output folder.")
    folder = Path(out)
    atomic.refuse_link(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"--out {folder} is a file; give a folder (it is created if needed).")
    atomic.check_writable(folder, needed_bytes)
    lock = atomic.FolderLock(folder, f"another {command}")
    try:
        lock.acquire()  # recovers a folder whose replacement was killed, before the checks
    except atomic.FolderLockedError as error:
        raise ValueError(str(error)) from None
    try:
        others = foreign_files(folder, owned)
        if others:
            raise ValueError(
                f"--out {folder} holds files {command} did not write ({', '.join(others[:5])}); "
                f"{command} replaces its output folder as a whole, so give an empty or new folder."
            )
        if folder.is_dir() and any(folder.iterdir()) and not force:
            raise ValueError(
                f"--out {folder} already holds {command} results; pass --force to replace them "
                "or choose another folder."
            )
    except BaseException:
        lock.release()
        raise
    return lock
