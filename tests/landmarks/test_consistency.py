"""Checking detections across the views on perfect landmarks of the demo: a view swapped left/right is put
right, a view showing someone else is dropped whole, two views that disagree are settled by the tracked body, and
the batched triangulation is the single one."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from tracker.geometry.dlt import triangulate_many
from tracker.io.poses import load_poses
from tracker.io.recording import open_recording
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.consistency import consistent, sided_with, triangulate, unswapped
from tracker.landmarks.store import Keypoints
from tracker.model import load_model

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


@pytest.fixture(scope="module")
def perfect():
    """Frames 0-4 of the demo: the true joint centres' images in its three cameras, confidence 1."""
    recording = open_recording(DEMO)
    model = load_model(recording.model_path)
    truth = load_poses(DEMO / "truth.npz")
    component = landmark_points(model, LANDMARKS)[0]
    pixels = np.full((5, 3, len(LANDMARKS), 2), np.nan)
    for k, camera in enumerate(recording.cameras):
        for j in np.flatnonzero(component >= 0):
            pixels[:, k, j] = camera.project(truth["poses"][:5, component[j], :3, 3])
    confidence = np.where(np.isfinite(pixels[..., 0]), 1.0, 0.0)
    names = tuple(camera.name for camera in recording.cameras)
    keypoints = Keypoints(np.arange(5), names, pixels, confidence, np.zeros((5, 3, len(LANDMARKS), 3)))
    return recording.cameras, keypoints


def test_perfect_views_are_all_kept(perfect):
    cameras, keypoints = perfect
    checked, dropped = consistent(keypoints, cameras)
    np.testing.assert_array_equal(checked.confidence, keypoints.confidence)
    np.testing.assert_array_equal(checked.pixels, keypoints.pixels)
    assert not dropped.any()


def test_landmarks_off_the_persons_mask_are_dropped_and_not_counted(perfect):
    """Masks that show the person in every view of every frame but for cam2's knees' and ankles' pixels in frame 1
    (a table before the legs): those landmarks go, nothing else, and the share dropped by the check stays 0."""
    cameras, keypoints = perfect
    square = np.zeros((5, 3, 3))
    square[..., :2] = np.nanmean(keypoints.pixels, axis=2)
    square[..., 2] = 400.0
    mask = np.full((5, 3, 256, 256), 255, np.uint8)
    legs = [LANDMARKS.index(f"{side}_{joint}") for side in ("left", "right") for joint in ("knee", "ankle")]
    for j in legs:  # holes 30 crop pixels about each, twice the widening (FAR_OFF)
        x, y = 256 / 400.0 * (keypoints.pixels[1, 2, j] - square[1, 2, :2]) + 128
        mask[1, 2, max(0, int(y) - 30) : int(y) + 30, max(0, int(x) - 30) : int(x) + 30] = 0
    checked, dropped = consistent(dataclasses.replace(keypoints, mask=mask, square=square), cameras)
    expected = keypoints.confidence.copy()
    expected[1, 2, legs] = 0.0
    np.testing.assert_array_equal(checked.confidence, expected)
    assert not dropped.any()


def test_a_view_swapped_left_right_is_put_right(perfect):
    cameras, keypoints = perfect
    knees = [LANDMARKS.index("left_knee"), LANDMARKS.index("right_knee")]
    pixels = keypoints.pixels.copy()
    pixels[2, 1, knees] = keypoints.pixels[2, 1, knees[::-1]]
    fixed = unswapped(
        Keypoints(keypoints.frame, keypoints.camera_names, pixels, keypoints.confidence, keypoints.world), cameras
    )
    np.testing.assert_array_equal(fixed.pixels, keypoints.pixels)


