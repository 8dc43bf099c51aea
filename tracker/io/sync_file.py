"""``sync.toml``: each camera's capture-time offset, in seconds (docs/formats.md, "Camera time offsets").

Camera k's frame n was captured at ``n / fps + offset_k``; the first camera's offset is 0 when ``tracker sync`` writes
the file, and a camera the file does not name has offset 0.  The ``[uncertainty]`` table (standard deviations, seconds)
is written beside it and not needed to read it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import tomli_w

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError
from tracker.tomlfile import read_toml

FILE = "sync.toml"
"""The offsets' file name in a recording folder."""

_HEADER = (
    "# Capture-time offsets of the cameras, seconds (tracker sync): camera k's frame n was captured at\n"
    "# n / fps + offset_k. The uncertainties are standard deviations.\n"
)


def load_offsets(path: str | os.PathLike, cameras: list[str], duration: float) -> dict[str, float]:
    """The offsets (seconds) per camera name in ``cameras`` from the file at ``path`` (0 for a camera it does not
    name); a one-line error naming the file and the fix for a file without an ``[offsets]`` table, a camera the
    recording does not have, an offset that is not a number, or one as long as the recording (``duration``, s)."""
    document = read_toml(path, "sync", "run tracker sync on the recording")
    table = document.get("offsets")
    if not isinstance(table, dict):
        raise TrackerInputError(f"{path}: needs an [offsets] table of seconds per camera name; fix it or remove it")
    offsets = dict.fromkeys(cameras, 0.0)
    for name, value in table.items():
        if name not in offsets:
            raise TrackerInputError(
                f"{path}: names camera {name!r}, which the recording does not have ({', '.join(cameras)}); "
                "fix or remove that line"
            )
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise TrackerInputError(f"{path}: the offset of {name} is not a number of seconds ({value!r}); fix it")
        if abs(value) >= duration:
            raise TrackerInputError(
                f"{path}: the offset of {name} ({value:g} s) is as long as the recording ({duration:g} s) or longer; "
                "fix it (seconds, not frames)"
            )
        offsets[name] = float(value)
    return offsets


def save_offsets(path: str | os.PathLike, offsets: dict[str, float], uncertainty: dict[str, float]) -> Path:
    """Write the offsets and their standard deviations (seconds per camera name) to ``path`` atomically."""
    document = {
        "offsets": {name: round(float(value), 6) for name, value in offsets.items()},
        "uncertainty": {name: round(float(value), 6) for name, value in uncertainty.items()},
    }
    text = (_HEADER + tomli_w.dumps(document)).encode()
    atomic_write(path, lambda file: file.write(text))
    return Path(path)
