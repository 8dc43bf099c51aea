"""The foreground cue: the channel-sum difference, the median background, its files, and the CLI."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracker.camera import Camera, load_calibration, look_at_camera, save_calibration
from tracker.cli import main
from tracker.errors import TrackerInputError
from tracker.io.poses import PosesWriter
from tracker.io.readers import keeping_grey
from tracker.io.recording import frames, open_recording
from tracker.model import joint_centres, load_model, rest_poses
from tracker.synthetic.render import Renderer, load_backgrounds
from tracker.tracking.foreground import (
    Background,
    cleared_background,
    load_background,
    median_background,
    preparers,
    reduced_camera,
    sample_indices,
    save_background,
)

WIDTH, HEIGHT, COUNT = 48, 32, 9


def scene(camera: int) -> np.ndarray:
    """The empty scene of camera ``camera``: seeded colour noise."""
    return np.random.default_rng(10 + camera).integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)


def square(index: int) -> tuple[slice, slice]:
    """Where the moving 'person' is in frame ``index``: each pixel is covered in at most 2 of 9 frames."""
    return slice(8, 24), slice(5 * index % (WIDTH - 8), 5 * index % (WIDTH - 8) + 8)


def frame(camera: int, index: int) -> np.ndarray:
    image = scene(camera).copy()
    image[square(index)] = (30, 200, 90)
    return image


@pytest.fixture()
def png_recording(tmp_path: Path) -> Path:
    """Two cameras as lossless PNG folders, so the background comes back exactly."""
    folder = tmp_path / "rec"
    K = np.array([[40.0, 0.0, 24.0], [0.0, 40.0, 16.0], [0.0, 0.0, 1.0]])
    save_calibration(
        [Camera(f"cam{i}", (WIDTH, HEIGHT), K, np.zeros(4), np.eye(3), np.array([i, 0.0, 3.0])) for i in range(2)],
        folder / "calibration.toml",
    )
    for camera in range(2):
        (folder / f"cam{camera}").mkdir()
        for index in range(COUNT):
            cv2.imwrite(str(folder / f"cam{camera}" / f"{index:06d}.png"), frame(camera, index))
    return folder


def test_difference_is_the_saturated_channel_sum():
    rng = np.random.default_rng(0)
    image, empty = rng.integers(0, 256, (2, 20, 30, 3), dtype=np.uint8)
    expected = np.minimum(255, np.abs(image.astype(int) - empty.astype(int)).sum(axis=2))
    got = Background((empty,)).difference(0, image)
    assert got.dtype == np.uint8 and got.shape == (20, 30)
    np.testing.assert_array_equal(got, expected)


def test_sample_indices_spread_over_the_recording():
    np.testing.assert_array_equal(sample_indices(5, 25), np.arange(5))
    picked = sample_indices(1000, 25)
    assert len(picked) == 25 and picked[0] == 0 and picked[-1] == 999
    assert np.ptp(np.diff(picked)) <= 1  # evenly spaced


def test_median_background_recovers_the_empty_scene(png_recording):
    recording = open_recording(png_recording)
    seen = []
    background = median_background(recording, progress=lambda reads: seen.extend(reads) or reads)
    assert seen == [(camera, index) for camera in range(2) for index in range(COUNT)]
    for camera in range(2):
        np.testing.assert_array_equal(background.images[camera], scene(camera))
        difference = background.difference(camera, frame(camera, 4))
        inside = np.zeros((HEIGHT, WIDTH), bool)
        inside[square(4)] = True
        assert not difference[~inside].any() and (difference[inside] > 0).mean() > 0.99


def test_readers_hand_colour_frames_to_per_camera_preparers(png_recording):
    recording = open_recording(png_recording)
    background = Background(tuple(scene(camera) for camera in range(2)))
    prepared = [keeping_grey(prepare) for prepare in preparers(background, lambda image: image)]
    for index, items in frames(recording, prepare=prepared, colour=True):
        for camera, (grey, measured) in enumerate(items):
            np.testing.assert_array_equal(grey, cv2.cvtColor(frame(camera, index), cv2.COLOR_BGR2GRAY))
            np.testing.assert_array_equal(measured, background.difference(camera, frame(camera, index)))


def test_saved_background_loads_back_and_is_checked(png_recording, tmp_path):
    recording = open_recording(png_recording)
    background = Background(tuple(scene(camera) for camera in range(2)))
    folder = save_background(background, recording, tmp_path / "bg")
    loaded = load_background(folder, recording)
    for camera in range(2):
        np.testing.assert_array_equal(loaded.images[camera], scene(camera))
    cv2.imwrite(str(folder / "cam1.png"), scene(1)[:, :40])
    with pytest.raises(TrackerInputError, match=r"cam1\.png: background is 40x32 but camera cam1 gives 48x32"):
        load_background(folder, recording)
    (folder / "cam1.png").unlink()
    with pytest.raises(TrackerInputError, match=r"cam1\.png: no background image for camera cam1"):
        load_background(folder, recording)
    with pytest.raises(TrackerInputError, match="background folder not found"):
        load_background(tmp_path / "nowhere", recording)


def test_track_with_a_median_background(tiny_recording, tmp_path, capsys):
    out = tmp_path / "out"
    overlay = tmp_path / "overlay.avi"
    assert (
        main(
            [
                "track",
                str(tiny_recording),
                "--background",
                "median",
                "--out",
                str(out),
                "--quiet",
                "--overlay",
                str(overlay),
            ]
        )
        == 0
    )
    assert "background: per-pixel median of 6 frames per camera" in capsys.readouterr().err
    for camera in ("cam0", "cam1"):
        assert cv2.imread(str(out / "background" / f"{camera}.png")).shape == (240, 320, 3)
    video = cv2.VideoCapture(str(overlay))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 6
    ok, picture = video.read()
    assert ok and picture.std() > 20  # the camera frames themselves, not the (mostly black) differences


def test_track_against_the_empty_scene(tiny_recording, tmp_path, capsys):
    """The rendering's own background photos as the empty scene: the body is tracked as well as by grey edges
    (6 frames in which the body hardly moves: the median background would hold the body itself). Edges only, as
    the test means: the keypoint cue, on by default, can fuse detections of the photos' basketball players."""
    rig = load_calibration(tiny_recording / "calibration.toml")
    photos, _ = load_backgrounds(rig, seed=1)
    save_background(Background(tuple(photos)), open_recording(tiny_recording), tmp_path / "empty")
    assert (
        main(
            [
                "track",
                str(tiny_recording),
                "--background",
                str(tmp_path / "empty"),
                "--out",
                str(tmp_path / "out"),
                "--keypoints",  # the edges of the difference image alone, as the grey ones are compared
                "off",
                "--quiet",
            ]
        )
        == 0
    )
    report = capsys.readouterr().out
    assert "0 uncertain, 0 lost" in report
    mpjpe = float(re.search(r"MPJPE ([0-9.]+) mm", report).group(1))
    assert mpjpe < 15.0


