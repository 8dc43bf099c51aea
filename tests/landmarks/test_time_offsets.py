"""The cameras' capture-time offsets from the landmarks' motion (tracker.landmarks.time_offsets): the epipolar distance
against a brute-force one, offsets found from landmarks seen at known capture times, a body standing still left
undecided, and the pairs' shifts joined by least squares."""

import dataclasses
import shutil

import numpy as np
import pytest
from conftest import file_hashes

from tracker.apps.sync import Refined
from tracker.camera import load_calibration, look_at_camera, save_calibration
from tracker.cli import main
from tracker.io.recording import open_recording
from tracker.io.sync_file import load_offsets
from tracker.landmarks.store import Keypoints
from tracker.landmarks.time_offsets import _solved, camera_offsets, epipolar_pixels, essential

FPS = 30.0


@pytest.fixture(scope="module")
def rig():
    return [
        look_at_camera("cam0", (0.4, -4.0, 1.5), (0.0, 0.0, 1.0), size=(640, 480), focal=520.0),
        look_at_camera("cam1", (3.8, 1.0, 1.3), (0.0, 0.0, 1.0), size=(640, 480), focal=480.0),
        look_at_camera(
            "cam2", (-3.0, 2.8, 1.8), (0.0, 0.0, 1.0), size=(640, 480), focal=560.0, distortions=(-0.08, 0.02, 0, 0)
        ),
    ]


def test_the_epipolar_distance_is_the_pixel_distance_to_the_epipolar_line(rig):
    """Brute force: the epipolar line of a first-camera point is the image in the second camera of two points on its
    ray; the distance is each point's to the other's line, averaged, in ideal (undistorted) pixels."""
    first, second = rig[0], rig[1]
    rng = np.random.default_rng(1)
    world = rng.uniform([-0.5, -0.5, 0.3], [0.5, 0.5, 1.8], size=(20, 3))
    moved = world + rng.normal(0.0, 0.05, size=world.shape)  # the second camera sees other points
    a = (first.camera_from_world[:3, :3] @ world.T).T + first.camera_from_world[:3, 3]
    b = (second.camera_from_world[:3, :3] @ moved.T).T + second.camera_from_world[:3, 3]
    x1, x2 = a[:, :2] / a[:, 2:], b[:, :2] / b[:, 2:]
    matrix = essential(first, second)
    got = epipolar_pixels(x1, x2, matrix=matrix, focal=(first.matrix[0, 0], second.matrix[0, 0]))

    def line_distance(camera_from, camera_to, point_from, point_to, focal):
        centre = -camera_from[:3, :3].T @ camera_from[:3, 3]
        ray = camera_from[:3, :3].T @ np.append(point_from, 1.0)
        ends = [centre + ray, centre + 5.0 * ray]
        image = [(camera_to[:3, :3] @ e + camera_to[:3, 3]) for e in ends]
        p, q = (e[:2] / e[2] for e in image)
        direction = (q - p) / np.linalg.norm(q - p)
        offset = point_to - p
        return focal * abs(offset[0] * direction[1] - offset[1] * direction[0])

    for k in range(len(world)):
        in_second = line_distance(first.camera_from_world, second.camera_from_world, x1[k], x2[k], second.matrix[0, 0])
        in_first = line_distance(second.camera_from_world, first.camera_from_world, x2[k], x1[k], first.matrix[0, 0])
        assert got[k] == pytest.approx(0.5 * (in_first + in_second), rel=1e-9)
    same = (second.camera_from_world[:3, :3] @ world.T).T + second.camera_from_world[:3, 3]  # the points themselves
    on_line = epipolar_pixels(x1, same[:, :2] / same[:, 2:], matrix=matrix, focal=(500.0, 500.0))
    assert np.abs(on_line).max() < 1e-9


