"""Detections that agree across the views: a landmark seen in several cameras must triangulate.

A detector that follows the wrong person in one view (someone in the background), or confuses a
limb, gives a landmark that no 3-D point explains together with the other views.  Per frame and
landmark, over the cameras that see it confidently: every pair of them is triangulated (linear,
in undistorted normalised coordinates), each camera's reprojection distance to that point is
measured, and the pair whose point most cameras reach within ``gate`` (a share of the image's
short side) wins; the cameras it leaves out keep the landmark at confidence 0.  With one camera
there is nothing to check against, and the landmark is kept.

Two checks come first.  A view that disagrees on most of the landmarks that could be checked in it
(seen by two other views) shows someone else, and all its landmarks of that frame are dropped, the
unchecked ones too.  Then a view whose left and right are swapped (the detector mistook the
person's back for their front) is put right when the other views, triangulated, place both
landmarks of a left/right pair the other way round (three views or more).

Two views that disagree, with no third to settle it, leave the landmark in neither.  Each view's own last frame
can settle it: a detector that jumped to someone else jumped, while the body moved on a little (:func:`sided_with`).
The tracked body does not: where it is wrong (an arm along a frontal view's ray), the view that agrees with it is the
wrong one, and siding with it would hold the body where it is (docs/keypoints.md, "Two views that disagree").

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
from tracker.geometry.dlt import triangulate_many
from tracker.landmarks.body_landmarks import LANDMARKS, left_right_pairs
from tracker.landmarks.guided import GATE, undistorted
from tracker.landmarks.silhouette import on_person
from tracker.landmarks.store import Keypoints

STEADY = 0.1
"""The share of a view's landmarks' extent within which, in the median, its confident detections must lie from its
own last ones for the view to have moved on steadily (:func:`sided_with`): the recovery's
:data:`tracker.seeding.recovery.STRAYED`."""

CONFIDENT = 0.5
"""A detection's confidence from which :func:`sided_with` counts it as seen."""

STEADY_COUNT = 4
"""Landmarks a view must show in both frames for its own last frame to say whether it moved on steadily
(:func:`sided_with`)."""


def triangulate(cameras: list[Camera], normalised: np.ndarray) -> np.ndarray:
    """The world point (3,) nearest in the linear (DLT) sense to the rays of ``normalised`` (len(cameras), 2),
    ideal normalised image coordinates."""
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    return triangulate_many(projections, normalised[None], np.ones((1, len(cameras)), bool))[0]


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
    *,
    limits: np.ndarray,
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
    """``keypoints`` checked across the views, and the share (C,) of each camera's confident detections
    dropped.  First the landmarks off their own detection's mask of the person are dropped (confidence 0,
    :func:`tracker.landmarks.silhouette.on_person`: guessed where a table hides the body; not counted in the
    share), then the views that show someone else are dropped whole, then swapped views are put right
    (:func:`unswapped`: pixels, confidence and world of each swapped pair exchanged), then every detection
    that disagrees with the other views is dropped (confidence 0)."""
    keypoints = on_person(keypoints)
    usable = _usable(keypoints, min_confidence)
    confidence = keypoints.confidence.copy()
    disagree, checked = _disagreements(keypoints, cameras, usable, gate)
    confidence[2 * (checked & disagree).sum(axis=2) > checked.sum(axis=2)] = 0.0  # (F, C): someone else
    keypoints = unswapped(dataclasses.replace(keypoints, confidence=confidence), cameras, min_confidence=min_confidence)
    disagree, _ = _disagreements(keypoints, cameras, _usable(keypoints, min_confidence), gate)
    confidence = np.where(disagree, 0.0, keypoints.confidence)
    dropped = ((confidence < min_confidence) & usable).sum(axis=(0, 2)) / np.maximum(usable.sum(axis=(0, 2)), 1)
    return dataclasses.replace(keypoints, confidence=confidence), dropped


def _usable(keypoints: Keypoints, min_confidence: float) -> np.ndarray:
    """(F, C, K): confident detections with finite pixels."""
    return (keypoints.confidence >= min_confidence) & np.isfinite(keypoints.pixels).all(axis=3)


def _disagreements(
    keypoints: Keypoints, cameras: list[Camera], usable: np.ndarray, gate: float
) -> tuple[np.ndarray, np.ndarray]:
    """(F, C, K) each: the ``usable`` detections that the best pair of views' triangulation does not reach
    within ``gate`` of the image's short side, and those seen with two other views to check against.  The
    best pair is the one most views agree with, then the one they agree with most closely."""
    frames, count, landmarks = usable.shape
    seen = usable.transpose(0, 2, 1).reshape(-1, count)  # (M, C), M = F K
    normalised = _normalised(keypoints, cameras, usable).transpose(0, 2, 1, 3).reshape(-1, count, 2)
    pixels = keypoints.pixels.transpose(0, 2, 1, 3).reshape(-1, count, 2)
    limits = np.array([gate * min(camera.size) for camera in cameras])
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    best = np.zeros(seen.shape, bool)
    best_count = np.full(len(seen), -1)
    best_sum = np.full(len(seen), np.inf)
    for a, b in itertools.combinations(range(count), 2):
        pair = np.zeros(count, bool)
        pair[[a, b]] = True
        both = seen[:, a] & seen[:, b]
        point = triangulate_many(projections, normalised, seen & pair)
        distance = np.linalg.norm(_project(cameras, point) - pixels, axis=2)  # (M, C)
        agree = seen & (np.nan_to_num(distance, nan=np.inf) < limits)
        agreeing = agree.sum(axis=1)
        total = np.where(agree, distance, 0.0).sum(axis=1)
        better = both & ((agreeing > best_count) | ((agreeing == best_count) & (total < best_sum)))
        best[better], best_count[better], best_sum[better] = agree[better], agreeing[better], total[better]
    views = seen.sum(axis=1)
    disagree = seen & ~best & (views >= 2)[:, None]
    checked = seen & (views >= 3)[:, None]
    shape = (frames, landmarks, count)
    return disagree.reshape(shape).transpose(0, 2, 1), checked.reshape(shape).transpose(0, 2, 1)


