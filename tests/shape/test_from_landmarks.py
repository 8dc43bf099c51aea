"""The joints fitted to landmarks (tracker.shape.from_landmarks): exact landmarks of a reshaped body give its joints."""

from __future__ import annotations

import cv2
import numpy as np
from conftest import HUMAN

from tracker.errors import TrackerInputError
from tracker.landmarks.body_landmarks import LANDMARKS, anchors, landmark_world
from tracker.model import model_from_dict, poses_from_rotations
from tracker.proportions import sizes, stretched
from tracker.shape.from_landmarks import PRIOR, design, fit_landmarks, solve
from tracker.shape.layout import Layout
from tracker.tomlfile import read_toml


def posed_landmarks(model, rng, frames):
    """World points (F, 33, 3) of the landmarks of ``model`` in random poses (F, N, 4, 4), where the keypoint cue
    puts them (the joint centres and the head's, hands' and feet's surface points), and the poses."""
    component, point = anchors(model)
    out, poses = np.full((frames, len(LANDMARKS), 3), np.nan), []
    for f in range(frames):
        turns = rng.normal(size=(model.size, 3)) * 0.35
        turns[0] = [0.0, 0.0, rng.uniform(-3, 3)]  # upright, facing anywhere
        rotations = np.stack([cv2.Rodrigues(turn)[0] for turn in turns])
        poses.append(model.coerce(poses_from_rotations(model, rng.normal(size=3) * [1, 1, 0] + [0, 0, 1], rotations)))
        out[f] = landmark_world(poses[-1], component, point)
    return out, np.stack(poses)


def reshaped_body(document, rng):
    """A model TOML document: ``document`` with every part's length and thickness drawn within +-15 %."""
    factors = {
        c["name"]: np.r_[rng.uniform(0.85, 1.15, 2)[[0, 0]], rng.uniform(0.85, 1.15)] for c in document["component"]
    }
    for name in list(factors):
        if name.endswith("_r"):
            factors[name] = factors[name[:-2] + "_l"]
    return stretched(document, factors)


MEASURED = ("length to shin", "length to foot", "length to forearm", "length to hand", "length to thigh")
"""The joint distances that the joint landmarks measure (the trunk's inner joints they do not)."""


def test_with_the_rotations_known_the_joints_are_solved_exactly():
    """The linear step alone, at the true rotations: the limbs' lengths and the hips' width come out exact."""
    document = read_toml(HUMAN, "model", "")
    rng = np.random.default_rng(0)
    body = reshaped_body(document, rng)
    points, poses = posed_landmarks(model_from_dict(body), rng, 8)
    model = model_from_dict(document)
    layout = Layout.of(model)
    x = solve(design(layout, model, poses[:, :, :3, :3]), points, layout.prior(PRIOR, PRIOR))
    for true, got in zip(sizes(body), sizes(layout.document(x, document))):
        if true.what.startswith(MEASURED):
            assert abs(got.metres - true.metres) < 5e-4, (true, got)


def test_exact_landmarks_of_a_reshaped_body_bring_its_limbs_closer():
    """The whole stage, the poses fitted with the given model first: a start, not the answer (each pose is
    fitted with the joints pulled towards rest a little, and once)."""
    document = read_toml(HUMAN, "model", "")
    rng = np.random.default_rng(0)
    body = reshaped_body(document, rng)
    points, _ = posed_landmarks(model_from_dict(body), rng, 8)
    layout = Layout.of(model_from_dict(document))
    fit = fit_landmarks(layout, document, points, frames=np.arange(8))
    fitted = layout.document(fit.x, document)
    errors = [
        (abs(got.metres - true.metres), abs(given.metres - true.metres))
        for true, got, given in zip(sizes(body), sizes(fitted), sizes(document))
        if true.what.startswith(MEASURED)
    ]
    after, before = np.array(errors).T
    assert after.max() < 0.015 and after.mean() < before.mean() / 3
    assert fit.misfit < fit.misfit_before / 2


def test_too_few_frames_with_the_trunk_is_a_one_line_error(one_line_error):
    document = read_toml(HUMAN, "model", "")
    points, _ = posed_landmarks(model_from_dict(document), np.random.default_rng(1), 4)
    points[:, LANDMARKS.index("left_hip")] = np.nan
    layout = Layout.of(model_from_dict(document))
    message = one_line_error(lambda: fit_landmarks(layout, document, points, frames=np.arange(4)))
    assert "0 of 4 frames" in message and "--frames" in message
    assert issubclass(TrackerInputError, Exception)
