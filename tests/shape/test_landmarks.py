"""The joints fitted to landmarks (tracker.shape.landmarks): exact landmarks of a reshaped body give its joints."""

from __future__ import annotations

import cv2
import numpy as np
from conftest import HUMAN

from tracker.errors import TrackerInputError
from tracker.keypoint_cue import LANDMARKS, anchors, landmark_world
from tracker.model import model_from_dict, poses_from_rotations
from tracker.proportions import sizes, stretched
from tracker.shape.landmarks import fit_landmarks
from tracker.shape.layout import Layout
from tracker.tomlfile import read_toml


def joint_landmarks(model, rng, frames):
    """World points (F, 33, 3) of the landmarks of ``model`` in random poses, where the keypoint cue puts them
    (the joint centres and the head's, hands' and feet's surface points)."""
    component, point = anchors(model)
    out = np.full((frames, len(LANDMARKS), 3), np.nan)
    for f in range(frames):
        turns = rng.normal(size=(model.size, 3)) * 0.35
        turns[0] = [0.0, 0.0, rng.uniform(-3, 3)]  # upright, facing anywhere
        rotations = np.stack([cv2.Rodrigues(turn)[0] for turn in turns])
        poses = model.coerce(poses_from_rotations(model, rng.normal(size=3) * [1, 1, 0] + [0, 0, 1], rotations))
        out[f] = landmark_world(poses, component, point)
    return out


def test_exact_landmarks_of_a_reshaped_body_give_its_joints():
    """Within a few millimetres: each frame's pose is fitted with the model as reshaped so far (its joints pulled
    towards rest a little), and only the limbs' lengths and the hips' width are measured by joint landmarks."""
    document = read_toml(HUMAN, "model", "")
    rng = np.random.default_rng(0)
    factors = {
        c["name"]: np.r_[rng.uniform(0.85, 1.15, 2)[[0, 0]], rng.uniform(0.85, 1.15)] for c in document["component"]
    }
    for name in list(factors):
        if name.endswith("_r"):
            factors[name] = factors[name[:-2] + "_l"]
    body = stretched(document, factors)
    points = joint_landmarks(model_from_dict(body), rng, 8)
    layout = Layout.of(model_from_dict(document))
    fit = fit_landmarks(layout, document, points, np.arange(8))
    fitted = layout.document(fit.x, document)
    measured = ("length to shin", "length to foot", "length to forearm", "length to hand", "length to thigh")
    for true, got in zip(sizes(body), sizes(fitted)):
        if true.what.startswith(measured):
            assert abs(got.metres - true.metres) < 0.005, (true, got)
    assert fit.misfit < fit.misfit_before / 3


def test_too_few_frames_with_the_trunk_is_a_one_line_error(one_line_error):
    document = read_toml(HUMAN, "model", "")
    points = joint_landmarks(model_from_dict(document), np.random.default_rng(1), 4)
    points[:, LANDMARKS.index("left_hip")] = np.nan
    layout = Layout.of(model_from_dict(document))
    message = one_line_error(lambda: fit_landmarks(layout, document, points, np.arange(4)))
    assert "0 of 4 frames" in message and "--frames" in message
    assert issubclass(TrackerInputError, Exception)
