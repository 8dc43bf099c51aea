"""Reading ``.npz`` archives of plain arrays (poses, truth, keypoints) with one-line errors that name the file and
the fix.

NumPy takes any file that is neither a zip archive nor an ``.npy`` array for pickled data, and refuses it as such
when pickles are not allowed: the tracker looks at the file's first bytes itself, so that a text file, an empty one
or a single array is called what it is.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError

ZIP = b"PK"
"""How an .npz archive (a zip file) begins."""

NPY = b"\x93NUMPY"
"""How a single ``.npy`` array begins."""


def read_npz(path: str | os.PathLike, what: str, fix: str) -> dict[str, np.ndarray]:
    """The arrays of the .npz archive at ``path``, read without pickle. ``what`` names the file the reader wants
    ("a poses file") and ``fix`` says what to do about a file that is not one or not readable."""
    path = Path(path)
    try:
        with open(path, "rb") as file:
            start = file.read(512)
    except FileNotFoundError:
        raise TrackerInputError(f"{path}: file not found; check the path") from None
    except IsADirectoryError:
        raise TrackerInputError(f"{path}: is a folder, not {what}; {fix}") from None
    except OSError as error:
        raise TrackerInputError(f"{path}: cannot read it ({error.strerror or error}); {fix}") from None
    if not start.startswith(ZIP):
        raise TrackerInputError(f"{path}: not {what} (an .npz archive) but {_kind(start)}; {fix}")
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {key: archive[key] for key in archive.files}
    except ValueError as error:
        if "Object arrays" in str(error) or "pickle" in str(error):
            raise TrackerInputError(
                f"{path}: holds object arrays, which only pickle reads and the tracker never unpickles (save names as "
                f"np.array(names, dtype=str)); {fix}"
            ) from None
        raise TrackerInputError(f"{path}: not a readable .npz archive ({error}); {fix}") from None
    except (OSError, EOFError, zipfile.BadZipFile) as error:
        raise TrackerInputError(f"{path}: not a readable .npz archive ({error}); {fix}") from None


def _kind(start: bytes) -> str:
    """What a file that begins with ``start`` (and is not a zip archive) is, as an error message says it."""
    if not start:
        return "an empty file"
    if start.startswith(NPY):
        return "a single .npy array"
    return "a file of another kind" if b"\0" in start else "text"
