"""World points of the landmarks over a recording's first frames, with left and right told by the body
(docs/keypoints.md, "Automatic first pose").

Per frame (:func:`frame_points`): the views that follow someone else are left out (:func:`strays`); each
landmark, and each left/right pair with every view free to read it either way round, is triangulated from
the views that agree (:func:`tracker.landmarks.consistency.readings`).  Two views alone cannot always tell
a swap: when the pair lies along their epipolar lines, both readings triangulate, to points at different
depths.  Of the readings that most detections agree with, the one whose distances to the landmarks already
placed fit the model's is kept (:func:`tracker.landmarks.anchors.rigid_distances`, the shoulders' width, an
upper arm's length; and :func:`tracker.landmarks.anchors.reach`): first the pairs that lie across the body
(hips, shoulders, ears, eyes) and the single landmarks, then the limbs' pairs from the trunk outwards.
Every pair is labelled by the person's left (:func:`body_left`) where that is known (a limb's pair,
otherwise, by those distances); a point out of reach of the others is dropped (:func:`within_reach`).
Then the frames' labels are aligned (:func:`aligned`) and, per landmark, the median over the frames is its
point: the body moves little in a few frames, while one frame's detections may be swapped or missing.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tracker.camera import Camera
from tracker.landmarks.anchors import reach, rigid_distances
from tracker.landmarks.body_landmarks import LANDMARKS, left_right_pairs
from tracker.landmarks.consistency import Reading, readings
from tracker.landmarks.guided import GATE, undistorted
from tracker.landmarks.store import Keypoints
from tracker.model import Model

LATERAL = ("hip", "shoulder", "ear", "eye_inner", "eye", "eye_outer")
"""Pairs that lie across the body, labelled by the side they lie on."""

LIMB = ("elbow", "wrist", "pinky", "index", "thumb", "knee", "ankle", "heel", "foot_index")
"""The limbs' pairs, each after the one it hangs on."""

PERSON_SHARE = 0.5
"""A view of which a smaller share of detections agrees with the person's points follows someone else in that
frame: none of its detections is used (:func:`strays`)."""

REACH_SCALE, REACH_SLACK = 1.2, 0.1
"""Two landmarks may lie up to 1.2 times the model's reach between them, plus 10 cm, apart: the person may be
larger than the model, and two views' points a few centimetres off."""


@dataclass(frozen=True)
class Triangulated:
    """World points of the landmarks: ``points`` (33, 3) metres (NaN where no two views agreed in any frame
    used), ``views`` (33,) int, the median number of views that agreed on each, ``frames`` (F,), the keypoint
    frames used, and which detections ``agree`` (F, C, 33) bool with that frame's points, as a view read them
    (maybe swapped)."""

    points: np.ndarray
    views: np.ndarray
    frames: np.ndarray
    agree: np.ndarray


@dataclass(frozen=True)
class FramePoints:
    """The landmarks' world points frame by frame: ``rows`` (F,), the rows of the keypoints that show a person in
    two views or more, their ``points`` (F, 33, 3) metres (NaN where fewer than two views agree), how many
    ``views`` agreed on each (F, 33) int, and which detections ``agree`` (F, C, 33) bool with that frame's points,
    as a view read them (maybe swapped).  Each frame's pairs are labelled by the person's left where its points
    tell it (:func:`body_left`), not aligned with the other frames'."""

    rows: np.ndarray
    points: np.ndarray
    views: np.ndarray
    agree: np.ndarray


def frame_by_frame(
    keypoints: Keypoints,
    cameras: list[Camera],
    model: Model,
    *,
    frames: int | None = None,
    min_confidence: float = 0.5,
    gate: float = GATE,
) -> FramePoints:
    """The landmarks' world points in each of the first ``frames`` frames of ``keypoints`` (all by default, in
    ``cameras``) that show a person in two views or more (detections at least ``min_confidence``), views
    agreeing within ``gate`` of the image's short side, the distances those of ``model`` (module docstring)."""
    usable = (keypoints.confidence[:frames] >= min_confidence) & np.isfinite(keypoints.pixels[:frames]).all(axis=3)
    rows = np.flatnonzero(usable.any(axis=2).sum(axis=1) >= 2)
    pixels = np.where(usable[rows, ..., None], keypoints.pixels[rows], np.nan)
    normalised = undistorted(pixels, cameras)
    limits = np.array([gate * min(camera.size) for camera in cameras])
    distances, farthest = rigid_distances(model), REACH_SCALE * reach(model) + REACH_SLACK
    points = np.full((len(rows), len(LANDMARKS), 3), np.nan)
    views = np.zeros((len(rows), len(LANDMARKS)), np.int64)
    agree = np.zeros(pixels.shape[:3], bool)
    for row in range(len(rows)):
        points[row], views[row], read_as = frame_points(
            cameras, pixels[row], normalised[row], limits=limits, distances=distances, farthest=farthest
        )
        points[row] = within_reach(points[row], farthest)
        kept = np.isfinite(points[row]).all(axis=1)
        views[row][~kept] = 0
        agree[row] = (read_as >= 0) & kept[read_as]
    return FramePoints(rows, points, views, agree)


