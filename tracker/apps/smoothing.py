"""A recorded folder's track judged with the frames after each one (``tracker track --smooth``, docs/motion-models.md,
"Smoothing over the whole recording").

The forward track (:func:`tracker.apps.track.track`) solves each frame from the frames before it alone, as live
capture must.  A recording also holds the frames after it:

* ``rts``: the forward track smoothed over the whole recording on the motion model
  (:func:`tracker.tracking.smoother.smoothed_track`), each frame weighed by what its cues said of each part's pose
  (:meth:`tracker.tracking.frame_loop.Tracker.measured`), its chains restarting at each re-seed (:func:`restarts`).
* ``both-ways``: the recording is also tracked from its last frame back to its first (:func:`track_backwards`), from
  the forward track's last pose, with its own recovery.  In each frame where the two tracks disagree
  (:data:`AGREE`), both poses are judged in that frame's images alike (:func:`backing`): the share of their outline
  samples that found an edge, plus the share of their body on the person's masks, less ``misfit_weight`` times
  their landmarks' misfit (the mean over the views of the median landmark's image distance, a share of the body's
  size).  The frame keeps the pose that scores higher over the frames about it (:func:`taken`), and the track so
  fused is smoothed as with ``rts``.  Where the
  forward track strayed (a limb lost on clutter, a trunk tipped, then re-seeded) the backward one, come from later
  frames, has often not, and the other way round.

``tracker live`` has no frames after the one it tracks and keeps the forward track.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable, Sequence

import numpy as np

from tracker import stop_signals
from tracker.seeding.recovery import Recovery
from tracker.status import LOST, RESEEDED
from tracker.tracking.frame_loop import FrameResult, Tracker

Landmarks = tuple[np.ndarray, np.ndarray]
"""A frame's landmarks: pixels (C, 33, 2) and confidence (C, 33)."""


@dataclasses.dataclass(frozen=True)
class Track:
    """A track's rows in frame order (F rows, N components): ``frame`` (F,), ``poses`` (F, N, 4, 4), ``status``
    (F,), ``residual`` (F,) pixels, ``elapsed`` (F,) seconds spent on each, and ``information`` (F, N, 2, 3, 3),
    what each frame's cues said of its poses (:meth:`tracker.tracking.frame_loop.Tracker.measured`; zero where
    nothing was measured); ``held`` (F, N) int8, which parts the images held in each (:mod:`tracker.tracking.held`),
    None for a file that does not say."""

    frame: np.ndarray
    poses: np.ndarray
    status: np.ndarray
    residual: np.ndarray
    elapsed: np.ndarray
    information: np.ndarray
    held: np.ndarray | None = None

    def restarts(self) -> np.ndarray:
        """:func:`restarts` of this track."""
        return restarts(self.frame, self.status)


def restarts(frame: np.ndarray, status: np.ndarray) -> np.ndarray:
    """The rows (F,) bool where a track's motion starts afresh: a re-seeded frame, a frame after a missing one."""
    out = status == RESEEDED
    out[1:] |= np.diff(frame) != 1
    return out


AGREE = 0.01
"""Metres: two tracks whose joint centres all lie this near each other agree, and the frame keeps the forward pose
unjudged."""


def _apart(one: np.ndarray, other: np.ndarray) -> float:
    """How far apart two poses (N, 4, 4) put the body: the largest distance between their joint centres, metres."""
    return float(np.linalg.norm(one[:, :3, 3] - other[:, :3, 3], axis=1).max())


@dataclasses.dataclass(frozen=True)
class Backward:
    """What :func:`track_backwards` made of the frames it tracked back, in frame order: the fused ``track``, which of
    its frames took the backward track's pose (``taken``, (F,) bool), where its motion starts afresh (``starts``,
    (F,) bool: a re-seed of the track taken on both sides), whether a stop signal ended it early
    (``interrupted``: the rows are then those done) and the seconds it took."""

    track: Track
    taken: np.ndarray
    starts: np.ndarray
    interrupted: bool
    seconds: float


