"""The first pose without an init file: the body model fitted to the landmarks of the first frames, snapped to
the edges (docs/keypoints.md, "Automatic first pose").

1. :func:`tracker.landmarks.triangulation.triangulated`: the landmarks' world points over the first few
   frames, left and right told by the body, hips read high behind a table lowered first
   (:func:`tracker.landmarks.hips.with_hips_lowered`).
2. :func:`tracker.seeding.pose_fit.fit_pose`: the model's pose whose landmark points lie nearest those points.
3. :func:`tracker.seeding.pose_fit.fit_to_views`: that pose refined against the detections of the same frames.
4. :func:`snap_to_edges`: the tracker on the first frame's images, without a motion model, the frame's
   landmarks fused with the edges (docs/method-tracking.md, sections 3 and 6).

Poses are world_from_component (N, 4, 4).
"""

from __future__ import annotations

import itertools

import numpy as np

from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.io.recording import Recording
from tracker.io.recording import frames as frames_of
from tracker.landmarks.consistency import consistent
from tracker.landmarks.hips import with_hips_lowered
from tracker.landmarks.store import Keypoints
from tracker.landmarks.triangulation import Triangulated, middle, triangulated
from tracker.model import Model
from tracker.seeding.pose_fit import fit_pose, fit_to_views
from tracker.tracking.frame_loop import FrameResult, Tracker
from tracker.tracking.settings import Settings

FRAMES = 5
"""Frames, from the first, whose landmarks are triangulated: the body moves a few millimetres in them, while
one frame's detection may be swapped or missing."""

APART = 0.5
"""The sine of the angle between two views' lines of sight to the body, at the least, for them to place it in
depth (30 to 150 degrees: its depth then as sure as half its breadth): two views that stand together, or face each
other, leave it free along their common line of sight, where a few pixels of the detector's error become
decimetres (:func:`placed_in_depth`)."""

SNAP = Settings().but(motion=dict(dynamics="none"), solve=dict(iterations=10))
"""The edge snap's tracker settings: no motion model, ten IRLS iterations a round."""

SNAP_ROUNDS = 10
"""Rounds of the edge snap: a round costs a few milliseconds, and a start some ten centimetres off takes several
to settle."""


def snap_to_edges(
    model: Model,
    cameras: list[Camera],
    poses: np.ndarray,
    *,
    images: list[np.ndarray],
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    settings: Settings = SNAP,
    rounds: int = SNAP_ROUNDS,
    smoothed: bool = False,
) -> FrameResult:
    """The tracker's result on one frame, ``images`` (one grey (H, W) uint8 per camera, :meth:`Tracker.smooth`-ed
    when ``smoothed``), from ``poses``: ``rounds`` tracking steps of ``settings.solve.iterations`` IRLS iterations
    on the same frame without a motion model, each round's prior centred where the last ended, the frame's
    ``keypoints`` (pixels (C, 33, 2), confidence (C, 33)) fused with the edges (docs/method-tracking.md,
    section 6)."""
    tracker = Tracker(model, cameras, poses, settings.but(motion=dict(dynamics="none")))
    result = tracker.step(images, smoothed=smoothed, keypoints=keypoints)
    for _ in range(rounds - 1):
        result = tracker.step(images, smoothed=smoothed, keypoints=keypoints)
    return result


def agreeing_views(found: Triangulated) -> np.ndarray:
    """The views (indices) whose detections agree with the person's points in a frame of ``found``."""
    return np.flatnonzero(found.agree.any(axis=(0, 2)))


def placed_in_depth(found: Triangulated, cameras: list[Camera], views: np.ndarray) -> bool:
    """Whether two of ``views`` (those that agree on the person in ``found``, :func:`agreeing_views`) see its trunk
    (the midpoint of its hips' and shoulders' midpoints) along lines of sight at least :data:`APART` apart (the sine
    of their angle); True where the trunk is not known, which the fit reports (:func:`fit_pose`)."""
    centre = (middle(found.points, "hip") + middle(found.points, "shoulder")) / 2
    if not np.isfinite(centre).all():
        return True
    sights = [(cameras[k].center - centre) / np.linalg.norm(cameras[k].center - centre) for k in views]
    return any(np.linalg.norm(np.cross(a, b)) >= APART for a, b in itertools.combinations(sights, 2))


