"""Hips read high: where a table or a desk hides them, the detector puts the hips at the edge of what it sees.

A person's shoulders and hips keep their distance. Triangulated frame by frame, the midpoints of the landmarks'
shoulders and of their hips lie, in the median frame, 0.94-1.42 of the model's trunk apart (its shoulder joints'
midpoint to its hip joints') on the hard suite's renders whose hips are seen (0.75 or more in 95 % of their frames)
and 1.05 on the balancing trial, against 0.84 on ``table-booth`` (0.55 in its lowest twentieth) and 0.51-0.57 on the
seated renders, whose desks hide the hips: there the detector reads them at the desk's edge, and a fit to them tips
the whole body over to bring them up (docs/keypoints.md, "Hips read high"). So in a frame whose views place the
hips' midpoint nearer the shoulders' than :data:`HIPS_HIGH` of the trunk, and that guess a leg too (a leg bone far
shorter than the model's, :func:`tracker.landmarks.guessed.guessed`: the lower body is hidden, not misread), the hips
are taken to lie along the same line, a trunk's length from the shoulders, and each view's hip detections are moved
by the image shift of that midpoint (:func:`lowered`). Midpoints need no left and right: a view that swaps them
reads the same midpoint.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tracker.camera import Camera
from tracker.geometry.dlt import triangulate_many
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.guessed import bone_lengths, guessed
from tracker.landmarks.guided import rays
from tracker.landmarks.store import Keypoints
from tracker.model import Model, rest_poses

HIPS_HIGH = 0.75
"""The share of the model's trunk below which the hips' and the shoulders' midpoints lie too near each other: the
hips were read high, where a leg is guessed too (module docstring)."""

HIPS = np.array([LANDMARKS.index("left_hip"), LANDMARKS.index("right_hip")])
SHOULDERS = np.array([LANDMARKS.index("left_shoulder"), LANDMARKS.index("right_shoulder")])


@dataclasses.dataclass(frozen=True)
class Proportions:
    """The model's ``trunk`` (metres from the midpoint of its shoulder joints, the upper arms' origins, to that of
    its hip joints, the thighs') and its ``legs``' bone lengths (:func:`tracker.landmarks.guessed.bone_lengths`)."""

    trunk: float
    legs: np.ndarray


def proportions(model: Model) -> Proportions | None:
    """The model's :class:`Proportions`, at rest; None for a model without shoulders and hips."""
    names = ("upperarm_l", "upperarm_r", "thigh_l", "thigh_r")
    if not all(name in model.names for name in names):
        return None
    rest = rest_poses(model, np.eye(4))
    joints = rest[[model.index(name) for name in names], :3, 3]
    component, point, _ = landmark_points(model, LANDMARKS)
    trunk = float(np.linalg.norm(joints[:2].mean(axis=0) - joints[2:].mean(axis=0)))
    return Proportions(trunk, bone_lengths(rest, component, point))


def lowered(
    pixels: np.ndarray,
    confidence: np.ndarray,
    *,
    cameras: list[Camera],
    body: Proportions | None,
    min_confidence: float = 0.5,
) -> np.ndarray:
    """One frame's landmark ``pixels`` (C, 33, 2) with the hips moved down the trunk where the views read them high
    and guess a leg (module docstring), for a model of proportions ``body`` (None: unchanged); ``confidence``
    (C, 33).  The midpoints are triangulated from the views that see both hips and both shoulders at
    ``min_confidence``."""
    seen = (confidence >= min_confidence) & np.isfinite(pixels).all(axis=2)
    hips_seen = seen[:, HIPS].all(axis=1)
    both = hips_seen & seen[:, SHOULDERS].all(axis=1)
    if body is None or both.sum() < 2:
        return pixels
    middles = np.stack([pixels[:, HIPS].mean(axis=1), pixels[:, SHOULDERS].mean(axis=1)], axis=1)  # (C, 2, 2)
    used = np.repeat(both[:, None], 2, axis=1)
    hips, shoulders = triangulate_many(*rays(cameras, middles, used), used.T)
    read = float(np.linalg.norm(hips - shoulders))
    if not np.isfinite(read) or read >= HIPS_HIGH * body.trunk or read < 1e-6:
        return pixels
    if not guessed(cameras, pixels, confidence, lengths=body.legs).any():  # the hips misread, not hidden
        return pixels
    moved = shoulders + (hips - shoulders) * (body.trunk / read)
    out = pixels.copy()
    for k in np.flatnonzero(hips_seen):
        out[k, HIPS] += cameras[k].project(moved[None])[0] - cameras[k].project(hips[None])[0]
    return out


def with_hips_lowered(keypoints: Keypoints, cameras: list[Camera], model: Model) -> Keypoints:
    """``keypoints`` with every frame's hips :func:`lowered` where its views read them high."""
    body = proportions(model)
    if body is None or len(keypoints.frame) == 0:
        return keypoints
    pixels = np.stack(
        [
            lowered(frame, confident, cameras=cameras, body=body)
            for frame, confident in zip(keypoints.pixels, keypoints.confidence)
        ]
    )
    return dataclasses.replace(keypoints, pixels=pixels)