def backing(tracker: Tracker, result: FrameResult, *, recovery: Recovery | None, landmarks: Landmarks | None) -> float:
    """How well the frame ``tracker`` holds backs the poses of ``result`` (:meth:`Tracker.judged
    <tracker.tracking.frame_loop.Tracker.judged>` in its images): the share of their outline samples that found an
    edge, plus the share of their body on the person's masks (:meth:`tracker.tracking.person.PersonMasks.on_person`),
    less ``Settings.smoothing.misfit_weight`` times how far the frame's ``landmarks`` lie off them
    (:meth:`tracker.seeding.recovery.Recovery.misfit`, a share of the body's size; nothing without landmarks)."""
    score = result.share + tracker.person.on_person(result.poses)
    if landmarks is not None and recovery is not None:
        misfit, _ = recovery.misfit(result.poses, *landmarks)
        if np.isfinite(misfit):
            score -= tracker.settings.smoothing.misfit_weight * misfit
    return score


JUDGED_OVER = 5
"""Frames over which the two tracks' backing is compared: the detector's masks, whose share tells most, come with every
few frames only (every 2nd at 30 fps, every 4th at 60), and a track that strayed stays off for a stretch."""


def taken(difference: np.ndarray) -> np.ndarray:
    """Which frames (F,) bool, in frame order, take the backward track's pose: those where the tracks disagree (a
    finite ``difference``, the backward pose's :func:`backing` less the forward one's) and the mean of the difference
    over the :data:`JUDGED_OVER` frames about the frame (0 where they agree, the first and last frames repeated) is
    positive."""
    counted = np.nan_to_num(difference, nan=0.0)
    half = JUDGED_OVER // 2
    mean = np.convolve(np.pad(counted, half, mode="edge"), np.full(JUDGED_OVER, 1.0 / JUDGED_OVER), mode="valid")
    return np.isfinite(difference) & (mean > 0.0)


def track_backwards(
    tracker: Tracker,
    frames: Iterable[tuple[int, Sequence[np.ndarray]]],
    *,
    forward: Track,
    keypoints: Callable[[int], Landmarks | None] | None = None,
    check: Recovery | None = None,
    times: Callable[[int], float] | None = None,
    late: Callable[[int], np.ndarray] | None = None,
) -> Backward:
    """Track ``frames`` (index, smoothed images, the last frame first) with ``tracker`` (started at the ``forward``
    track's pose of the first of them), each frame's landmarks ``keypoints(index)`` fused and ``check`` (the
    recovery) after it as in the forward run, and keep in each frame the pose of the track, forward or backward,
    that the frames about it back better (:func:`backing`, :func:`taken`; the forward one where they agree,
    :data:`AGREE`).  Time runs
    backwards here: the capture times ``times(index)`` (a live recording's) are negated, so that the steps go
    forward in that time, and so is each view's lateness ``late(index)`` (a camera late is early in that time).
    Ctrl-C, SIGTERM or SIGHUP (:mod:`tracker.stop_signals`) end it with the frames done (:attr:`Backward.
    interrupted`)."""
    row_of = {int(frame): row for row, frame in enumerate(forward.frame)}
    rows: list[int] = []
    differences: list[float] = []  # backing(backward) - backing(forward), NaN where the tracks agree
    chosen: list[FrameResult] = []
    reseeded: list[bool] = []  # the backward track re-seeded in the frame
    spent: list[float] = []
    interrupted, last = False, None
    started = time.perf_counter()
    try:
        for index, images in frames:
            begun = time.perf_counter()
            at = None if times is None else -times(index)
            landmarks = None if keypoints is None else keypoints(index)
            dt = None if at is None or last is None else at - last
            lateness = None if late is None else -np.asarray(late(index))
            result = tracker.step(images, smoothed=True, dt=dt, keypoints=landmarks, late=lateness)
            if check is not None:
                result = check(tracker, images, landmarks, result)
            row = row_of[int(index)]
            difference = np.nan  # where the tracks agree
            if _apart(forward.poses[row], result.poses) > AGREE:
                back, ahead = (tracker.judged(poses=poses) for poses in (result.poses, forward.poses[row]))
                difference = backing(tracker, back, recovery=check, landmarks=landmarks) - backing(
                    tracker, ahead, recovery=check, landmarks=landmarks
                )
            rows.append(row)
            differences.append(difference)
            chosen.append(result)
            reseeded.append(result.status == RESEEDED)
            spent.append(time.perf_counter() - begun)
            last = at
    except (KeyboardInterrupt, SystemError) as error:  # SystemError: a stop inside a numba kernel, as it reports it
        if not stop_signals.stopped_within(error):
            raise
        interrupted = True
    order = np.argsort(rows)
    return _fused(
        forward,
        np.asarray(rows, np.int64)[order],
        [chosen[k] for k in order],
        taken(np.asarray(differences)[order]),
        np.asarray(reseeded, bool)[order],
        np.asarray(spent)[order],
        interrupted,
        time.perf_counter() - started,
    )


