"""The detector's accuracy against a render's truth: landmarks made from the truth itself, then moved,
swapped or dropped by known amounts, give the known scores."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tracker.camera import load_calibration
from tracker.io.poses import load_poses
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.store import Keypoints
from tracker.model import load_model
from tracker.synthetic.keypoint_accuracy import accuracy
from tracker.synthetic.synth import table_before


@pytest.fixture(scope="module")
def scene(tiny_recording):
    """The tiny recording's cameras, true poses, model, and keypoints at the true joints' images."""
    cameras = load_calibration(tiny_recording / "calibration.toml")
    poses = load_poses(tiny_recording / "truth.npz")["poses"]
    model = load_model(tiny_recording / "model.toml")
    component = landmark_points(model, LANDMARKS)[0]
    pixels = np.full((len(poses), len(cameras), len(LANDMARKS), 2), np.nan)
    for k, camera in enumerate(cameras):
        for j in np.flatnonzero(component >= 0):
            pixels[:, k, j] = camera.project(poses[:, component[j], 0:3, 3])
    confidence = np.where(np.isfinite(pixels[..., 0]), 0.9, 0.3)  # the face's landmarks: unsure
    exact = Keypoints(
        np.arange(len(poses)), tuple(c.name for c in cameras), pixels, confidence, np.zeros((*pixels.shape[:3], 3))
    )
    sizes = np.stack(
        [
            np.ptp(camera.project(poses[:, :, 0:3, 3].reshape(-1, 3)).reshape(len(poses), -1, 2), axis=1)
            for camera in cameras
        ],
        axis=1,
    )
    return cameras, poses, model, exact, np.linalg.norm(sizes, axis=2)  # sizes (F, C): the body's diagonal


def test_the_truth_scores_zero_and_known_moves_score_their_size(scene):
    cameras, poses, model, exact, size = scene
    score = accuracy(exact, cameras, poses, model=model)
    views = len(poses) * len(cameras)
    assert (score.views, score.found, score.scored, score.on_body) == (views, views, 12 * views, views)
    assert score.median == pytest.approx(0.0, abs=1e-9) and score.wrong == 0.0 and score.swapped == 0.0
    for share, wrong, on_body in ((0.05, 0.0, views), (0.15, 1.0, views), (0.3, 1.0, 0)):
        moved = exact.pixels + (share * size)[:, :, None, None] * np.array([0.6, 0.8])  # |offset| = share * size
        score = accuracy(dataclasses.replace(exact, pixels=moved), cameras, poses, model=model)
        assert score.median == pytest.approx(share, rel=1e-9) and score.wrong == wrong and score.on_body == on_body
        assert math.isnan(score.swapped) if on_body == 0 else score.swapped == 0.0


def test_swapped_views_unsure_landmarks_absent_people_and_hidden_joints(scene):
    cameras, poses, model, exact, _ = scene
    _, _, pairs = landmark_points(model, LANDMARKS)
    pixels, confidence = exact.pixels.copy(), exact.confidence.copy()
    pixels[0:3, 0][:, pairs.ravel()] = exact.pixels[0:3, 0][:, pairs[:, ::-1].ravel()]  # cam0 mirrored in frames 0-2
    confidence[5, 1, 11:17] = 0.2  # cam1's arms unsure in frame 5
    pixels[4, 1], confidence[4, 1] = np.nan, 0.0  # nobody found by cam1 in frame 4
    score = accuracy(dataclasses.replace(exact, pixels=pixels, confidence=confidence), cameras, poses, model=model)
    views = len(poses) * len(cameras)
    assert (score.found, score.scored) == (views - 1, 12 * (views - 1) - 6)
    assert score.on_body == views - 1 and score.swapped == pytest.approx(3 / (views - 1))
    hidden = accuracy(exact, cameras, poses, model=model, props=(table_before(cameras[0], gap=0.5),))
    assert 12 * views - 4 * len(poses) <= hidden.scored < 12 * views  # at most the knees and ankles, in cam0