def triangulated(
    keypoints: Keypoints,
    cameras: list[Camera],
    model: Model,
    *,
    frames: int,
    min_confidence: float = 0.5,
    gate: float = GATE,
) -> Triangulated:
    """The landmarks' world points over the first ``frames`` frames of ``keypoints`` (in ``cameras``) that show
    a person in two views or more (:func:`frame_by_frame`), the frames' labels aligned and the median taken
    (module docstring)."""
    found = frame_by_frame(keypoints, cameras, model, frames=frames, min_confidence=min_confidence, gate=gate)
    points = aligned(found.points)
    seen = np.isfinite(points).all(axis=2)
    median = np.full((len(LANDMARKS), 3), np.nan)
    support = np.zeros(len(LANDMARKS), np.int64)
    for j in np.flatnonzero(seen.any(axis=0)):
        median[j] = np.median(points[seen[:, j], j], axis=0)
        support[j] = round(float(np.median(found.views[seen[:, j], j])))
    return Triangulated(median, support, keypoints.frame[found.rows], found.agree)


def aligned(points: np.ndarray) -> np.ndarray:
    """World points (F, 33, 3) of F frames with each left/right pair labelled as in the frames before: swapped in
    a frame where the other labelling lies nearer (summed distance) to the pair's first known points."""
    out = points.copy()
    for pair in left_right_pairs(LANDMARKS):
        reference = np.full((2, 3), np.nan)
        for frame in out:
            straight = np.linalg.norm(frame[pair] - reference, axis=1)
            crossed = np.linalg.norm(frame[pair[::-1]] - reference, axis=1)
            if np.nansum(crossed) < np.nansum(straight):
                frame[pair] = frame[pair[::-1]]
            reference = np.where(np.isnan(reference), frame[pair], reference)
    return out


def _index(name: str) -> int:
    return LANDMARKS.index(name)


def _pair(part: str) -> list[int]:
    return [_index(f"left_{part}"), _index(f"right_{part}")]


