"""The frame loop that every app runs: each frame tracked, checked, written to poses.npz and handed on
(:func:`track_frames`).

``tracker track`` adds its progress bar, overlay and viewer, ``tracker bench`` its timings, ``tracker live`` its
capture times, camera drops and viewer, each through the loop's arguments.  A test needs a tracker, the frames and an
output path, and may wrap the keypoint source (a plain callable) to perturb the landmarks; as ``tracker track`` runs
a recording with the detector and the recovery::

    tracker = Tracker(model, recording.cameras, first_pose, settings)
    stream = KeypointStream(recording, 0, recording.frame_count, step, cache, reductions(settings, recording.cameras),
                            landmark_model="heavy")
    read = tracked_frames(stream, recording, 0, recording.frame_count, prepare=tracker.smooth)
    track_frames(tracker, read, out / "poses.npz", fps=recording.fps, keypoints=lambda index: moved(stream.get(index)),
                 check=Recovery(model, recording.cameras))
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker import stop_signals
from tracker.io.poses import PosesWriter
from tracker.model import joint_centres
from tracker.tracking.frame_loop import FrameResult, Tracker

Landmarks = tuple[np.ndarray, np.ndarray]
"""A frame's landmarks: pixels (C, 33, 2) and confidence (C, 33), one row per camera of the tracker's rig."""

KeypointSource = Callable[[int], Landmarks | None]
"""The landmarks of frame ``index``, or None when it has none: :meth:`tracker.apps.keypoint_stream.KeypointStream.get`,
or that wrapped (a test may move them by a little noise)."""

Check = Callable[[Tracker, Sequence[np.ndarray], Landmarks | None, FrameResult], FrameResult]
"""Sees a frame's result (the tracker, the frame's smoothed images, its landmarks, the result) before it is written,
and may track the frame again: the keypoints' recovery, :class:`tracker.seeding.recovery.Recovery`."""


@dataclass(frozen=True)
class Tracked:
    """A frame the loop tracked and wrote: its index, the smoothed images it was tracked in, its result, and the
    seconds its step (and check) took."""

    index: int
    images: Sequence[np.ndarray]
    result: FrameResult
    spent: float


@dataclass(frozen=True)
class Loop:
    """What a run of :func:`track_frames` did: the frames tracked and written, the seconds it took (the last write
    included), those of them spent on the rows (joint centres and the writer), and whether a stop signal (Ctrl-C,
    SIGTERM, SIGHUP) stopped it (the frames done are written all the same)."""

    frames: int
    seconds: float
    writing: float
    interrupted: bool


def track_frames(
    tracker: Tracker,
    frames: Iterable[tuple[int, Sequence[np.ndarray]]],
    path: Path,
    *,
    fps: float,
    keypoints: KeypointSource | None = None,
    check: Check | None = None,
    times: Callable[[int], float] | None = None,
    late: Callable[[int], np.ndarray] | None = None,
    retarget: Callable[[Tracker], Tracker] | None = None,
    each: Callable[[Tracked], None] | None = None,
    before: dict[str, np.ndarray] | None = None,
) -> Loop:
    """Track the ``frames`` with ``tracker`` and write each one's row to the poses.npz at ``path`` (frames at ``fps``)
    as it is done: poses, joint centres, status, which parts the images hold, residual, seconds spent and capture
    time.  Ctrl-C, SIGTERM or SIGHUP (:mod:`tracker.stop_signals`) ends the loop with the frames done written
    (:attr:`Loop.interrupted`).

    ``frames`` yields (index, images), one image per camera of the tracker's rig, already :meth:`Tracker.smooth
    <tracker.tracking.frame_loop.Tracker.smooth>`-ed.  ``keypoints(index)``: the frame's landmarks, fused with the
    edges.  ``check``: sees each result before it is written (:data:`Check`).  ``times(index)``: the frame's capture
    time in seconds (live capture), written in its row; the step's ``dt`` is the time since the frame before.
    ``late(index)``: seconds (C,) each camera's image of the frame was captured after the frame's time (cameras not
    frame-locked).
    ``retarget(tracker)``: before each frame, the tracker to track it with (``tracker live`` rebuilds it for the
    cameras still delivering).  ``each``: called with every frame once its row is written.  ``before``: rows of a
    poses.npz (its arrays: frame, poses, joints, status, held, residual, elapsed, time) written first, in their
    order, as the frames tracked back from the first pose of ``frames`` (:func:`tracker.apps.track.track`); not counted
    in the loop.
    """
    done, writing, interrupted, last = 0, 0.0, False, None
    started = time.perf_counter()
    with PosesWriter(path, list(tracker.model.names), list(tracker.model.joint_names), fps) as writer:
        if before is not None:
            for row, frame in enumerate(before["frame"]):
                writer.append(
                    int(frame),
                    before["poses"][row],
                    before["joints"][row],
                    status=int(before["status"][row]),
                    residual=float(before["residual"][row]),
                    elapsed=float(before["elapsed"][row]),
                    time=None if times is None else float(before["time"][row]),
                    held=before["held"][row],
                )
        try:
            for index, images in frames:
                if retarget is not None:
                    tracker = retarget(tracker)
                at = None if times is None else times(index)
                landmarks = None if keypoints is None else keypoints(index)
                begun = time.perf_counter()
                dt = None if at is None or last is None else at - last
                lateness = None if late is None else late(index)
                result = tracker.step(images, smoothed=True, dt=dt, keypoints=landmarks, late=lateness)
                if check is not None:
                    result = check(tracker, images, landmarks, result)
                spent = time.perf_counter() - begun
                writer.append(
                    index,
                    result.poses,
                    joint_centres(result.poses),
                    status=result.status,
                    residual=result.residual,
                    elapsed=spent,
                    time=at,
                    held=result.held,
                )
                writing += time.perf_counter() - begun - spent
                done, last = done + 1, at
                if each is not None:
                    each(Tracked(index, images, result, spent))
        except (KeyboardInterrupt, SystemError) as error:  # SystemError: a stop inside a numba kernel, as it reports it
            if not stop_signals.stopped_within(error):
                raise
            interrupted = True
    return Loop(done, time.perf_counter() - started, writing, interrupted)
