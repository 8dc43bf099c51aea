"""A command never writes over its own inputs.

A command names the files it reads, each with the words that tell the user what it is ("the poses file being
exported"), and the files it is about to write; :func:`keep_inputs` refuses an output that is the same file as one of
the inputs, before any work is done, with a one-line TrackerInputError that names the file and the fix. Two paths
are the same file when they reach the same file on disk (``os.path.samefile``): another spelling of the path, a
symbolic or a hard link. Only existing files are compared: a file not there yet is nobody's input.
"""

from __future__ import annotations

import os
from collections.abc import Iterable

from tracker.errors import TrackerInputError

Given = str | os.PathLike | None
"""A path as a command has it: None for an option not given."""


def same_file(first: str | os.PathLike, second: str | os.PathLike) -> bool:
    """Whether ``first`` and ``second`` are one existing file (or folder)."""
    try:
        return os.path.samefile(first, second)
    except OSError:  # one of them does not exist (or cannot be looked at): not one existing file
        return False


def keep_inputs(outputs: Iterable[Given], inputs: Iterable[tuple[Given, str]], fix: str) -> None:
    """Raise ``OUTPUT: is WHAT; FIX`` for the first of ``outputs`` that is the same file as one of ``inputs``, each
    a path and what it is ("the calibration being refined"); paths that are None are left out."""
    read = [(path, what) for path, what in inputs if path is not None]
    for output in outputs:
        for path, what in read:
            if output is not None and same_file(output, path):
                raise TrackerInputError(f"{output}: is {what}; {fix}")
