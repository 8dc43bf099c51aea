"""``timestamps.csv``: each camera's capture time of each frame (docs/formats.md, "Recording folder").

Two layouts are read.  The project's own (``tracker live --record``): a header ``frame,<camera>,...`` and one row
per frame, each camera's time in seconds.  caliscope's: a header ``sync_index,cam_id[,frame_index],frame_time`` and one
row per camera and frame set; the sets, in the order of their sync index, are the recording's frames, and a camera
numbered k is the calibration's camera named ``cam{k}``, ``cam_{k}`` or ``port_{k}``, else its k-th camera.  A camera
missing from a set has no time for that frame (NaN).
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError


def camera_times(path: str | os.PathLike, cameras: list[str], *, rig: list[str], frames: int) -> np.ndarray:
    """The capture times (F, C) in seconds of ``frames`` frames of the ``cameras`` (names, in the recording's order)
    from the file at ``path`` (module docstring), NaN where a camera has no time for a frame; ``rig`` names every
    camera of the calibration.  One-line errors name the file: a table that does not parse, a camera the calibration
    does not have, a count of frames other than the videos', or a camera whose time goes backwards."""
    path = Path(path)
    try:
        with open(path, newline="") as file:
            rows = [[cell.strip() for cell in row] for row in csv.reader(file) if row]
    except (OSError, UnicodeDecodeError) as error:
        raise TrackerInputError(f"{path}: cannot read the timestamps ({error}); fix it or remove it") from None
    if not rows:
        raise TrackerInputError(f"{path}: empty; give a header and one row per frame, or remove it")
    header, body = rows[0], rows[1:]
    if header[:2] == ["sync_index", "cam_id"] and header[-1] == "frame_time":
        table = _by_sets(path, body, rig, frames)
    elif header[:1] == ["frame"]:
        table = _by_frames(path, header, body, rig, frames)
    else:
        raise TrackerInputError(
            f"{path}: the header {','.join(header)!r} is neither frame,<camera>,... nor "
            "sync_index,cam_id[,frame_index],frame_time; fix it or remove it"
        )
    times = np.column_stack([table.get(name, np.full(frames, np.nan)) for name in cameras])
    for name, column in zip(cameras, times.T):
        known = np.flatnonzero(np.isfinite(column))
        back = np.flatnonzero(np.diff(column[known]) < 0)
        if len(back):
            frame = int(known[back[0] + 1])
            raise TrackerInputError(
                f"{path}: camera {name}'s time goes backwards at frame {frame} ({column[known[back[0]]]:.6f} then "
                f"{column[frame]:.6f} s); fix it or remove it"
            )
    return times


def _number(path: Path, text: str, where: str) -> float:
    """``text`` as a finite number, else a one-line error naming ``where`` in the file."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise TrackerInputError(f"{path}: {where} is {text!r}, not a finite number; fix it or remove it")
    return value


def _by_frames(path: Path, header: list[str], body: list[list[str]], rig: list[str], frames: int) -> dict:
    """The own layout's columns: camera name -> times (F,)."""
    for name in header[1:]:
        if name not in rig:
            raise TrackerInputError(
                f"{path}: names camera {name!r}, which the calibration does not have ({', '.join(rig)}); "
                "fix the header or remove the file"
            )
    if len(body) != frames:
        raise TrackerInputError(f"{path}: has {len(body)} rows for {frames} frames; give one row per frame")
    table = {}
    for column, name in enumerate(header[1:], start=1):
        table[name] = np.array(
            [
                _number(path, row[column] if column < len(row) else "", f"row {k + 2}'s {name}")
                for k, row in enumerate(body)
            ]
        )
    return table


def _camera_of(path: Path, number: str, rig: list[str]) -> str:
    """The calibration's camera that caliscope numbers ``number``."""
    for name in (f"cam{number}", f"cam_{number}", f"port_{number}"):
        if name in rig:
            return name
    if number.isdigit() and int(number) < len(rig):
        return rig[int(number)]
    raise TrackerInputError(
        f"{path}: names camera {number!r}, which the calibration does not have ({', '.join(rig)}); fix it or remove it"
    )


def _by_sets(path: Path, body: list[list[str]], rig: list[str], frames: int) -> dict:
    """caliscope's rows: camera name -> times (F,), one frame per sync index in order."""
    indices = [int(_number(path, row[0], "a sync_index")) for row in body]
    frame_of = {index: frame for frame, index in enumerate(sorted(set(indices)))}
    if len(frame_of) != frames:
        raise TrackerInputError(f"{path}: has {len(frame_of)} frame sets for {frames} frames; give one set per frame")
    table: dict[str, np.ndarray] = {}
    for index, row in zip(indices, body):
        name = _camera_of(path, row[1], rig)
        table.setdefault(name, np.full(frames, np.nan))[frame_of[index]] = _number(
            path, row[-1], f"{name}'s frame_time"
        )
    return table
