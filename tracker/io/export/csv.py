"""CSV of joint centres for spreadsheets: one row per frame.

Comma-separated, a header line then one line per frame::

    frame,time,status,residual,pelvis_x,pelvis_y,pelvis_z,torso_x,...
    0,0.000000000,0,0.812,0.012345678,-0.100000000,0.950000000,...

``frame`` is the recording's frame index, ``time`` seconds from the first row,
``status`` 0 tracked / 1 uncertain / 2 lost, ``residual`` the tracker's robust
mean edge distance in pixels, then x, y, z of each joint centre in metres in
the tracker's world (right-handed, z up).  Gaps (lost frames, unknown values)
are written ``NaN``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from tracker.atomic import atomic_write


def csv_lines(
    names: Sequence[str],
    *,
    frame: np.ndarray,
    time: np.ndarray,
    status: np.ndarray,
    residual: np.ndarray,
    joints: np.ndarray,
) -> list[str]:
    """The lines (without newlines) of the CSV of ``joints`` (F, J, 3) metres."""
    header = ["frame", "time", "status", "residual"] + [f"{name}_{axis}" for name in names for axis in "xyz"]
    row_format = "%d,%.9f,%d,%.6g" + ",%.9f" * (3 * len(names))
    lines = [",".join(header)]
    for index, seconds, state, error, coordinates in zip(frame, time, status, residual, joints):
        lines.append((row_format % (index, seconds, state, error, *coordinates.ravel())).replace("nan", "NaN"))
    return lines


def write_csv(
    path: str | os.PathLike,
    names: Sequence[str],
    *,
    frame: np.ndarray,
    time: np.ndarray,
    status: np.ndarray,
    residual: np.ndarray,
    joints: np.ndarray,
) -> None:
    """Write the CSV file ``path`` (atomically): one row per frame, joints (F, J, 3) in metres."""
    text = "\n".join(csv_lines(names, frame=frame, time=time, status=status, residual=residual, joints=joints)) + "\n"

    atomic_write(path, lambda file: file.write(text.encode()))
