"""The detector alone as a baseline: its landmarks triangulated frame by frame, against a render's truth.

The tracker fuses the detector's landmarks with the image cues; it should never do worse than those landmarks
alone.  Per frame, each of the twelve joint landmarks (shoulders, elbows, wrists, hips, knees, ankles: the joint
centres of :data:`tracker.landmarks.body_landmarks.SIDES`) is triangulated from the views that agree on it, left and
right told by the body (:func:`tracker.landmarks.triangulation.frame_by_frame`), with no tracking and no model
fit.  Its error is the distance to the true joint centre where the truth has one (the camera sees the joint);
the tracker is scored over the same joints and frames, so the two numbers compare.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracker.camera import Camera
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.store import Keypoints
from tracker.landmarks.triangulation import frame_by_frame
from tracker.model import Model


@dataclass(frozen=True)
class Baseline:
    """Millimetres: the triangulated landmarks' mean error (``landmarks_mm``) and the tracker's over the same
    joints and frames (``tracker_mm``), and the share of the truth's joint landmarks (joint and frame) the
    landmarks gave (``coverage``); NaN where there is nothing to average."""

    landmarks_mm: float
    tracker_mm: float
    coverage: float


def baseline(
    keypoints: Keypoints, truth: dict, *, cameras: list[Camera], model: Model, poses: dict | None = None
) -> Baseline:
    """The baseline of ``keypoints`` (seen by ``cameras``, distances of ``model``) against ``truth`` (a truth.npz's
    arrays), and the tracker's ``poses`` (a poses.npz's) over the same joints and frames."""
    by_name = {camera.name: camera for camera in cameras}
    found = frame_by_frame(keypoints, [by_name[name] for name in keypoints.camera_names], model)
    component, _, _ = landmark_points(model, LANDMARKS)
    landmarks = np.flatnonzero(component >= 0)
    names = list(truth["joint_names"])
    columns = np.array([names.index(model.names[component[j]]) for j in landmarks])
    truth_rows = {int(frame): row for row, frame in enumerate(truth.get("frame", np.arange(len(truth["joints"]))))}
    tracked_rows = {}
    if poses is not None:
        pose_names = list(poses["joint_names"])
        pose_columns = np.array([pose_names.index(model.names[component[j]]) for j in landmarks])
        frames = poses.get("frame", np.arange(len(poses["joints"])))
        tracked_rows = {int(frame): row for row, frame in enumerate(frames)}
    errors, tracker_errors = [], []
    for index, frame in enumerate(keypoints.frame[found.rows]):
        if int(frame) not in truth_rows:
            continue
        true = truth["joints"][truth_rows[int(frame)], columns]
        points = found.points[index, landmarks]
        both = np.isfinite(true).all(axis=1) & np.isfinite(points).all(axis=1)
        if poses is not None:
            if int(frame) not in tracked_rows:
                continue
            tracked = poses["joints"][tracked_rows[int(frame)], pose_columns]
            both &= np.isfinite(tracked).all(axis=1)
            tracker_errors.append(np.linalg.norm(tracked[both] - true[both], axis=1))
        errors.append(np.linalg.norm(points[both] - true[both], axis=1))
    known = int(np.isfinite(truth["joints"][:, columns]).all(axis=2).sum())
    error = np.concatenate(errors) if errors else np.zeros(0)
    tracker_error = np.concatenate(tracker_errors) if tracker_errors else np.zeros(0)
    return Baseline(
        landmarks_mm=1000.0 * float(error.mean()) if len(error) else math.nan,
        tracker_mm=1000.0 * float(tracker_error.mean()) if len(tracker_error) else math.nan,
        coverage=len(error) / known if known else math.nan,
    )