def fitted_to_frames(
    model: Model,
    cameras: list[Camera],
    keypoints: Keypoints,
    *,
    frames: int = FRAMES,
    source: object = "the recording",
    in_depth: bool = False,
) -> np.ndarray:
    """World poses (N, 4, 4) of ``model`` fitted to the landmarks of the first ``frames`` frames of ``keypoints``
    (in ``cameras``): their triangulated points, then their detections (steps 1-3 of the module docstring),
    unsnapped; a one-line error naming the frames of ``source`` when they show nobody or cannot place the body, or
    (``in_depth``) when the two views or more that agree on it do not place it in depth (:func:`placed_in_depth`)."""
    keypoints = with_hips_lowered(keypoints, cameras, model)
    found = triangulated(keypoints, cameras, model, frames=frames)
    first, last = int(keypoints.frame[0]), int(keypoints.frame[:frames][-1])
    if len(found.frames) == 0:
        raise TrackerInputError(
            f"no person found by the keypoint detector in two views in frames {first}..{last} of {source}; "
            "pass --init or start later with --start"
        )
    views = agreeing_views(found)
    if in_depth and len(views) >= 2 and not placed_in_depth(found, cameras, views):
        raise TrackerInputError(
            f"frames {first}..{last} of {source}: the views that agree on the person "
            f"({', '.join(cameras[k].name for k in views)}) face each other or stand together, and do not place it "
            "in depth; pass --init or start later with --start"
        )
    try:
        fitted = fit_pose(model, found.points)
    except TrackerInputError as error:
        raise TrackerInputError(f"frames {first}..{last} of {source}: {error}") from None
    row_of = {int(frame): row for row, frame in enumerate(keypoints.frame)}
    rows = np.array([row_of[int(frame)] for frame in found.frames], np.int64)
    agreeing = np.where(found.agree, keypoints.confidence[rows], 0.0)
    return fit_to_views(model, fitted, cameras, pixels=keypoints.pixels[rows], confidence=agreeing)


def first_pose(
    recording: Recording,
    model: Model,
    keypoints: Keypoints,
    *,
    settings: Settings = Settings(),
    frames: int = FRAMES,
    images: list[np.ndarray] | None = None,
) -> np.ndarray:
    """World poses (N, 4, 4) of ``model`` at the first frame of ``keypoints`` (the detector's landmarks in every
    camera of ``recording``, from that frame on; module docstring): the landmarks' points over its first
    ``frames`` frames, the model fitted to them and then to their detections, snapped to that frame's edges
    with its landmarks checked across the views (:func:`tracker.landmarks.consistency.consistent`).
    ``settings`` tune the snap (its motion model and iterations are :data:`SNAP`'s); ``images`` are that
    frame's images as the tracker reads them (one (H, W) uint8 per camera, e.g. differences from the empty
    scene), by default its grey frames."""
    names = tuple(camera.name for camera in recording.cameras)
    if keypoints.camera_names != names:
        raise TrackerInputError(
            f"{recording.path}: the keypoints are of cameras {', '.join(keypoints.camera_names)}, the recording's "
            f"are {', '.join(names)}; detect them again with tracker keypoints"
        )
    if len(names) < 2:
        raise TrackerInputError(
            f"{recording.path}: the keypoints place the first pose from two cameras or more, it has one; pass --init"
        )
    poses = fitted_to_frames(model, recording.cameras, keypoints, frames=frames, source=recording.path, in_depth=True)
    if images is None:
        first = int(keypoints.frame[0])
        [images] = [grey for _, grey in frames_of(recording, first, first + 1)]
    checked = with_hips_lowered(consistent(keypoints.rows(slice(0, 1)), recording.cameras)[0], recording.cameras, model)
    snap = settings.but(solve=dict(iterations=SNAP.solve.iterations))
    landmarks = (checked.pixels[0], checked.confidence[0])
    return snap_to_edges(model, recording.cameras, poses, images=images, keypoints=landmarks, settings=snap).poses