def _fused(
    forward: Track,
    rows: np.ndarray,
    backward: list[FrameResult],
    taken: np.ndarray,
    reseeded: np.ndarray,
    spent: np.ndarray,
    interrupted: bool,
    seconds: float,
) -> Backward:
    """The :class:`Backward` of the forward track's ``rows`` (in frame order) tracked back to ``backward``, the
    backward pose ``taken`` where it is, the backward track ``reseeded`` in a frame and the seconds ``spent`` on
    each.  The fused track's motion starts afresh at a frame the forward track was re-seeded in, when the frame
    before it is also the forward track's, and after one the backward track was re-seeded in (its frames before it in
    time were tracked from the re-seed, the one after from before it), when both are the backward track's."""
    n = forward.poses.shape[1]
    poses = forward.poses[rows].copy()
    status = forward.status[rows].copy()
    residual = forward.residual[rows].copy()
    information = forward.information[rows].copy()
    held = None if forward.held is None else forward.held[rows].copy()
    for k in np.flatnonzero(taken):
        result = backward[k]
        poses[k], status[k], residual[k] = result.poses, result.status, result.residual
        if held is not None:
            held[k] = result.held
        information[k] = np.zeros((n, 2, 3, 3)) if result.information is None else result.information
    frame = forward.frame[rows]
    starts = np.zeros(len(rows), bool)
    starts[1:] = np.diff(frame) != 1
    starts |= ~taken & (forward.status[rows] == RESEEDED) & np.r_[True, ~taken[:-1]]
    starts[1:] |= taken[1:] & taken[:-1] & reseeded[:-1]
    track = Track(frame, poses, status, residual, forward.elapsed[rows] + spent, information, held)
    return Backward(track, taken, starts, interrupted, seconds)


def smoothing_input(track: Track) -> np.ndarray:
    """The information (F, N, 2, 3, 3) the smoother weighs ``track``'s frames by: a lost frame's counts for nothing,
    and a frame that was not measured (a re-seed, snapped to its edges outside the tracker's solve) counts as much as
    the nearest frame that was."""
    information = np.asarray(track.information, np.float64)
    lost = track.status == LOST
    measured = np.flatnonzero(information.any(axis=(1, 2, 3, 4)) & ~lost)
    if len(measured) == 0:
        return np.zeros_like(information)
    rows = np.arange(len(information))
    after = measured[np.minimum(np.searchsorted(measured, rows), len(measured) - 1)]
    before = measured[np.maximum(np.searchsorted(measured, rows, side="right") - 1, 0)]
    nearest = np.where(np.abs(after - rows) < np.abs(rows - before), after, before)
    return np.where(lost[:, None, None, None, None], 0.0, information[nearest])


@dataclasses.dataclass(frozen=True)
class Smoothed:
    """What smoothing a recording's track did (``method``): the seconds it took, the frames it smoothed (with
    ``both-ways``: those it tracked back), how many of them took the backward track's pose, and whether a stop
    (Ctrl-C, SIGTERM, SIGHUP) ended it, the forward track then kept."""

    method: str
    seconds: float
    frames: int
    taken: int
    interrupted: bool