def _landmarks(rig, offsets, *, amplitude, frames=90, noise=0.7, seed=2):
    """33 points of a body-sized cloud, each swinging on its own sine (up to ``amplitude`` metres, 0.7-1.6 Hz), seen
    by each camera at its capture times n / FPS + offset, with pixel noise; pixels (F, C, 33, 2), confidence."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform([-0.3, -0.2, 0.2], [0.3, 0.2, 1.7], size=(33, 3))
    swing = rng.uniform(-1.0, 1.0, size=(33, 3)) * amplitude
    rate, phase = rng.uniform(0.7, 1.6, size=(33, 1)), rng.uniform(0.0, 2 * np.pi, size=(33, 1))
    pixels = np.empty((frames, len(rig), 33, 2))
    for k, (camera, offset) in enumerate(zip(rig, offsets)):
        for n in range(frames):
            t = n / FPS + offset
            pixels[n, k] = camera.project(centre + swing * np.sin(2 * np.pi * rate * t + phase))
    pixels += rng.normal(0.0, noise, size=pixels.shape)
    confidence = np.where(rng.random((frames, len(rig), 33)) < 0.1, 0.2, 0.9)  # a tenth unsure, left out
    return pixels, confidence


def test_offsets_are_found_from_a_moving_body(rig):
    offsets = np.array([0.0, 0.021, -0.05])
    pixels, confidence = _landmarks(rig, offsets, amplitude=0.25)
    found = camera_offsets(pixels, confidence, rig, fps=FPS, reach=0.3)
    assert found.decided.all()
    assert np.abs(found.seconds - offsets).max() < 0.002  # within 2 ms, a sixteenth of a frame
    assert (found.sigma[1:] > 0).all() and (found.sigma[1:] < 0.002).all()
    for (i, j), (shift, _, decided) in found.pairs.items():
        assert decided and abs(shift - (offsets[j] - offsets[i])) < 0.003


def test_a_body_standing_still_decides_nothing(rig):
    pixels, confidence = _landmarks(rig, [0.0, 0.03, -0.02], amplitude=0.0)
    found = camera_offsets(pixels, confidence, rig, fps=FPS, reach=0.3)
    assert not found.decided[1:].any() and np.isnan(found.seconds[1:]).all()
    assert not any(decided for _, _, decided in found.pairs.values())


def test_a_camera_that_never_sees_the_body_is_undecided(rig):
    offsets = [0.0, 0.021, -0.05]
    pixels, confidence = _landmarks(rig, offsets, amplitude=0.25)
    confidence[:, 2] = 0.0
    found = camera_offsets(pixels, confidence, rig, fps=FPS, reach=0.3)
    assert found.decided.tolist() == [True, True, False]
    assert abs(found.seconds[1] - 0.021) < 0.002


def test_the_pairs_shifts_are_joined_by_weighted_least_squares():
    pairs = {(0, 1): (0.02, 0.001, True), (0, 2): (-0.05, 0.004, True), (1, 2): (-0.068, 0.001, True)}
    found = _solved(3, pairs)
    # o1 and o2 from three equations, weights 1/sigma^2: brute force over a fine grid
    grid = np.arange(-0.1, 0.1, 0.0001)
    o1, o2 = np.meshgrid(grid, grid, indexing="ij")
    cost = ((o1 - 0.02) / 0.001) ** 2 + ((o2 + 0.05) / 0.004) ** 2 + ((o2 - o1 + 0.068) / 0.001) ** 2
    best = np.unravel_index(np.argmin(cost), cost.shape)
    assert found.seconds[1] == pytest.approx(grid[best[0]], abs=2e-4)
    assert found.seconds[2] == pytest.approx(grid[best[1]], abs=2e-4)
    design = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 1.0]]) / np.array([[0.001], [0.004], [0.001]])
    np.testing.assert_allclose(found.sigma[1:], np.sqrt(np.diag(np.linalg.inv(design.T @ design))))
    assert found.sigma[0] == 0 and found.sigma[2] < 0.004  # better known than from its own pair alone
    chained = _solved(4, {(0, 1): (0.01, 0.001, True), (1, 3): (0.02, 0.001, True), (0, 2): (0.5, 0.2, False)})
    assert chained.seconds[3] == pytest.approx(0.03) and np.isnan(chained.seconds[2])


def test_tracker_sync_finds_the_offsets_of_a_render(late_render):
    """End to end: a render whose cameras run 0.04 s late and 0.025 s early (athletic motion, patterned clothes, the
    room), detected and synced; the offsets written to REC/sync.toml.  The benchmark renders (docs/sync.md) come within
    2 ms; a test allows 8 ms (a quarter frame), since the detector's last bits differ between machines."""
    rec, lines = late_render.rec, late_render.lines
    assert lines[0].startswith("cam0  +0.0000 s  reference") and lines[-1] == f"wrote {rec / 'sync.toml'}"
    written = load_offsets(rec / "sync.toml", ["cam0", "cam1", "cam2"], 3.0)
    assert abs(written["cam1"] - 0.04) < 0.008 and abs(written["cam2"] + 0.025) < 0.008
    assert (late_render.out / "keypoints-full.npz").is_file()