def unswapped(keypoints: Keypoints, cameras: list[Camera], *, min_confidence: float = 0.5) -> Keypoints:
    """``keypoints`` with every view's left/right pair exchanged where the other views disagree with it:
    both landmarks triangulated (linear, every other view that sees both) reproject nearer to this view's
    detections swapped than as labelled (summed distance).  Needs two other views; views and frames
    without them are left as they are."""
    pixels, confidence, world = keypoints.pixels.copy(), keypoints.confidence.copy(), keypoints.world.copy()
    usable = _usable(keypoints, min_confidence)
    normalised = _normalised(keypoints, cameras, usable)
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    count = len(cameras)
    for a, b in left_right_pairs(LANDMARKS):
        both = usable[:, :, a] & usable[:, :, b]  # (F, C)
        for k in range(count):
            others = both.copy()
            others[:, k] = False
            frames = np.flatnonzero(both[:, k] & (others.sum(axis=1) >= 2))
            if not len(frames):
                continue
            place = [
                cameras[k].project(triangulate_many(projections, normalised[frames, :, j], others[frames]))
                for j in (a, b)
            ]
            left, right = pixels[frames, k, a], pixels[frames, k, b]
            straight = np.linalg.norm(place[0] - left, axis=1) + np.linalg.norm(place[1] - right, axis=1)
            crossed = np.linalg.norm(place[0] - right, axis=1) + np.linalg.norm(place[1] - left, axis=1)
            swap = frames[crossed < straight]
            for array in (pixels, confidence, world):
                array[swap, k, a], array[swap, k, b] = array[swap, k, b].copy(), array[swap, k, a].copy()
    return dataclasses.replace(keypoints, pixels=pixels, confidence=confidence, world=world)


def _project(cameras: list[Camera], points: np.ndarray) -> np.ndarray:
    """Pixels (M, C, 2) of world points (M, 3) in every camera; NaN for NaN points."""
    return np.stack([camera.project(points) for camera in cameras], axis=1)


def _normalised(keypoints: Keypoints, cameras: list[Camera], usable: np.ndarray) -> np.ndarray:
    """Ideal normalised image coordinates (F, C, K, 2) of the ``usable`` detections, NaN elsewhere."""
    return undistorted(np.where(usable[..., None], keypoints.pixels, np.nan), cameras)


def sided_with(
    detected: tuple[np.ndarray, np.ndarray],
    checked: tuple[np.ndarray, np.ndarray],
    *,
    previous: np.ndarray | None,
    min_confidence: float = CONFIDENT,
    steady: float = STEADY,
) -> tuple[np.ndarray, np.ndarray]:
    """A frame's ``checked`` landmarks (pixels (C, K, 2), confidence (C, K); :func:`consistent` of ``detected``) with
    the disputes the views could not settle given to the view that moved on steadily.

    Two views that disagree on a landmark, and no third, leave it in neither (:func:`consistent`): one of them may
    show someone else (a bystander, a photograph) where the other lost the body, and the views alone cannot tell
    which.  ``previous`` (C, K, 2), the landmarks the tracker was given at the last detected frame (NaN where none),
    can: where one of the two views' confident detections lie within ``steady`` of that view's own previous landmarks
    in the median (its size taken from their extent) and the other's do not, the steady view gets its disputed
    landmarks back (where three or more saw a landmark, the check had a majority to go by).  A detector that jumps to a
    bystander or a photograph for some frames leaves the body's view steady and its own not.  Both steady, or
    neither, or no last frame, and the dispute stands."""
    pixels, confidence = checked[0].copy(), checked[1].copy()
    kept = (confidence >= min_confidence) & np.isfinite(pixels).all(axis=2)
    seen = (detected[1] >= min_confidence) & np.isfinite(detected[0]).all(axis=2)
    unsettled = (kept.sum(axis=0) < 2) & (seen.sum(axis=0) == 2)
    if previous is None or not unsettled.any():  # no dispute to settle: most frames
        return pixels, confidence
    moved_on = np.array([_steady(detected[0][k], seen[k], previous[k], steady) for k in range(len(seen))])
    wins = unsettled & seen & moved_on[:, None] & ((seen & ~moved_on[:, None]).sum(axis=0) == 1)
    pixels[wins] = detected[0][wins]
    confidence[wins] = detected[1][wins]
    return pixels, confidence


def _steady(pixels: np.ndarray, seen: np.ndarray, previous: np.ndarray, steady: float) -> bool:
    """Whether a view's ``seen`` detections ``pixels`` (K, 2) lie within ``steady`` of its ``previous`` landmarks in
    the median, as a share of their extent; not with fewer than :data:`STEADY_COUNT` landmarks in both."""
    both = seen & np.isfinite(previous).all(axis=1)
    if both.sum() < STEADY_COUNT:
        return False
    size = max(float(np.linalg.norm(np.ptp(previous[both], axis=0))), 1.0)
    return bool(np.median(np.linalg.norm(pixels[both] - previous[both], axis=1)) / size < steady)