def test_a_view_showing_someone_else_is_dropped_whole(perfect):
    """cam1 sees a person 150 px to the right of the body in frame 3: every landmark of that view goes."""
    cameras, keypoints = perfect
    pixels = keypoints.pixels.copy()
    pixels[3, 1] += np.array([150.0, 0.0])
    moved = Keypoints(keypoints.frame, keypoints.camera_names, pixels, keypoints.confidence, keypoints.world)
    checked, _ = consistent(moved, cameras)
    assert not checked.confidence[3, 1].any()
    np.testing.assert_array_equal(checked.confidence[:, [0, 2]], keypoints.confidence[:, [0, 2]])
    np.testing.assert_array_equal(np.delete(checked.confidence, 3, axis=0), np.delete(keypoints.confidence, 3, axis=0))


def test_batched_triangulation_is_the_single_one():
    rng = np.random.default_rng(3)
    cameras = open_recording(DEMO).cameras
    points = rng.normal([0.0, 0.0, 1.0], 0.4, size=(6, 3))
    normalised = np.stack(
        [np.stack([camera.undistort_pixels(camera.project(p))[0] for camera in cameras]) for p in points]
    )
    normalised += rng.normal(scale=1e-3, size=normalised.shape)
    seen = np.ones((6, 3), bool)
    seen[0, 1] = seen[1, 0] = False
    seen[2] = [True, False, False]
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    batched = triangulate_many(projections, normalised, seen)
    for m in range(6):
        views = np.flatnonzero(seen[m])
        if len(views) < 2:
            assert np.isnan(batched[m]).all()
        else:
            single = triangulate([cameras[k] for k in views], normalised[m, views])
            np.testing.assert_allclose(batched[m], single, atol=1e-9)


@pytest.fixture
def disputed(perfect):
    """Frame 0 of :func:`perfect` seen by cam0 and cam1 only, cam0 showing someone else 150 px lower: the detections
    (pixels, confidence), the check's (pixels, confidence) and which landmarks the model places."""
    cameras, keypoints = perfect
    model = load_model(open_recording(DEMO).model_path)
    component = landmark_points(model, LANDMARKS)[0]
    pixels = keypoints.pixels[:1, :2].copy()
    pixels[0, 0] += [0.0, 150.0]
    detected = Keypoints(np.arange(1), ("cam0", "cam1"), pixels, keypoints.confidence[:1, :2], keypoints.world[:1, :2])
    checked = consistent(detected, cameras[:2])[0]
    return (pixels[0], detected.confidence[0]), (checked.pixels[0], checked.confidence[0]), component >= 0


def test_a_view_that_moved_on_steadily_settles_a_dispute(perfect, disputed):
    """Two views disagree and the check keeps neither; each view's own last landmarks settle it: cam0 jumped 150 px
    since (to someone else), cam1 moved a pixel, so cam1's disputed landmarks come back and cam0's stay out.  Where
    both moved on steadily, or neither, or no last frame is known, the dispute stands; and a landmark the check kept
    in two views of three is left as it is."""
    cameras, keypoints = perfect
    found, before, seen = disputed
    assert not (before[1][:, seen] >= 0.5).any()  # the views alone keep neither
    last = keypoints.pixels[0, :2] + [1.0, 0.0]  # where each view's landmarks were at the last detected frame
    got_pixels, got_confidence = sided_with(found, before, previous=last)
    assert not (got_confidence[0] >= 0.5).any()
    assert (got_confidence[1, seen] >= 0.5).all()
    np.testing.assert_array_equal(got_pixels[1, seen], found[0][1, seen])
    for previous in (found[0] + [1.0, 0.0], last + [300.0, 0.0], None):  # both steady, neither, none known
        _, unsettled = sided_with(found, before, previous=previous)
        assert not (unsettled[:, seen] >= 0.5).any()
    three = consistent(keypoints.at_frames(np.array([0])), cameras)[0]
    settled = (three.pixels[0], three.confidence[0])
    kept = sided_with((keypoints.pixels[0], keypoints.confidence[0]), settled, previous=keypoints.pixels[0])
    np.testing.assert_array_equal(kept[1], settled[1])
