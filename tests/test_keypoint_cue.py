"""The keypoint cue: the projection Jacobian against finite differences, the left/right swap test, and
one solve that pulls a far-off body back onto perfect landmarks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker.geometry import se3
from tracker.io.poses import load_poses
from tracker.io.recording import open_recording
from tracker.keypoint_cue import keypoint_kernel, landmark_points, project_point
from tracker.keypoints.detector import LANDMARKS
from tracker.model import load_model
from tracker.outline import Rig

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "recordings" / "demo"


def test_projection_jacobian_matches_finite_differences():
    rng = np.random.default_rng(5)
    camera = open_recording(DEMO).cameras[1]
    rig = Rig.from_cameras([camera])
    distortion = rig.distortion[0] + np.array([-0.1, 0.02, 0.001, -0.002, 0.0])
    pose = se3.exp(np.r_[0.1, -0.2, 0.9, rng.normal(scale=0.3, size=3)])
    point = np.array([0.05, -0.02, -0.2])
    pixel, jac = project_point(rig.matrix[0], distortion, rig.camera_from_world[0] @ pose, point)
    numeric = np.zeros((2, 6))
    for a in range(6):
        step = np.zeros(6)
        step[a] = 1e-6
        plus = project_point(rig.matrix[0], distortion, rig.camera_from_world[0] @ pose @ se3.exp(step), point)[0]
        minus = project_point(rig.matrix[0], distortion, rig.camera_from_world[0] @ pose @ se3.exp(-step), point)[0]
        numeric[:, a] = (plus - minus) / 2e-6
    np.testing.assert_allclose(jac, numeric, rtol=1e-5, atol=1e-4)
    assert np.isfinite(pixel).all()


def test_landmarks_map_onto_the_human_model():
    model = load_model(ROOT / "models" / "human.toml")
    component, point, pairs = landmark_points(model, LANDMARKS)
    assert component[LANDMARKS.index("left_knee")] == model.names.index("shin_l")
    assert component[LANDMARKS.index("right_shoulder")] == model.names.index("upperarm_r")
    assert (component >= 0).sum() == 12 and component[LANDMARKS.index("nose")] == -1
    assert len(pairs) == 15 and not point.any()  # every left_* with its right_* (the mouth corners are not)


@pytest.fixture(scope="module")
def demo_frame():
    """The demo's rig, model, true poses of frame 0 and perfect detections: the true joint centres' images."""
    recording = open_recording(DEMO)
    model = load_model(recording.model_path)
    truth = load_poses(DEMO / "truth.npz")
    rig = Rig.from_cameras(recording.cameras)
    component, point, pairs = landmark_points(model, LANDMARKS)
    poses = truth["poses"][0]
    pixels = np.full((len(recording.cameras), len(LANDMARKS), 2), np.nan)
    for k, camera in enumerate(recording.cameras):
        for j in np.flatnonzero(component >= 0):
            pixels[k, j] = camera.project((poses[component[j]] @ np.append(point[j], 1.0))[:3])
    return model, rig, component, point, pairs, poses, pixels


def _add(model, rig, component, point, pairs, poses, pixels, confidence):
    information = np.zeros((model.size, 6, 6))
    eta = np.zeros((model.size, 6))
    counts = keypoint_kernel(
        poses,
        rig.camera_from_world,
        rig.matrix,
        rig.distortion,
        component,
        point,
        pairs,
        pixels,
        confidence,
        0.5,
        2.0,
        1.0,
        information,
        eta,
    )
    return counts, information, eta


def test_perfect_landmarks_at_the_truth_add_information_and_no_pull(demo_frame):
    model, rig, component, point, pairs, poses, pixels = demo_frame
    confidence = np.ones(pixels.shape[:2])
    (used, rejected), information, eta = _add(model, rig, component, point, pairs, poses, pixels, confidence)
    assert used == 3 * 12 and rejected == 0
    np.testing.assert_allclose(eta, 0.0, atol=1e-6)
    for j in np.flatnonzero(component >= 0):
        assert np.linalg.matrix_rank(information[component[j]][:3, :3]) == 3


def test_swapped_pairs_are_rejected_and_low_confidence_ignored(demo_frame):
    model, rig, component, point, pairs, poses, pixels = demo_frame
    swapped = pixels.copy()
    left, right = LANDMARKS.index("left_knee"), LANDMARKS.index("right_knee")
    swapped[1, [left, right]] = pixels[1, [right, left]]
    confidence = np.ones(pixels.shape[:2])
    confidence[2, LANDMARKS.index("left_wrist")] = 0.2
    (used, rejected), _, eta = _add(model, rig, component, point, pairs, poses, swapped, confidence)
    assert rejected == 1 and used == 3 * 12 - 2 - 1
    np.testing.assert_allclose(eta, 0.0, atol=1e-6)