def test_missing_background_folder_is_one_line_exit_2(tiny_recording, tmp_path, capsys):
    assert (
        main(
            [
                "track",
                str(tiny_recording),
                "--background",
                str(tmp_path / "nowhere"),
                "--out",
                str(tmp_path / "out"),
                "--quiet",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere: background folder not found" in err[0]


MODELS = Path(__file__).resolve().parents[2] / "models"
STILL = 6  # frames the body stands at the centre; the other three put it far to each side


def standing_poses(model) -> np.ndarray:
    """(9, N, 4, 4): the rest pose at x = 0 in frames 0-5, then at x = -1.4, +1.4 and +2.8."""
    places = [0.0] * STILL + [-1.4, 1.4, 2.8]
    poses = []
    for x in places:
        root = np.eye(4)
        root[:3, 3] = (x, 0.0, 0.95)
        poses.append(rest_poses(model, root))
    return np.array(poses)


@pytest.fixture()
def standing_recording(tmp_path: Path):
    """One PNG camera watching a body that stands still in two thirds of the frames, so the plain
    median keeps it; the scene is seeded colour noise and the rendering has no sensor noise."""
    model = load_model(MODELS / "human.toml")
    camera = look_at_camera("cam0", eye=(0.0, -5.0, 1.0), size=(96, 72), focal=100.0)
    folder = tmp_path / "standing"
    save_calibration([camera], folder / "calibration.toml")
    empty = np.random.default_rng(3).integers(0, 256, (72, 96, 3), dtype=np.uint8)
    renderer = Renderer(model, camera, empty, noise=0.0)
    poses = standing_poses(model)
    (folder / "cam0").mkdir()
    for index, pose in enumerate(poses):
        cv2.imwrite(str(folder / "cam0" / f"{index:06d}.png"), renderer.render(pose))
    body = renderer.cast(poses[0])[0] >= 0
    return folder, model, poses, empty, body


def test_cleared_background_removes_a_body_that_stands_still(standing_recording):
    folder, model, poses, empty, body = standing_recording
    recording = open_recording(folder)
    plain = median_background(recording).images[0]
    assert body.sum() > 150
    assert np.abs(plain.astype(int) - empty).sum(axis=2)[body].mean() > 60  # the median keeps him
    cleared = cleared_background(recording, model, frames=np.arange(9), poses=poses, margin=2)
    got = cleared.background.images[0]
    np.testing.assert_array_equal(got[body], empty[body])
    assert (got == empty).all(axis=2).mean() > 0.999
    assert cleared.replaced[0] >= body.mean() and cleared.hidden == (0.0,)
    np.testing.assert_array_equal(cleared.frames, np.arange(9))


def test_cleared_background_keeps_the_plain_median_where_the_track_sees_no_body(standing_recording):
    folder, model, poses, empty, body = standing_recording
    recording = open_recording(folder)
    away = poses.copy()
    away[:, :, 0, 3] += 20.0  # a track that puts him out of view: nothing is masked
    cleared = cleared_background(recording, model, frames=np.arange(9), poses=away, margin=2)
    np.testing.assert_array_equal(cleared.background.images[0], median_background(recording).images[0])
    assert cleared.replaced == (0.0,)


def test_reduced_camera_keeps_pixel_centres():
    camera = look_at_camera("c", eye=(0.5, -4.0, 1.2), size=(101, 75), focal=80.0, distortions=(-0.1, 0.02, 0, 0))
    small = reduced_camera(camera, 4.0)
    assert small.size == (26, 19)
    points = np.random.default_rng(1).uniform((-0.5, -0.5, 0.5), (0.5, 0.5, 1.5), (20, 3))
    np.testing.assert_allclose(small.project(points), (camera.project(points) + 0.5) / 4.0 - 0.5, atol=1e-9)


def test_background_command_writes_the_cleared_scene(standing_recording, tmp_path, capsys):
    folder, model, poses, empty, body = standing_recording
    out = tmp_path / "run"
    with PosesWriter(out / "poses.npz", list(model.names), list(model.joint_names), 30.0) as writer:
        for index, pose in enumerate(poses):
            writer.append(index, pose, joint_centres(pose), status=0, residual=1.0)
    assert (
        main(
            [
                "background",
                str(folder),
                "--model",
                str(MODELS / "human.toml"),
                "--poses",
                str(out / "poses.npz"),
                "--margin",
                "2",
                "--quiet",
            ]
        )
        == 0
    )
    got = cv2.imread(str(out / "background-cleared" / "cam0.png"))
    np.testing.assert_array_equal(got[body], empty[body])
    printed = capsys.readouterr().out
    assert "median of 9 tracked frames" in printed and "cam0:" in printed


def test_background_command_errors(standing_recording, tmp_path, capsys):
    folder, model, poses, empty, body = standing_recording
    human = str(MODELS / "human.toml")

    def error(*argv: str) -> str:
        assert main(["background", str(folder), *argv]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1
        return lines[0]

    assert "none.npz: file not found" in error("--model", human, "--poses", str(tmp_path / "none.npz"))
    lost = tmp_path / "lost" / "poses.npz"
    with PosesWriter(lost, list(model.names), list(model.joint_names), 30.0) as writer:
        for index, pose in enumerate(poses):
            writer.append(index, pose, joint_centres(pose), status=2, residual=float("nan"))
    assert "0 frames with a pose that is not lost" in error("--model", human, "--poses", str(lost))
    other = tmp_path / "other.toml"
    other.write_text((MODELS / "human.toml").read_text().replace('"pelvis"', '"hips"'))
    assert "do not match the model" in error("--model", str(other), "--poses", str(lost))
    good = tmp_path / "good" / "poses.npz"
    with PosesWriter(good, list(model.names), list(model.joint_names), 30.0) as writer:
        for index, pose in enumerate(poses):
            writer.append(index, pose, joint_centres(pose), status=0, residual=1.0)
    assert "--samples 3: too few" in error("--model", human, "--poses", str(good), "--samples", "3")
