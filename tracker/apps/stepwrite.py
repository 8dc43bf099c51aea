"""Step and write: track one frame and append its row to poses.npz, as every tracking command does."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from tracker.io.poses import PosesWriter
from tracker.model import joint_centres
from tracker.tracking.track import FrameResult, Tracker


def step_and_write(
    tracker: Tracker,
    writer: PosesWriter,
    index: int,
    images,
    *,
    at: float | None = None,
    previous: float | None = None,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    check: Callable[[Tracker, list, tuple[np.ndarray, np.ndarray] | None, FrameResult], FrameResult] | None = None,
) -> tuple[FrameResult, float]:
    """Track frame ``index`` from its smoothed grey images (one per camera, rig order) and append its row
    (poses, joint centres, status, residual, seconds spent, capture time ``at``) to ``writer``.

    ``at`` and ``previous`` are the capture times of this frame and of the one tracked before it, in
    seconds (None for a recording without them); their difference is the step's ``dt``.  ``keypoints``:
    the frame's landmarks, fused with the edges (:meth:`tracker.tracking.track.Tracker.step`).  ``check``, if
    given, sees the result before it is written and may track the frame again (the keypoints' recovery,
    :class:`tracker.keypoints.recovery.Recovery`).  Returns the result and the seconds spent on the frame.
    """
    begun = time.perf_counter()
    dt = None if at is None or previous is None else at - previous
    result = tracker.step(images, smoothed=True, dt=dt, keypoints=keypoints)
    if check is not None:
        result = check(tracker, images, keypoints, result)
    spent = time.perf_counter() - begun
    writer.append(
        index,
        result.poses,
        joint_centres(result.poses),
        status=result.status,
        residual=result.residual,
        elapsed=spent,
        time=at,
    )
    return result, spent
