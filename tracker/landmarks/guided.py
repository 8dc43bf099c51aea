"""Where the other views place the body: which views' detections of one frame agree, and the square in which a
view that disagrees should show the body.

A landmarker in video mode follows whatever it found last.  On a render of a man jumping in a furnished
room, one view's landmarker followed a desk and chair as if they were a person (confidence 1.0) for half the
frames, and another found nobody for as long, so that only one view held the body.  Two views whose landmarks
triangulate agree; a view that agrees with neither of them is read again in the square around the agreeing
views' landmarks projected into it (docs/keypoints.md, "Views read where the others place the body").

Two views agree when most of the landmarks both see confidently (at least :data:`SHARED`) triangulate to a
point in front of both cameras that reprojects within :data:`GATE` of the image's
short side in both: two readings of different things meet that only by chance, on a few landmarks.  The same
gate, and the recorded pixels' ideal normalised coordinates (:func:`undistorted`), serve the check of each
landmark across the views (:mod:`tracker.landmarks.consistency`).
"""

from __future__ import annotations

import itertools

import numpy as np

from tracker.camera import Camera
from tracker.geometry.dlt import triangulate_many
from tracker.landmarks.crop import Region, around

GATE = 0.05
"""Reprojection distance, as a share of the image's short side, within which a view agrees."""

MARGIN = 1.5
"""The side of the square a view is read again in, over the longer side of the body's projected extent: tighter
than a followed crop's (:data:`tracker.landmarks.crop.MARGIN`), so that the landmarker's person detector finds
the body rather than someone beside it."""

REACH = 1.8
"""Metres from their median within which a person's landmarks lie: the face's eleven pull the median up to the
head, and the feet lie about 1.5 m below it."""

SHARED = 6
"""Landmarks two views must both see confidently for their agreement to be judged."""

CONFIDENT = 0.5
"""A landmark's confidence from which it counts as seen."""


def agreeing_views(
    cameras: list[Camera], pixels: np.ndarray, confidence: np.ndarray, *, gate: float = GATE
) -> np.ndarray:
    """(V,) bool: the views whose landmarks ``pixels`` (V, K, 2) (full-image pixels, NaN where none) agree with
    at least one other view's (see the module); ``confidence`` (V, K)."""
    seen = (confidence >= CONFIDENT) & np.isfinite(pixels).all(axis=2)
    projections, normalised = rays(cameras, pixels, seen)
    agree = np.zeros(len(cameras), bool)
    for a, b in itertools.combinations(range(len(cameras)), 2):
        both = seen[a] & seen[b]
        if both.sum() < SHARED:
            continue
        pair = np.zeros((len(both), len(cameras)), bool)
        pair[:, a] = pair[:, b] = both
        points = triangulate_many(projections, normalised, pair)
        reach = np.ones(len(both), bool)
        for k in (a, b):
            reach &= _reaches(cameras[k], points, pixels[k], gate * min(cameras[k].size))
        if 2 * int((reach & both).sum()) > int(both.sum()):
            agree[[a, b]] = True
    return agree


def placed_points(
    cameras: list[Camera], pixels: np.ndarray, confidence: np.ndarray, *, among: np.ndarray, gate: float = GATE
) -> np.ndarray:
    """World points (K, 3) of the landmarks ``pixels`` (V, K, 2) as the views ``among`` (V,) bool triangulate them,
    each from those of them that see it confidently; NaN where fewer than two do, where the point misses one of
    them by more than ``gate`` of its image's short side, or where it lies farther than :data:`REACH` from the
    points' median (two views that agree on most landmarks may read a few differently, and two views close
    together place such a point anywhere along their rays: on the demo, metres behind the body)."""
    seen = (confidence >= CONFIDENT) & np.isfinite(pixels).all(axis=2) & among[:, None]
    projections, normalised = rays(cameras, pixels, seen)
    points = triangulate_many(projections, normalised, seen.T)
    for k in np.flatnonzero(among):
        missed = seen[k] & ~_reaches(cameras[k], points, pixels[k], gate * min(cameras[k].size))
        points[missed] = np.nan
    known = np.isfinite(points).all(axis=1)
    if known.any():
        known[known] = np.linalg.norm(points[known] - np.median(points[known], axis=0), axis=1) <= REACH
        points[~known] = np.nan
    return points


def placed(camera: Camera, points: np.ndarray) -> Region | None:
    """The square of ``camera``'s image around the projections of the world ``points`` (K, 3) (NaN where
    unknown), :data:`MARGIN` times their extent; None when fewer than :data:`SHARED` of them lie in front of the
    camera or the square's centre lies outside its image."""
    ahead = np.isfinite(points).all(axis=1)
    ahead[ahead] = (points[ahead] @ camera.rotation.T + camera.translation)[:, 2] > 0.0
    if ahead.sum() < SHARED:
        return None
    square = around(camera.project(points[ahead]), MARGIN)
    width, height = camera.size
    if square is None or not (0.0 <= square.centre[0] < width and 0.0 <= square.centre[1] < height):
        return None
    return square


def fits(camera: Camera, points: np.ndarray, pixels: np.ndarray, *, confidence: np.ndarray, gate: float = GATE) -> bool:
    """Whether most of one view's confident landmarks ``pixels`` (K, 2) (at least :data:`SHARED`, of those whose
    world ``points`` (K, 3) are known) lie within ``gate`` of the image's short side of the points' projections in
    ``camera``."""
    seen = (confidence >= CONFIDENT) & np.isfinite(pixels).all(axis=1) & np.isfinite(points).all(axis=1)
    if seen.sum() < SHARED:
        return False
    reach = _reaches(camera, points, np.where(seen[:, None], pixels, np.nan), gate * min(camera.size))
    return 2 * int(reach.sum()) > int(seen.sum())


def rays(cameras: list[Camera], pixels: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cameras' [R | t] (V, 3, 4) and the ideal normalised coordinates (K, V, 2) of the landmarks ``pixels``
    (V, K, 2) that are ``seen`` (V, K) bool (NaN elsewhere), as :func:`tracker.geometry.dlt.triangulate_many` takes
    them."""
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    normalised = undistorted(np.where(seen[..., None], pixels, np.nan)[None], cameras)[0].transpose(1, 0, 2)
    return projections, normalised


def _reaches(camera: Camera, points: np.ndarray, pixels: np.ndarray, limit: float) -> np.ndarray:
    """(K,) bool: ``points`` (K, 3) lie in front of ``camera`` and project within ``limit`` pixels of ``pixels``."""
    reach = np.zeros(len(points), bool)
    known = np.isfinite(points).all(axis=1) & np.isfinite(pixels).all(axis=1)
    depth = points[known] @ camera.rotation.T + camera.translation
    ahead = depth[:, 2] > 0.0
    index = np.flatnonzero(known)[ahead]
    reach[index] = np.linalg.norm(camera.project(points[index]) - pixels[index], axis=1) < limit
    return reach


def undistorted(pixels: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """Ideal normalised coordinates (F, C, K, 2) of recorded ``pixels`` (F, C, K, 2), NaN where they are NaN."""
    normalised = np.full(pixels.shape, np.nan)
    for k, camera in enumerate(cameras):
        seen = np.isfinite(pixels[:, k]).all(axis=2)
        normalised[:, k][seen] = camera.undistort_pixels(pixels[:, k][seen])
    return normalised
