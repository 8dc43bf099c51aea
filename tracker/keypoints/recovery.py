"""Never stay lost: a tracked pose that strays from the keypoints is seeded again from them.

After each frame tracked with landmarks (checked across the views,
:mod:`tracker.keypoints.consistency`), the tracked pose's landmark points
(:func:`tracker.keypoint_cue.cue_points`) are projected into every view that has six or more of
them, and the median image distance to their detections is taken as a share of the body's size
there.  When the mean over the views exceeds :data:`STRAYED` (:data:`DOUBTED` when the edges too
found the frame uncertain), or the frame is lost, the tracker
starts again from the model fitted to the landmarks' triangulated points and then to the detections
(:mod:`tracker.keypoints.fit`; with one view, from the tracked pose fitted to its detections),
snapped to the frame's edges as the first pose is (:func:`tracker.keypoints.first_pose.snap_to_edges`):
its status says so (:data:`tracker.status.RESEEDED`).

Image distances, not triangulated ones: two views triangulate a detector's few pixels of noise into
centimetres of depth, while the share of the body's size reads the same in any view; the mean over
the views, because a body shifted along one camera's axis shows in the others.  Measured at the true
poses, the statistic is 2.6 % in a median frame and 8.6 % in the worst on the demo (a faceless
mannequin the detector reads poorly), about 2.5 % and at most 6.5 % on the hard suite's renders
(faces, rooms); a body lost on the real trial gives 66 % and more, and the demo's body moved 42 cm
sideways 11 %.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.keypoint_cue import cue_points
from tracker.keypoints.consistency import triangulate_many
from tracker.keypoints.first_pose import snap_to_edges
from tracker.keypoints.fit import fit_pose, fit_to_views
from tracker.model import Model
from tracker.status import LOST, RESEEDED, UNCERTAIN
from tracker.track import FrameResult, Tracker

STRAYED = 0.10
"""Median image distance between the tracked landmarks and their detections, as a share of the body's size in
the image, beyond which the pose has strayed (module docstring)."""

DOUBTED = 0.05
"""The same share beyond which a frame whose edges are uncertain has strayed: the edges and the landmarks
both say the pose is off."""

MIN_LANDMARKS = 6
"""Landmarks needed to judge a pose, or to fit one."""


def world_points(
    cameras: list[Camera], pixels: np.ndarray, confidence: np.ndarray, min_confidence: float = 0.5
) -> np.ndarray:
    """The landmarks' world points (K, 3), triangulated from the views that see them (``pixels`` (C, K, 2),
    ``confidence`` (C, K)); NaN where fewer than two views do."""
    seen = (confidence >= min_confidence) & np.isfinite(pixels).all(axis=2)  # (C, K)
    normalised = np.full(pixels.shape, np.nan)
    for k, camera in enumerate(cameras):
        normalised[k, seen[k]] = camera.undistort_pixels(pixels[k, seen[k]])
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    return triangulate_many(projections, normalised.transpose(1, 0, 2), seen.T)


def landmark_world(poses: np.ndarray, component: np.ndarray, point: np.ndarray) -> np.ndarray:
    """World points (K, 3) of the landmarks' model points at ``poses``; NaN for landmarks without a component."""
    out = np.full((len(component), 3), np.nan)
    marked = component >= 0
    out[marked] = (
        np.einsum("kij,kj->ki", poses[component[marked], :3, :3], point[marked]) + poses[component[marked], :3, 3]
    )
    return out


@dataclasses.dataclass
class Recovery:
    """Checks each frame tracked with landmarks and seeds the tracker again when it strayed (module docstring);
    ``reseeded`` counts the frames."""

    model: Model
    cameras: list[Camera]
    min_confidence: float = 0.5
    reseeded: int = 0

    def __post_init__(self) -> None:
        self.component, self.point = cue_points(self.model)

    def strayed(self, poses: np.ndarray, pixels: np.ndarray, confidence: np.ndarray, limit: float = STRAYED) -> bool:
        """Whether ``poses`` lie off the landmarks by more than ``limit`` (module docstring); False when no view
        has enough of them."""
        tracked = landmark_world(poses, self.component, self.point)
        shares = []
        for camera, seen_pixels, seen_confidence in zip(self.cameras, pixels, confidence):
            usable = (seen_confidence >= self.min_confidence) & np.isfinite(seen_pixels).all(axis=1)
            usable &= np.isfinite(tracked).all(axis=1)
            if usable.sum() < MIN_LANDMARKS:
                continue
            projected = camera.project(tracked[usable])
            size = max(float(np.linalg.norm(np.ptp(projected, axis=0))), 1.0)
            shares.append(float(np.median(np.linalg.norm(projected - seen_pixels[usable], axis=1))) / size)
        return bool(shares) and float(np.mean(shares)) > limit

    def fitted(self, start: np.ndarray, pixels: np.ndarray, confidence: np.ndarray) -> np.ndarray | None:
        """The model fitted to the landmarks (to their world points, then to the detections), or None when too
        few are seen or they cannot place the body (no hips and shoulders); with one view, ``start`` refined
        against the detections."""
        if len(self.cameras) >= 2:
            points = world_points(self.cameras, pixels, confidence, self.min_confidence)
            if np.isfinite(points).all(axis=1).sum() < MIN_LANDMARKS:
                return None
            try:
                start = fit_pose(self.model, points)
            except TrackerInputError:  # the landmarks cannot place the body: go on as tracked
                return None
        elif ((confidence[0] >= self.min_confidence) & np.isfinite(pixels[0]).all(axis=1)).sum() < MIN_LANDMARKS:
            return None
        return fit_to_views(self.model, start, self.cameras, pixels[None], confidence[None])

    def __call__(
        self, tracker: Tracker, images, keypoints: tuple[np.ndarray, np.ndarray] | None, result: FrameResult
    ) -> FrameResult:
        """``result`` of the frame just tracked in ``images`` (smoothed), or, when the pose strayed from
        ``keypoints`` or was lost, the frame tracked again from the pose fitted to them (status RESEEDED)."""
        if keypoints is None:
            return result
        pixels, confidence = keypoints
        limit = DOUBTED if result.status == UNCERTAIN else STRAYED
        if result.status != LOST and not self.strayed(result.poses, pixels, confidence, limit):
            return result
        seed = self.fitted(result.poses, pixels, confidence)
        if seed is None:
            return result
        snapped = snap_to_edges(
            self.model, self.cameras, seed, images, keypoints=keypoints, settings=tracker.settings, smoothed=True
        )
        tracker.restart(snapped.poses)
        self.reseeded += 1
        return dataclasses.replace(snapped, status=RESEEDED)
