"""The detector's regions: the square around landmarks, the crop's map and its inverse, the search's tiles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker.io.poses import load_poses
from tracker.landmarks.crop import SMALLEST, Region, around, crop_from_image, cut, search, to_image


def test_square_around_landmarks_by_hand():
    """Landmarks spanning x 100..140 and y 50..130 (NaN rows ignored): centre (120, 90), side 2.5 * 80."""
    pixels = np.array([[100.0, 50.0], [140.0, 130.0], [np.nan, np.nan], [110.0, 70.0]])
    region = around(pixels)
    assert region is not None
    assert region.centre == (120.0, 90.0) and region.side == 200.0
    assert around(np.full((33, 2), np.nan)) is None
    tiny = around(np.array([[10.0, 10.0], [11.0, 12.0]]))
    assert tiny is not None and tiny.side == SMALLEST


def test_crop_map_and_its_inverse():
    """A region's centre lands at the crop's centre and its corners at the crop's corners; to_image undoes
    crop_from_image exactly, for any point (also outside the image)."""
    region = Region((300.0, 200.0), 64.0)
    forward = crop_from_image(region, 256)
    corners = np.array([[268.0, 168.0], [332.0, 232.0], [300.0, 200.0]])
    mapped = corners @ forward[:, :2].T + forward[:, 2]
    np.testing.assert_allclose(mapped, [[0.0, 0.0], [256.0, 256.0], [128.0, 128.0]], atol=1e-12)
    points = np.random.default_rng(3).uniform(-500.0, 1500.0, (50, 2))
    np.testing.assert_allclose(to_image(points @ forward[:, :2].T + forward[:, 2], region, 256), points, atol=1e-9)


def test_cut_moves_an_image_point_where_the_map_says():
    """A bright pixel of the image appears in the crop where crop_from_image puts it (upscaled 4 times,
    bilinear: the brightest crop pixel), and the crop is black beyond the image's border."""
    image = np.zeros((120, 160), np.uint8)
    image[40, 70] = 255
    region = Region((60.0, 50.0), 64.0)
    crop = cut(image, region, 256)
    assert crop.shape == (256, 256)
    forward = crop_from_image(region, 256)
    expected = forward[:, :2] @ np.array([70.0, 40.0]) + forward[:, 2]
    row, column = np.unravel_index(np.argmax(crop), crop.shape)
    assert abs(column - expected[0]) <= 1 and abs(row - expected[1]) <= 1
    outside = cut(np.full((120, 160), 200, np.uint8), Region((0.0, 0.0), 40.0), 64)
    assert outside[:30, :30].max() == 0 and outside[34:, 34:].min() == 200


@pytest.mark.parametrize("width, height, count", [(640, 480, 15), (800, 600, 15), (480, 640, 15), (300, 300, 9)])
def test_search_zooms_out_then_covers_the_image_with_tiles(width, height, count):
    """First the whole image in a square twice its long side, centred; then squares of half the short
    side, inside the image, neighbours overlapping by at least half, from the top left to the bottom right."""
    whole, *found = search(width, height)
    assert whole == Region((width / 2, height / 2), 2.0 * max(width, height))
    side = min(width, height) // 2
    assert len(found) == count and all(tile.side == side for tile in found)
    centres = np.array([tile.centre for tile in found])
    assert tuple(centres[0]) == (side / 2, side / 2) and tuple(centres[-1]) == (width - side / 2, height - side / 2)
    for axis in (0, 1):
        steps = np.diff(np.unique(centres[:, axis]))
        assert (steps <= side / 2 + 1e-9).all()


def _plain_finds(image: np.ndarray) -> bool:
    """Whether BlazePose's whole-image pass alone (a fresh landmarker) finds a person in a BGR image."""
    import cv2

    from tracker.landmarks.detector import pose_solution

    with pose_solution().Pose(static_image_mode=True, model_complexity=1) as landmarker:
        return landmarker.process(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)).pose_landmarks is not None


def test_a_far_body_is_found_where_the_whole_image_shows_nobody(tmp_path):
    """The demo's rig moved back 2.5 times (a body about 70 px tall in 640x480, a face, in a room), 6
    frames: the whole-image pass finds nobody in any of the 18 views; with the crops the detector finds the
    person in every view, its joint landmarks a few per cent of the body's size from the true joint centres
    (measured: docs/keypoints.md)."""
    from tracker.io.recording import frames, open_recording
    from tracker.landmarks.detect_recording import detect_recording
    from tracker.model import load_model
    from tracker.synthetic.keypoint_accuracy import accuracy
    from tracker.synthetic.synth import Staging, synthesize

    root = Path(__file__).resolve().parents[2]
    folder = tmp_path / "far"
    synthesize(
        root / "models" / "human.toml",
        root / "calib" / "demo3.toml",
        folder,
        frames=6,
        seed=3,
        progress=False,
        staging=Staging(distance=2.5, backdrop="room", face=True),
    )
    recording = open_recording(folder)
    plain = [_plain_finds(image) for _, images in frames(recording, colour=True) for image in images]
    assert not any(plain)
    keypoints, _ = detect_recording(recording, landmark_model="full")
    truth = load_poses(folder / "truth.npz")["poses"]
    score = accuracy(keypoints, recording.cameras, truth, model=load_model(folder / "model.toml"))
    assert score.found == score.views == 18
    assert score.median < 0.05 and score.on_body == 18, score
