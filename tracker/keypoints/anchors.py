"""Where BlazePose's landmarks sit on a body model: a component and a point in its frame, and the distances
between landmarks that no pose changes (docs/keypoints.md, "Automatic first pose").

A shoulder, elbow, wrist, hip, knee or ankle marks the joint centre of a :data:`tracker.keypoint_cue.SIDES`
component (its origin).  The nose and ears, the index and little-finger knuckles, the heel and the toes
mark points on the surface of the head, hand and foot: ``c + d * r`` on the component's first ellipsoid
(centre c, radii r) in the direction d of :data:`SURFACE`, with the component frames of models/human.toml
(x to the body's left, y backwards, z up at rest).
"""

from __future__ import annotations

import numpy as np

from tracker.chain import BALL, FIXED, HINGE
from tracker.keypoint_cue import LANDMARKS, landmark_points
from tracker.model import Model

SURFACE = {
    "nose": ("head", (0.0, -1.0, 0.0)),
    "left_ear": ("head", (1.0, 0.0, 0.0)),
    "right_ear": ("head", (-1.0, 0.0, 0.0)),
    "left_index": ("hand_l", (0.0, -1.0, 0.0)),
    "right_index": ("hand_r", (0.0, -1.0, 0.0)),
    "left_pinky": ("hand_l", (0.0, 1.0, 0.0)),
    "right_pinky": ("hand_r", (0.0, 1.0, 0.0)),
    "left_heel": ("foot_l", (0.0, 1.0, 0.0)),
    "right_heel": ("foot_r", (0.0, 1.0, 0.0)),
    "left_foot_index": ("foot_l", (0.0, -1.0, 0.0)),
    "right_foot_index": ("foot_r", (0.0, -1.0, 0.0)),
}
"""Landmark -> (component, direction d): the nose in front of the head, the ears at its sides, the index
knuckle at the front of the hand and the little finger's at its back (the palm faces the thigh at rest),
the heel behind the foot and the toes in front."""


def anchors(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Each landmark's component (33,) int (-1 when the model has none) and its point (33, 3) in that
    component's frame: the joint centres of :data:`tracker.keypoint_cue.SIDES` and the :data:`SURFACE`
    points (where the component's first quadric is an ellipsoid or a sphere)."""
    component, point, _ = landmark_points(model, LANDMARKS)
    for name, (part, direction) in SURFACE.items():
        if part not in model.names:
            continue
        index = model.index(part)
        owned = np.flatnonzero(model.quadric_component == index)
        if len(owned) == 0 or model.quadric_shape[owned[0]] not in ("ellipsoid", "sphere"):
            continue
        params = model.quadric_params[owned[0]]
        radii = np.asarray(params["radii"] if "radii" in params else [params["radius"]] * 3, float)
        centre = np.asarray(params.get("center", [0.0, 0.0, 0.0]), float)
        component[LANDMARKS.index(name)] = index
        point[LANDMARKS.index(name)] = centre + np.multiply(direction, radii)
    return component, point


def _fixed_points(model: Model) -> list[list[tuple[int, np.ndarray]]]:
    """For the 33 landmarks and then every component's origin (its joint centre): the components in whose
    frames it is fixed, each with its point there.  A landmark's point is fixed in its component's frame,
    an origin in its own; a joint centre also in its parent's (a ball or hinge turns about it, a fixed joint
    fixes the whole component)."""
    component, point = anchors(model)
    nodes = [(int(i), p) for i, p in zip(component, point)] + [(i, np.zeros(3)) for i in range(model.size)]
    fixed: list[list[tuple[int, np.ndarray]]] = []
    for i, p in nodes:
        fixed.append([])
        if i < 0:
            continue
        fixed[-1].append((i, p))
        parent, kind = model.parent[i], model.joint_type[i]
        if parent >= 0 and (kind == FIXED or (kind in (BALL, HINGE) and not np.any(p))):
            fixed[-1].append((int(parent), model.rest[i, :3, :3] @ p + model.rest[i, :3, 3]))
    return fixed


def _distances(model: Model) -> np.ndarray:
    """Metres between every two of the landmarks and the joint centres (:func:`_fixed_points`) that share a
    frame, NaN for the others."""
    fixed = _fixed_points(model)
    out = np.full((len(fixed), len(fixed)), np.nan)
    for j, k in zip(*np.triu_indices(len(fixed), 1)):
        for body, p in fixed[j]:
            for other, q in fixed[k]:
                if body == other:
                    out[j, k] = out[k, j] = np.linalg.norm(p - q)
    return out


def rigid_distances(model: Model) -> np.ndarray:
    """Metres (33, 33) between two landmarks' model points that every pose keeps apart by the same distance,
    NaN for the others (and on the diagonal): those fixed in one component's frame (e.g. the shoulders in the
    torso's, a shoulder and an elbow in the upper arm's)."""
    count = len(LANDMARKS)
    return _distances(model)[:count, :count]


def reach(model: Model) -> np.ndarray:
    """The farthest (33, 33) metres that any pose can hold two landmarks apart: the shortest chain of rigid
    distances between them through the landmarks and joint centres (inf when none joins them, 0 on the
    diagonal)."""
    distances = _distances(model)
    farthest = np.where(np.isfinite(distances), distances, np.inf)
    np.fill_diagonal(farthest, 0.0)
    for k in range(len(farthest)):
        farthest = np.minimum(farthest, farthest[:, k : k + 1] + farthest[k : k + 1, :])
    count = len(LANDMARKS)
    return farthest[:count, :count]
