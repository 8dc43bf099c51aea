"""C3D files (biomechanics' binary motion format), written with ezc3d.

What we write: POINT data only (no analogs), one point per joint centre,
``POINT:LABELS`` = joint names, ``POINT:UNITS`` = "mm", ``POINT:RATE`` = frames
per second, 32-bit floats.  The header's first frame is the recording's frame
index (C3D counts from 1, so readers show the index plus one).  A point's
residual word is -1 where it is a gap (the C3D convention for an invalid
point; ezc3d then reads NaN) and 0 elsewhere (C3D: a valid point computed
rather than measured by cameras).  The coordinates stay in the tracker's world,
right-handed with z up; ``POINT:X_SCREEN`` = "+X" and ``POINT:Y_SCREEN`` = "+Z"
tell viewers such as Mokka that z is up.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from tracker.atomic import atomic_path
from tracker.errors import TrackerInputError
from tracker.io.export.units import MM_PER_M

_C3D_MAX_FRAMES = 65535  # the header's first and last frame are 16-bit


def write_c3d(
    path: str | os.PathLike, names: Sequence[str], *, first_frame: int, rate: float, joints: np.ndarray
) -> None:
    """Write ``joints`` (F, M, 3) metres, NaN for gaps, as the C3D file ``path`` (mm, atomically)."""
    import ezc3d

    count = len(joints)
    if count > _C3D_MAX_FRAMES or not 0 <= first_frame <= _C3D_MAX_FRAMES:
        raise TrackerInputError(
            f"{path}: C3D headers hold frame numbers up to {_C3D_MAX_FRAMES}, these frames run "
            f"{first_frame}..{first_frame + count - 1}; export to TRC or CSV instead"
        )
    gap = ~np.isfinite(joints).all(axis=2)  # (F, M)
    points = np.ones((4, len(names), count))
    points[:3] = np.transpose(joints, (2, 1, 0)) * MM_PER_M
    points[:3, gap.T] = np.nan
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(rate)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = list(names)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d.add_parameter("POINT", "X_SCREEN", ["+X"])
    c3d.add_parameter("POINT", "Y_SCREEN", ["+Z"])
    c3d["header"]["points"]["first_frame"] = int(first_frame)
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"]["residuals"] = np.where(gap.T, -1.0, 0.0)[np.newaxis]

    with atomic_path(path, ".c3d") as temp:  # ezc3d writes only to a file name, and adds .c3d to one without it
        c3d.write(str(temp))
