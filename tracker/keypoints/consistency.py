"""Detections that agree across the views: a landmark seen in several cameras must triangulate.

A detector that follows the wrong person in one view (someone in the background), or confuses a
limb, gives a landmark that no 3-D point explains together with the other views.  Per frame and
landmark, over the cameras that see it confidently: every pair of them is triangulated (linear,
in undistorted normalised coordinates), each camera's reprojection distance to that point is
measured, and the pair whose point most cameras reach within ``gate`` (a share of the image's
short side) wins; the cameras it leaves out keep the landmark at confidence 0.  With one camera
there is nothing to check against, and the landmark is kept.

The same search (:func:`readings`) also takes a left/right pair of landmarks at once and lets each
view read the pair either way round, for a detector that swaps left and right in some views: then a
hypothesis is a pair of views and the order in which the second reads the pair, and every view
takes the order its detections fit best.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Reading:
    """One explanation of a landmark (G = 1) or a left/right pair (G = 2) across V views: world ``points``
    (G, 3) (NaN where fewer than two detections agree), whether each view reads the pair ``swapped`` (V,)
    bool, whether view k's detection of point g ``agree``-s (V, G) bool (its detection of landmark g, or of
    the other one of the pair when it reads it swapped), and the summed pixel ``distance`` of those that
    agree."""

    points: np.ndarray
    swapped: np.ndarray
    agree: np.ndarray
    distance: float


def readings(
    cameras: list[Camera],
    pixels: np.ndarray,
    normalised: np.ndarray,
    limits: np.ndarray,
    *,
    swaps: bool = False,
    among: np.ndarray | None = None,
) -> list[Reading]:
    """Every pair of views' explanation of one landmark or left/right pair, the most agreeing detections first
    (then the smallest summed distance; the first pair of views first among equals).

    ``pixels`` (V, G, 2) are the recorded pixels in the V ``cameras`` (NaN where not usable), ``normalised``
    the same undistorted, ``limits`` (V,) each view's agreement distance in pixels.  A pair of views (of those
    ``among`` (V,) bool, default all) is triangulated (with ``swaps``, also with the second reading the pair
    the other way round); each view reads the pair the way its detections reach the points best (most within
    its limit, then the smallest summed distance).  The points are then triangulated again from all the
    detections that agree, and the order that most agreeing views read is called straight."""
    views, count = pixels.shape[:2]
    orders = [np.arange(count)] + ([np.arange(count)[::-1]] if swaps and count == 2 else [])
    seen = np.isfinite(pixels).all(axis=2)
    found = []
    for a, b in itertools.combinations(np.flatnonzero(np.ones(views, bool) if among is None else among), 2):
        for order in orders:
            points = np.full((count, 3), np.nan)
            for g in range(count):
                if seen[a, g] and seen[b, order[g]]:
                    pair = np.array([normalised[a, g], normalised[b, order[g]]])
                    points[g] = triangulate([cameras[a], cameras[b]], pair)
            if not np.isnan(points).all():
                found.append(_refit(cameras, normalised, *_read(cameras, pixels, points, limits, orders)))
    return sorted(found, key=lambda reading: (-int(reading.agree.sum()), reading.distance))


def _refit(
    cameras: list[Camera], normalised: np.ndarray, swapped: np.ndarray, agree: np.ndarray, distance: float
) -> Reading:
    """The :class:`Reading` whose points are triangulated from every agreeing detection, the order most
    agreeing views read called straight."""
    count = agree.shape[1]
    reading = np.where(swapped[:, None], np.arange(count)[::-1], np.arange(count))
    points = np.full((count, 3), np.nan)
    for g in range(count):
        supporting = np.flatnonzero(agree[:, g])
        if len(supporting) >= 2:
            points[g] = triangulate([cameras[k] for k in supporting], normalised[supporting, reading[supporting, g]])
    agreeing = agree.any(axis=1)
    if swapped[agreeing].sum() > (~swapped[agreeing]).sum():
        return Reading(points[::-1].copy(), ~swapped, agree[:, ::-1].copy(), distance)
    return Reading(points, swapped, agree, distance)


def _read(
    cameras: list[Camera], pixels: np.ndarray, points: np.ndarray, limits: np.ndarray, orders: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray, float]:
    """Each view's reading of ``points`` (G, 3): swapped (V,) bool (it reads them in ``orders[1]``), whether
    its detection of point g agrees (V, G) bool, and the summed distance of the agreeing ones."""
    views, count = pixels.shape[:2]
    swapped, agree, total = np.zeros(views, bool), np.zeros((views, count), bool), 0.0
    known = np.isfinite(points).all(axis=1)
    for k in range(views):
        projected = np.full((count, 2), np.nan)
        projected[known] = cameras[k].project(points[known])
        best = (-1, np.inf)
        for index, order in enumerate(orders):
            distance = np.linalg.norm(projected - pixels[k, order], axis=1)
            within = distance < limits[k]
            key = (int(within.sum()), float(distance[within].sum()))
            if key[0] > best[0] or (key[0] == best[0] and key[1] < best[1]):
                best, swapped[k] = key, index == 1
                agree[k] = within
        total += best[1]
    return swapped, agree, total


def consistent(
    keypoints: Keypoints, cameras: list[Camera], *, min_confidence: float = 0.5, gate: float = GATE
) -> tuple[Keypoints, np.ndarray]:
    """``keypoints`` with the confidence of every detection that disagrees with the other views set to 0,
    and the share (C,) of each camera's confident detections so dropped."""
    confidence = keypoints.confidence.copy()
    usable = (confidence >= min_confidence) & np.isfinite(keypoints.pixels).all(axis=3)
    limits = np.array([gate * min(camera.size) for camera in cameras])
    pixels = np.where(usable[..., None], keypoints.pixels, np.nan)
    normalised = undistorted(pixels, cameras)
    for frame, landmark in zip(*np.nonzero(usable.sum(axis=1) >= 2)):
        found = readings(cameras, pixels[frame, :, landmark, None], normalised[frame, :, landmark, None], limits)
        confidence[frame, usable[frame, :, landmark] & ~found[0].agree[:, 0], landmark] = 0.0
    dropped = ((confidence == 0) & usable).sum(axis=(0, 2)) / np.maximum(usable.sum(axis=(0, 2)), 1)
    return dataclasses.replace(keypoints, confidence=confidence), dropped


def undistorted(pixels: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """Ideal normalised coordinates (F, C, K, 2) of recorded ``pixels`` (F, C, K, 2), NaN where they are NaN."""
    normalised = np.full(pixels.shape, np.nan)
    for k, camera in enumerate(cameras):
        seen = np.isfinite(pixels[:, k]).all(axis=2)
        normalised[:, k][seen] = camera.undistort_pixels(pixels[:, k][seen])
    return normalised
