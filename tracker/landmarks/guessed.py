"""Legs the detector guessed: landmarks whose bones triangulate far shorter than the model's.

The keypoint network places every landmark whether the limb is seen or not.  Behind a table it draws the
hidden legs inside the part of the person it sees: on the hard suite's ``table-booth`` the knees 18-26 % and
the ankles 30-38 % of the body's size above their true images (median, every view), each view's guess
plausible and near the others', so the check across the views keeps them, and so does the person's mask,
which they lie on.  Their bones then triangulate to under half their length (thigh and shin 0.16-0.19 m in
the median, against 0.35-0.42 m wherever the legs are seen), which no real leg does from any side:
foreshortening shortens a bone in one image, not in 3-D.  Such a landmark, and every one below it on its
leg, is a guess; the parts it ends are hidden from the views, where their outlines find the table's edges,
not their own.  The tracker gives those parts no edge, colour or landmark weight in that frame
(:meth:`tracker.tracking.frame_loop.Tracker.step`), so the motion prior and the joints carry them.

:func:`leg_landmarks` and :func:`axis_points` serve the legs hidden from one view, which the person's mask tells
(:meth:`tracker.tracking.frame_loop.Tracker.see_person`).

The legs only: a forearm is short and a wrist the detector's noisiest landmark, and forearms triangulate
under half their length in up to 14 % of the frames of renders whose arms are all seen.  docs/keypoints.md,
"Guessed legs", has the measurements.
"""

from __future__ import annotations

import numpy as np

from tracker.camera import Camera
from tracker.geometry.dlt import triangulate_many
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_world
from tracker.model import Model, with_descendants

SHORT = 0.5
"""A bone triangulated shorter than this share of the model's is a guess."""

BONES = tuple(
    (LANDMARKS.index(f"{side}_{upper}"), LANDMARKS.index(f"{side}_{lower}"))
    for side in ("left", "right")
    for upper, lower in (("hip", "knee"), ("knee", "ankle"))
)
"""(upper, lower) landmark indices of the legs' bones, each after the one it hangs on."""

BELOW = {
    LANDMARKS.index(f"{side}_{joint}"): [LANDMARKS.index(f"{side}_{name}") for name in names]
    for side in ("left", "right")
    for joint, names in (("knee", ("knee", "ankle", "heel", "foot_index")), ("ankle", ("ankle", "heel", "foot_index")))
}
"""The landmarks a bone's lower end takes with it when it is a guess (itself included)."""

MIN_CONFIDENCE = 0.5
"""A detection's confidence from which it is triangulated: that of the check across the views."""


def bone_lengths(poses: np.ndarray, component: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The legs' bones' lengths (len(BONES),) at ``poses`` (N, 4, 4), any pose of the model (its joints hold
    them): the distances between the model points ``point`` in ``component`` of their landmarks
    (:func:`tracker.landmarks.body_landmarks.landmark_world`)."""
    world = landmark_world(poses, component, point)
    return np.array([np.linalg.norm(world[upper] - world[lower]) for upper, lower in BONES])


def guessed(cameras: list[Camera], pixels: np.ndarray, confidence: np.ndarray, *, lengths: np.ndarray) -> np.ndarray:
    """The landmarks (K,) bool that the detections ``pixels`` (C, K, 2) at ``confidence`` (C, K) in ``cameras``
    guess: below each bone of :data:`BONES` whose ends, each triangulated from the views that see it at
    :data:`MIN_CONFIDENCE` (two or more), lie closer than :data:`SHORT` of its model length ``lengths``
    (:func:`bone_lengths`), its lower end and the landmarks below it (:data:`BELOW`)."""
    ends = sorted({j for bone in BONES for j in bone})
    usable = (confidence[:, ends] >= MIN_CONFIDENCE) & np.isfinite(pixels[:, ends]).all(axis=2)  # (C, E)
    out = np.zeros(len(LANDMARKS), bool)
    if (usable.sum(axis=0) < 2).all():
        return out
    normalised = np.stack(
        [camera.undistort_pixels(np.nan_to_num(pixels[k, ends])) for k, camera in enumerate(cameras)], axis=1
    )  # (E, C, 2)
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    world = dict(zip(ends, triangulate_many(projections, normalised, usable.T)))
    for (upper, lower), length in zip(BONES, lengths):
        if np.linalg.norm(world[upper] - world[lower]) < SHORT * length:  # False where an end is unknown (NaN)
            out[BELOW[lower]] = True
    return out


def hidden_parts(model: Model, component: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """The components (N,) bool that the guessed ``landmarks`` (K,) bool hide: for each (on ``component``),
    the part its joint hangs from (the thigh above a knee, the shin above an ankle) and every part below
    that."""
    tops = np.zeros(model.size, bool)
    for j in np.flatnonzero(landmarks & (component >= 0)):
        top = model.parent[component[j]]
        if top >= 0:
            tops[top] = True
    return with_descendants(model.parent, tops)


def leg_landmarks() -> np.ndarray:
    """The landmarks (K,) bool whose guess hides a leg: every one below a hip."""
    chosen = np.zeros(len(LANDMARKS), bool)
    for below in BELOW.values():
        chosen[below] = True
    return chosen


def axis_points(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Three points along the axis of every quadric of ``model``, in its component's frame: component (P,) and
    point (P, 3); a cone's or cylinder's ends and middle, an ellipsoid's centre and 0.6 of its longest semi-axis
    either way."""
    component, points = [], []
    for c, spec in zip(model.quadric_component, model.quadric_params):
        if spec["shape"] in ("cone", "cylinder"):
            start, end = np.asarray(spec["from"], float), np.asarray(spec["to"], float)
            chosen = [start, 0.5 * (start + end), end]
        else:
            centre = np.asarray(spec.get("center", (0.0, 0.0, 0.0)), float)
            semi = np.full(3, spec["radius"]) if spec["shape"] == "sphere" else np.asarray(spec["radii"], float)
            half = np.zeros(3)
            half[int(np.argmax(semi))] = 0.6 * semi.max()
            chosen = [centre - half, centre, centre + half]
        component += [int(c)] * 3
        points += chosen
    return np.asarray(component, np.int64), np.asarray(points)
