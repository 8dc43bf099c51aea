"""Atomic file writes: a reader sees the old file or the new one, never a partial one.

The content goes to a temporary file in the target's folder (same file system),
is flushed to disk, then renamed over the target with ``os.replace``, which
POSIX and Windows perform atomically. A write that fails is a one-line error
naming the file and the fix its cause calls for: a full disk, a folder where
the file goes, a file where a folder goes, a folder the user may not write to.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from tracker.errors import TrackerInputError


def ensure_writable_folder(folder: str | os.PathLike) -> Path:
    """Create ``folder`` (and parents) if missing and check a file can be created in it.

    Raises TrackerInputError when the folder cannot be created or written, so a
    long run fails before it starts rather than at its first save.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise TrackerInputError(
            f"{folder}: cannot write there ({error.strerror or error}); {_fix(folder, error)}"
        ) from None
    return folder


def writable_file(path: str | os.PathLike) -> Path:
    """``path``, checked now that a file can be written there (its folder made if missing and writable, and no
    folder in its place), so that a long run fails before it starts rather than at its end."""
    path = Path(path)
    ensure_writable_folder(path.parent)
    if path.is_dir():
        raise TrackerInputError(f"{path}: is a folder; give the name of a file to write")
    return path


def temporary_beside(path: Path, suffix: str | None = None) -> Path:
    """A new hidden file name in ``path``'s folder (same file system), to write before :func:`replace_with`; it ends
    in ``suffix`` (default ``path``'s suffix) for writers that pick the format by it or add it when missing."""
    ending = path.suffix if suffix is None else suffix
    return path.with_name(f".{path.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{ending}")


def replace_with(temp: Path, path: Path) -> None:
    """Rename the finished ``temp`` over ``path`` (atomic); an OS error removes ``temp`` and becomes a
    TrackerInputError naming ``path``."""
    try:
        os.replace(temp, path)
    except OSError as error:
        temp.unlink(missing_ok=True)
        raise _cannot_write(path, error) from None


def _cannot_write(path: Path, error: OSError) -> TrackerInputError:
    return TrackerInputError(f"{path}: cannot write ({error.strerror or error}); {_fix(path, error)}")


FULL = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}
"""The errors of a disk (or a quota) that is full."""


def _fix(path: Path, error: OSError) -> str:
    """What to do when writing ``path`` (a file, or a folder to write in) failed with ``error``."""
    if error.errno in FULL:
        return "free disk space or choose an output folder on another disk"
    if error.errno == errno.EISDIR:
        return "it is a folder; give the name of a file to write"
    if error.errno in (errno.ENOTDIR, errno.EEXIST):  # mkdir met a file where a folder should be
        return f"{_file_in_the_way(path)} is a file, not a folder; choose another output path"
    if error.errno == errno.ENAMETOOLONG:
        return "choose a shorter output path"
    return "choose a writable output folder"  # permission denied, a read-only file system, and the rest


def _file_in_the_way(path: Path) -> Path:
    """The part of ``path`` that is a file where a folder should be (``path`` itself when none is found)."""
    return next((part for part in (path, *path.parents) if part.exists() and not part.is_dir()), path)


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """For writers that only take a file name: yields a temporary path beside ``path`` (ending in ``suffix``, see
    :func:`temporary_beside`) that replaces it when the block ends without error (and is removed otherwise)."""
    path = Path(path)
    ensure_writable_folder(path.parent)
    temp = temporary_beside(path, suffix)
    try:
        yield temp
        replace_with(temp, path)
    finally:
        temp.unlink(missing_ok=True)


def atomic_write(path: str | os.PathLike, write_fn: Callable[[BinaryIO], object]) -> None:
    """Write ``path`` atomically: ``write_fn(file)`` fills a temporary binary file that then replaces ``path``.

    The folder is created if missing. The file gets the usual permissions
    (0o666 minus the umask). On any error the temporary file is removed and
    ``path`` is left as it was; OS errors become TrackerInputError naming the file.
    """
    with atomic_path(path) as temp:
        try:
            fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
            with os.fdopen(fd, "wb") as file:
                write_fn(file)
                file.flush()
                os.fsync(file.fileno())
        except OSError as error:
            raise _cannot_write(Path(path), error) from None


_TEMPORARY = re.compile(r"\..*\.\d+\.[0-9a-f]{8}\.tmp(\.[^.]+)?")
"""The names :func:`temporary_beside` gives."""


def remove_temporaries(folder: str | os.PathLike) -> None:
    """Remove the temporary files (:func:`temporary_beside`) left in ``folder`` and below it by writes that a killed
    process could not finish or clean up; no process may be writing there."""
    for path in Path(folder).rglob(".*"):
        if _TEMPORARY.fullmatch(path.name) and path.is_file():
            path.unlink(missing_ok=True)
