"""Detections that agree across the views: a landmark seen in several cameras must triangulate.

A detector that follows the wrong person in one view (someone in the background), or confuses a
limb, gives a landmark that no 3-D point explains together with the other views.  Per frame and
landmark, over the cameras that see it confidently: every pair of them is triangulated (linear,
in undistorted normalised coordinates), each camera's reprojection distance to that point is
measured, and the pair whose point most cameras reach within ``gate`` (a share of the image's
short side) wins; the cameras it leaves out keep the landmark at confidence 0.  With one camera
there is nothing to check against, and the landmark is kept.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from tracker.camera import Camera
from tracker.keypoints.store import Keypoints

GATE = 0.05
"""Reprojection distance, as a share of the image's short side, within which a view agrees."""


def triangulate(cameras: list[Camera], normalised: np.ndarray) -> np.ndarray:
    """The world point (3,) nearest in the linear (DLT) sense to the rays of ``normalised`` (len(cameras), 2),
    ideal normalised image coordinates."""
    rows = []
    for camera, (x, y) in zip(cameras, normalised):
        projection = camera.camera_from_world[:3]
        rows += [x * projection[2] - projection[0], y * projection[2] - projection[1]]
    point = np.linalg.svd(np.array(rows))[2][-1]
    return point[:3] / point[3]


def consistent(
    keypoints: Keypoints, cameras: list[Camera], *, min_confidence: float = 0.5, gate: float = GATE
) -> tuple[Keypoints, np.ndarray]:
    """``keypoints`` with the confidence of every detection that disagrees with the other views set to 0,
    and the share (C,) of each camera's confident detections so dropped."""
    confidence = keypoints.confidence.copy()
    usable = (confidence >= min_confidence) & np.isfinite(keypoints.pixels).all(axis=3)
    limits = np.array([gate * min(camera.size) for camera in cameras])
    normalised = np.full(keypoints.pixels.shape, np.nan)
    for k, camera in enumerate(cameras):
        seen = usable[:, k]
        normalised[:, k][seen] = camera.undistort_pixels(keypoints.pixels[:, k][seen])
    for frame, landmark in zip(*np.nonzero(usable.sum(axis=1) >= 2)):
        views = np.flatnonzero(usable[frame, :, landmark])
        best, best_key = views, (-1, np.inf)
        for a, b in itertools.combinations(views, 2):
            point = triangulate([cameras[a], cameras[b]], normalised[frame, [a, b], landmark])
            distance = np.array(
                [np.linalg.norm(cameras[k].project(point)[0] - keypoints.pixels[frame, k, landmark]) for k in views]
            )
            agree = distance < limits[views]
            key = (int(agree.sum()), float(distance[agree].sum()))
            if key[0] > best_key[0] or (key[0] == best_key[0] and key[1] < best_key[1]):
                best, best_key = views[agree], key
        confidence[frame, np.setdiff1d(views, best), landmark] = 0.0
    dropped = ((confidence == 0) & usable).sum(axis=(0, 2)) / np.maximum(usable.sum(axis=(0, 2)), 1)
    return dataclasses.replace(keypoints, confidence=confidence), dropped
