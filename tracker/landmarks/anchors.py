"""The distances between BlazePose's landmarks that no pose of a body model changes, and how far apart a
pose can put them (docs/keypoints.md, "Automatic first pose"); the landmarks sit on the model where
:func:`tracker.landmarks.body_landmarks.anchors` puts them.
"""

from __future__ import annotations

import numpy as np

from tracker.chain import BALL, FIXED, HINGE
from tracker.landmarks.body_landmarks import LANDMARKS, anchors
from tracker.model import Model


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
