"""Reading the project's text and TOML files with one-line errors that name the file and the fix."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from tracker.errors import TrackerInputError


def read_toml(path: str | os.PathLike, what: str, when_missing: str) -> dict:
    """The parsed document at ``path``; ``what`` names the file's role ("calibration", "model", ...)
    and ``when_missing`` says how to fix a missing file."""
    path = Path(path)
    try:
        with open(path, "rb") as file:
            return tomllib.load(file)
    except FileNotFoundError:
        raise TrackerInputError(f"{path}: {what} file not found; {when_missing}") from None
    except OSError as error:
        raise TrackerInputError(f"{path}: cannot read the {what} file ({error.strerror or error})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise TrackerInputError(f"{path}: the {what} file is not valid TOML ({error}); fix its syntax") from None


def read_text(path: str | os.PathLike, what: str, when_missing: str) -> str:
    """The text of the file at ``path``, with the same errors as :func:`read_toml` for missing or unreadable files."""
    path = Path(path)
    try:
        return path.read_text(errors="strict")
    except FileNotFoundError:
        raise TrackerInputError(f"{path}: {what} file not found; {when_missing}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise TrackerInputError(f"{path}: cannot read the {what} file ({error}); give a readable text file") from None
