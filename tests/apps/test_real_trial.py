"""The real balancing trial (pose2sim-balancing, 4 HD views) tracked by ``tracker track`` from a bare folder, under
an ensemble of tiny perturbations: the same outcome on every machine (docs/keypoints.md, "The same result on every
machine").

A result that a last-bit change can flip (another numpy or BLAS kernel, another CPU) is not a pass.  So the trial is
tracked six times, with the constant-velocity prediction's damping at 1 and at 1 - k 1e-9 for k = 1..5 (a relative
change of the predicted motion of a few parts in a billion, which in this chaotic loop changes the frames' poses
from the second frame on), and every variant must hold him: his head's crown within 10 cm of his cap in all 100
frames, 45 mm in the median, no frame lost.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracker.cli import main
from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.status import LOST
from tracker.tracking.foreground import median_background, preparers

BALANCING = Path(__file__).resolve().parents[3] / "shared" / "data" / "pose2sim-balancing"
MAN = Path(__file__).resolve().parents[2] / "models" / "pose2sim_man.toml"


def cap_centres(recording, count: int) -> np.ndarray:
    """Pixel centroid (camera, frame, 2) of the man's cyan swimming cap, the largest blob of its hue; a check
    of the tracked head that shares nothing with the tracker (which never looks at hue)."""
    centres = np.zeros((len(recording.sources), count, 2))
    for index, images in frames(recording, 0, count, colour=True):
        for camera, image in enumerate(images):
            mask = cv2.inRange(cv2.cvtColor(image, cv2.COLOR_BGR2HSV), (80, 120, 80), (100, 255, 255))
            _, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
            centres[camera, index] = centroids[1 + np.argmax(stats[1:, cv2.CC_STAT_AREA])]
    return centres


def triangulate(cameras, pixels: np.ndarray) -> np.ndarray:
    """The world point (3,) nearest, in the linear (DLT) sense, to the rays of ``pixels`` (camera, 2)."""
    rows = []
    for camera, pixel in zip(cameras, pixels):
        x, y = camera.undistort_pixels(pixel[None])[0]
        projection = camera.camera_from_world[:3]
        rows += [x * projection[2] - projection[0], y * projection[2] - projection[1]]
    point = np.linalg.svd(np.array(rows))[2][-1]
    return point[:3] / point[3]


def nudged(poses: np.ndarray, seed: int) -> np.ndarray:
    """``poses`` (N, 4, 4) moved rigidly by 1 mm in a seeded direction and turned 0.1 degree about a seeded
    axis through the root's origin."""
    rng = np.random.default_rng(seed)
    shift, axis = rng.normal(size=(2, 3))
    turn = np.eye(4)
    turn[:3, :3] = cv2.Rodrigues(np.radians(0.1) * axis / np.linalg.norm(axis))[0]
    root = poses[0, :3, 3]
    turn[:3, 3] = root - turn[:3, :3] @ root + 0.001 * shift / np.linalg.norm(shift)
    return turn @ poses


HELD = 5  # frames the edges hold him in from every nudged first pose (measured: 0-4 of 31 starts, none beyond)


@pytest.mark.skipif(not BALANCING.is_dir(), reason="shared pose2sim-balancing data not present")
def test_real_man_head_held_from_every_nudged_first_pose():
    """pose2sim-balancing, all 4 HD views, median background, the README's settings: from the hand-made first
    pose and from 5 seeded nudges of it (1 mm, 0.1 degree), the tracked crown of the head stays within 10 cm of
    his cap (triangulated from the 4 views) in each of the first HELD frames, while he stands.

    Only these frames hold on every start: later, as he swings into the balance, whether the edges alone keep
    him turns on the last bits of the start or of a BLAS kernel (docs/real-footage.md has the measurements);
    the keypoint cue holds him through all 100 frames (the test below)."""
    from tracker.io.posefile import load_pose_file
    from tracker.model import load_model
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.settings import Settings

    recording = open_recording(BALANCING)
    model = load_model(MAN)
    first = load_pose_file(MAN.with_suffix(".init.toml"), model)
    settings = Settings().but(
        motion=dict(dynamics="kalman", frame_rate=recording.fps),
        outline=dict(search_range=40),
        solve=dict(iterations=16),
    )
    prepare = preparers(median_background(recording), Tracker(model, recording.cameras, first, settings).smooth)
    images = [images for _, images in frames(recording, 0, HELD, prepare=prepare, colour=True)]
    caps = cap_centres(recording, HELD)
    head = model.names.index("head")
    top = np.array([0.0, -0.01, 0.2, 1.0])  # the crown of the head ellipsoid, in the head's frame
    errors = np.zeros((6, HELD))
    for start, poses in enumerate([first] + [nudged(first, seed) for seed in range(5)]):
        tracker = Tracker(model, recording.cameras, poses, settings)
        for index in range(HELD):
            result = tracker.step(images[index], smoothed=True)
            cap = triangulate(recording.cameras, caps[:, index])
            errors[start, index] = np.linalg.norm((result.poses[head] @ top)[:3] - cap)
    assert errors.max() < 0.10, errors.round(3)


CHANGES = (0.0, 1e-9, 2e-9, 3e-9, 4e-9, 5e-9)
"""Relative changes of the predicted motion, one variant each (``--damping 1 - change``)."""

CROWN = np.array([0.0, -0.01, 0.2, 1.0])
"""The crown of the head ellipsoid, in the head's frame."""


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    """The recording, its caps' world points (frame, 3) triangulated from the 4 views, and a folder that keeps the
    keypoint detector's landmarks of the first variant for the others (the detector's own result does not change
    with the tracker's perturbation)."""
    recording = open_recording(BALANCING)
    caps = cap_centres(recording, recording.frame_count)
    points = np.array([triangulate(recording.cameras, caps[:, frame]) for frame in range(recording.frame_count)])
    return recording, points, tmp_path_factory.mktemp("landmarks")


@pytest.mark.skipif(not BALANCING.is_dir(), reason="shared pose2sim-balancing data not present")
@pytest.mark.parametrize("change", CHANGES)
def test_real_man_held_through_all_frames_without_a_first_pose(trial, tmp_path, change):
    """No init file, no background, default settings but frame by frame (``--smooth none``: the cue's hold, not the
    frames after it): the first pose fitted to the keypoints, the cue holding him through all 100 frames under each
    perturbation (measured on an AVX2 machine: median 22-23 mm, max 36-73 mm over the variants; docs/keypoints.md)."""
    recording, caps, landmarks = trial
    out = tmp_path / "out"
    out.mkdir()
    cached = landmarks / "keypoints.npz"
    if cached.exists():
        shutil.copy(cached, out / "keypoints.npz")
    argv = ["track", str(BALANCING), "--model", str(MAN), "--out", str(out), "--quiet", "--smooth", "none"]
    argv += ["--damping", repr(1 - change)]
    assert main(argv) == 0
    if not cached.exists():
        shutil.copy(out / "keypoints.npz", cached)
    results = load_poses(out / "poses.npz")
    head = list(results["component_names"]).index("head")
    crowns = (results["poses"][:, head] @ CROWN)[:, :3]
    errors = np.linalg.norm(crowns - caps[results["frame"]], axis=1)
    assert len(errors) == recording.frame_count == 100 and not (results["status"] == LOST).any()
    assert errors.max() < 0.10 and np.median(errors) < 0.045, errors.round(3)