def frame_points(
    cameras: list[Camera],
    pixels: np.ndarray,
    normalised: np.ndarray,
    *,
    limits: np.ndarray,
    distances: np.ndarray,
    farthest: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One frame's world points (33, 3) of the landmarks (NaN: fewer than two views agree), how many views
    agreed on each (33,), and the point each detection agrees with as its view reads it (C, 33) int (-1:
    none), from ``pixels`` (C, 33, 2) (NaN: not usable), the same ``normalised``, agreement ``limits`` (C,)
    pixels, the model's rigid ``distances`` (33, 33) and the ``farthest`` two landmarks may lie apart
    (33, 33) (module docstring)."""
    paired = left_right_pairs(LANDMARKS)
    lateral = [tuple(_pair(part)) for part in LATERAL]
    limbs = [tuple(_pair(part)) for part in LIMB]
    singles: list[tuple[int, ...]] = [(j,) for j in range(len(LANDMARKS)) if j not in paired]

    def read(pixels: np.ndarray, normalised: np.ndarray) -> dict[tuple[int, ...], list[Reading]]:
        return {
            group: readings(cameras, pixels[:, group], normalised[:, group], limits=limits, swaps=len(group) == 2)
            for group in lateral + limbs + singles
        }

    stray = strays(cameras, pixels, normalised, limits=limits, groups=lateral + limbs + singles)
    found = read(np.where(stray[:, None, None], np.nan, pixels), np.where(stray[:, None, None], np.nan, normalised))
    points = np.full((len(LANDMARKS), 3), np.nan)
    views = np.zeros(len(LANDMARKS), np.int64)
    read_as = np.full(pixels.shape[:2], -1)

    def place(group: tuple[int, ...], swaps: bool) -> None:
        if found[group]:
            chosen = _choose(found[group], distances, farthest, points, list(group), swaps=swaps)
            points[list(group)], views[list(group)] = chosen.points, chosen.agree.sum(axis=0)
            for k, g in zip(*np.nonzero(chosen.agree)):
                read_as[k, group[len(group) - 1 - g if chosen.swapped[k] else g]] = group[g]

    def label(group: tuple[int, ...]) -> None:
        if left is not None and (points[group[0]] - points[group[1]]) @ left < 0:
            points[list(group)], views[list(group)] = points[list(group[::-1])], views[list(group[::-1])]
            for k, d in zip(*np.nonzero(np.isin(read_as, group))):
                read_as[k, d] = group[1] if read_as[k, d] == group[0] else group[0]

    for group in lateral + singles:
        place(group, swaps=False)
    best = np.full((len(LANDMARKS), 3), np.nan)
    for group, options in found.items():
        if options:
            best[list(group)] = options[0].points
    left = body_left(np.where(np.isfinite(points), points, best))
    for group in lateral:
        label(group)
    for group in limbs:
        place(group, swaps=True)
        label(group)
    return points, views, read_as


def strays(
    cameras: list[Camera],
    pixels: np.ndarray,
    normalised: np.ndarray,
    *,
    limits: np.ndarray,
    groups: list[tuple[int, ...]],
) -> np.ndarray:
    """The views (C,) bool that follow someone else in this frame.  Each pair of views triangulates every
    landmark ``group`` (a pair either way round) alone, and every view's detections (``pixels`` (C, 33, 2),
    NaN: not usable) are checked against those points; of the pairs whose points the most detections agree
    with, the first is taken for the person, and a view with less than :data:`PERSON_SHARE` of its detections
    agreeing follows someone else.  (Two views alone hardly tell: two people standing apart give rays that
    nearly meet when the cameras stand at one height.)"""
    seen = np.isfinite(pixels).all(axis=2)
    best = np.zeros(len(cameras))
    for a, b in itertools.combinations(np.flatnonzero(seen.any(axis=1)), 2):
        among = np.isin(np.arange(len(cameras)), (a, b))
        agreeing = np.zeros(len(cameras))
        for group in groups:
            found = readings(
                cameras, pixels[:, group], normalised[:, group], limits=limits, swaps=len(group) == 2, among=among
            )
            agreeing += found[0].agree.sum(axis=1) if found else 0
        if agreeing.sum() > best.sum():
            best = agreeing
    return best < PERSON_SHARE * seen.sum(axis=1)


def _choose(
    found: list[Reading],
    distances: np.ndarray,
    farthest: np.ndarray,
    points: np.ndarray,
    group: list[int],
    *,
    swaps: bool,
) -> Reading:
    """Of the readings ``found`` of landmarks ``group`` that most detections agree with (and, with ``swaps``, of
    each labelled either way round), the one whose distances to each other and to the ``points`` placed so far
    fit the body best: the least sum of squared differences from the rigid ``distances`` and of squared
    excesses over the ``farthest`` apart they can lie (the first among equals)."""
    most = int(found[0].agree.sum())
    options = [reading for reading in found if int(reading.agree.sum()) == most]
    if swaps:
        options += [Reading(r.points[::-1], ~r.swapped, r.agree[:, ::-1], r.distance) for r in options]
    placed = points.copy()

    def misfit(reading: Reading) -> float:
        placed[group] = reading.points
        apart = np.linalg.norm(placed[group, None] - placed[None], axis=2)
        return float(
            np.nansum((apart - distances[group]) ** 2) + np.nansum(np.maximum(apart - farthest[group], 0) ** 2)
        )

    return min(options, key=misfit)


def within_reach(points: np.ndarray, farthest: np.ndarray) -> np.ndarray:
    """World points (33, 3) without the landmarks that lie farther from others than ``farthest`` (33, 33)
    allows: from the hips outwards (in the order of ``farthest`` from the nearer hip), each known point is kept
    when it lies within reach of every one kept before it, else becomes NaN."""
    out = np.full_like(points, np.nan)
    order = np.argsort(farthest[_pair("hip")].min(axis=0), kind="stable")
    for j in order:
        kept = np.isfinite(out).all(axis=1)
        if np.all(np.linalg.norm(out[kept] - points[j], axis=1) <= farthest[j, kept]):
            out[j] = points[j]
    return out


def middle(points: np.ndarray, part: str) -> np.ndarray:
    """The midpoint (3,) of the left and right ``part`` (NaN unless both are known)."""
    return points[_pair(part)].mean(axis=0)


def body_left(points: np.ndarray) -> np.ndarray | None:
    """The person's left (3,), a unit vector ``up x forward`` from world points (33, 3) of the landmarks, or None
    when they do not tell: up from the hips' midpoint to the shoulders', forward (across up) from the heels'
    midpoint to the toes' and from the ears' to the nose; all of these whichever way the pairs are labelled."""
    up = middle(points, "shoulder") - middle(points, "hip")
    if not np.isfinite(up).all() or np.linalg.norm(up) < 1e-6:
        return None
    up /= np.linalg.norm(up)
    forward = np.zeros(3)
    for cue in (
        middle(points, "foot_index") - middle(points, "heel"),
        points[_index("nose")] - middle(points, "ear"),
    ):
        across = cue - (cue @ up) * up
        if np.isfinite(across).all() and np.linalg.norm(across) > 1e-6:
            forward += across / np.linalg.norm(across)
    if np.linalg.norm(forward) < 1e-6:
        return None
    left = np.cross(up, forward)
    return left / np.linalg.norm(left)