def test_tracker_sync_says_when_the_motion_cannot_decide(tiny_recording, tmp_path, monkeypatch, capsys):
    """A body standing still: one line naming the cameras and the fix, exit 2, no sync.toml (with --refine, also
    what the edges said; a camera the edges decide is written); a bad sync.toml already there is named before
    anything is detected."""
    rec = tmp_path / "rec"
    shutil.copytree(tiny_recording, rec)
    cameras = open_recording(rec).cameras
    still = np.random.default_rng(4).uniform([-0.3, -0.2, 0.3], [0.3, 0.2, 1.7], size=(33, 3))
    pixels = np.stack([np.stack([camera.project(still) for camera in cameras])] * 6)
    found = Keypoints(
        np.arange(6), tuple(c.name for c in cameras), pixels, np.full(pixels.shape[:3], 0.9), np.zeros((6, 2, 33, 3))
    )
    monkeypatch.setattr("tracker.landmarks.detect_recording.detect_recording", lambda *args, **kwargs: (found, True))
    assert main(["sync", str(rec), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not pin down the time offset of cam1" in err[0] and "by hand" in err[0]
    assert not (rec / "sync.toml").exists()
    edges = [np.array([0.0, -0.07]), np.array([0.0, 0.015]), np.array([True, False])]  # the edges: no rise either
    monkeypatch.setattr("tracker.apps.sync.refine_offsets", lambda *args, **kwargs: Refined(*edges))
    assert main(["sync", str(rec), "--refine", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the edges and the landmarks' motion does not pin down" in err[0]
    assert "its edges: -0.070 +- 0.015 s" in err[0] and not (rec / "sync.toml").exists()
    edges[2] = np.array([True, True])  # the edges decide what the landmarks did not
    assert main(["sync", str(rec), "--refine", "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert "cam1  -0.0700 s  +-0.0150  by the edges (landmarks undecided)" in capsys.readouterr().out
    assert load_offsets(rec / "sync.toml", ["cam0", "cam1"], 1.0)["cam1"] == -0.07
    assert main(["sync", str(rec), "--model", "m.toml", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "--model is for the tracks of --refine; add --refine" in capsys.readouterr().err
    (rec / "sync.toml").write_text("[offsets]\ncam1 = 'late'\n")
    assert main(["sync", str(rec), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "the offset of cam1 is not a number" in capsys.readouterr().err


@pytest.mark.parametrize(
    "case",
    [
        "--cameras cam0",
        "one camera's video",
        "--cameras cam0,cam1 of three",
        "the video of one of three missing",
        "--init of another frame",
    ],
)
def test_tracker_sync_refuses_before_any_detection(case, tiny_recording, tmp_path, monkeypatch, capsys):
    """Fewer than two cameras have no offset between them, and a run that would drop an offset of sync.toml loses
    it, and the tracks of --refine start at frame 0: one line naming the folder or file and the fix, exit 2, before
    any detection, the user's files as they were and nothing written."""
    rec = tmp_path / "rec"
    shutil.copytree(tiny_recording, rec)
    lines = []
    if case == "--cameras cam0":
        extra = ["--cameras", "cam0"]
        lines.append(
            f"{rec}: --cameras picks one camera (cam0), but tracker sync times cameras against one another; "
            "pick two or more"
        )
    elif case == "one camera's video":
        extra = []
        shutil.move(rec / "cam1.avi", tmp_path / "cam1.avi")
        lines.append(
            f"tracker: warning: {rec}: camera cam1 has no video, leaving cam0 of calibration.toml; add "
            "<name>.mp4|.avi|.mkv or a folder <name>/ of numbered images, or pick the cameras with --cameras to say so"
        )
        lines.append(
            f"{rec}: only camera cam0 has a video, but tracker sync times cameras against one another; add "
            "the other cameras' videos"
        )
    elif case == "--init of another frame":
        (rec / "init.toml").write_text((rec / "init.toml").read_text().replace("frame = 0", "frame = 7"))
        extra = ["--refine", "--init", str(rec / "init.toml")]
        lines.append(
            f"{rec / 'init.toml'}: is the pose at frame 7, but the tracks of --refine start at frame 0; pass --init "
            "with the pose at frame 0, or leave --init out to find the first pose by itself"
        )
    else:  # a third camera, whose offset sync.toml holds, left out by --cameras or without its video
        cameras = load_calibration(rec / "calibration.toml")
        save_calibration([*cameras, dataclasses.replace(cameras[1], name="cam2")], rec / "calibration.toml")
        (rec / "sync.toml").write_text("[offsets]\ncam2 = 0.03\n")
        if case == "--cameras cam0,cam1 of three":
            shutil.copyfile(rec / "cam1.avi", rec / "cam2.avi")
            extra, why = ["--cameras", "cam0,cam1"], "which --cameras leaves out"
        else:
            extra, why = [], "whose video is missing"
            lines.append(
                f"tracker: warning: {rec}: camera cam2 has no video, leaving cam0, cam1 of calibration.toml; add "
                "<name>.mp4|.avi|.mkv or a folder <name>/ of numbered images, or pick the cameras with --cameras to "
                "say so"
            )
        lines.append(
            f"{rec / 'sync.toml'}: also holds the offset of cam2, {why} and this run would drop; sync every camera, "
            "or move the file away to start afresh"
        )
    lines[-1] = f"tracker: error: {lines[-1]}"

    def detect(*args, **kwargs):
        raise AssertionError("detected")

    monkeypatch.setattr("tracker.landmarks.detect_recording.detect_recording", detect)
    before = file_hashes(rec)
    assert main(["sync", str(rec), *extra, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert capsys.readouterr().err.splitlines() == lines
    assert file_hashes(rec) == before and not (tmp_path / "out").exists()
