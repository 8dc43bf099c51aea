"""Reading the project's TOML files with one-line errors that name the file and the fix."""

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
