"""tracker calibrate: real data against OpenCV, caliscope and Qualisys; synthetic rigs; error messages.

The calibration files (caliscope's camera_array.toml and charuco.toml, the Pose2Sim rig's
calibration.toml and Qualisys export Calib.qca.txt) are committed in tests/data; the photos and videos
are not, and the tests that calibrate from them skip without ../shared/data.

Real data (../shared/data, see its README):
* opencv-stereo-chessboard: OpenCV's left/right 9x6 photos. Intrinsics against OpenCV's
  left_intrinsics.yml; the stereo pose against cv2.stereoCalibrate run the way OpenCV's
  stereo_calib sample runs it (stereo_calib.xml holds only the image list, no result).
* caliscope-4cam: 4 real cameras, an inverted ChArUco board; one camera sees the board's
  mirrored back. Camera poses against caliscope's camera_array.toml, with caliscope's
  intrinsics fixed (they came from intrinsic recordings that are not in the data).
* pose2sim-intrinsics: 6-7 photos of a 4x7 chessboard per camera; intrinsics against the
  rig's Qualisys export Calib.qca.txt and the converted pose2sim-balancing/calibration.toml.
"""

from __future__ import annotations

import re
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import SHARED_DATA, TEST_DATA, needs_shared

from tracker.calibrate.board import Detection, parse_board
from tracker.calibrate.extrinsics import (
    calibrate_rig,
    chordal_mean,
)
from tracker.camera import Camera, load_calibration, look_at_camera, save_calibration
from tracker.cli import build_parser
from tracker.errors import TrackerInputError
from tracker.geometry.se3 import from_rotation, inverse, rotation_angle

OPENCV = SHARED_DATA / "opencv-stereo-chessboard"
CALISCOPE = SHARED_DATA / "caliscope-4cam"  # its videos and corners; camera_array.toml, charuco.toml committed
POSE2SIM = SHARED_DATA / "pose2sim-intrinsics"  # its photos; Calib.qca.txt committed
CALISCOPE_FILES = TEST_DATA / "caliscope"
POSE2SIM_FILES = TEST_DATA / "pose2sim"  # Calib.qca.txt and pose2sim-balancing's calibration.toml


def run_cli(argv: list[str]) -> int:
    args = build_parser().parse_args(["calibrate", *argv])
    return args.run(args)


def _relative(cameras: list[Camera], base: int, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and centre of camera ``index`` in the frame of camera ``base``."""
    R = cameras[index].rotation @ cameras[base].rotation.T
    t = cameras[index].translation - R @ cameras[base].translation
    return R, -R.T @ t


def _ray_error(ours: Camera, theirs: Camera, reach: float = 1.0, step: int = 20) -> float:
    """Largest pixel distance between where the two cameras' intrinsics send the same ray, over the
    pixels within ``reach`` half diagonals of the image centre."""
    w, h = ours.size
    u, v = np.meshgrid(np.arange(0, w, step), np.arange(0, h, step))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1).astype(float)
    half = np.array([w, h]) / 2
    pixels = pixels[np.linalg.norm(pixels - half, axis=1) <= reach * np.linalg.norm(half)]
    return float(np.linalg.norm(theirs.distort_normalized(ours.undistort_pixels(pixels)) - pixels, axis=1).max())


# ------------------------------------------------------------------------------------------------ #
# OpenCV stereo set


def _opencv_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "stereo"
    for side in ("left", "right"):
        (folder / side).mkdir(parents=True)
        for photo in sorted(OPENCV.glob(f"{side}*.jpg")):
            (folder / side / photo.name).symlink_to(photo)
    return folder


def _opencv_reference_stereo(square: float):
    """OpenCV's own stereo calibration of these photos: the stereo_calib sample's corner search, each
    camera's cv2.calibrateCamera, then cv2.stereoCalibrate refining everything (5-coefficient model).
    (The sample's own flags, one focal length for both cameras and a rational model without
    tangential terms, fit these photos worse: RMS 0.60 px, and 1 degree from both fits here.)"""
    objects, left, right = [], [], []
    board = np.zeros((54, 3), np.float32)
    board[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * square
    for index in range(1, 15):
        pair = [OPENCV / f"{side}{index:02d}.jpg" for side in ("left", "right")]
        if not all(path.exists() for path in pair):
            continue
        found = []
        for path in pair:
            grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            ok, corners = cv2.findChessboardCorners(
                grey, (9, 6), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
            )
            if ok:
                corners = cv2.cornerSubPix(
                    grey, corners, (11, 11), (-1, -1), (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
                )
            found.append(corners if ok else None)
        if all(c is not None for c in found):
            objects.append(board)
            left.append(found[0])
            right.append(found[1])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-8)
    _, K1, d1, _, _ = cv2.calibrateCamera(objects, left, (640, 480), None, None, criteria=criteria)
    _, K2, d2, _, _ = cv2.calibrateCamera(objects, right, (640, 480), None, None, criteria=criteria)
    rms, *_, R, T, _, _ = cv2.stereoCalibrate(
        objects, left, right, K1, d1, K2, d2, (640, 480), flags=cv2.CALIB_USE_INTRINSIC_GUESS, criteria=criteria
    )
    return R, T.ravel(), rms


@needs_shared("opencv-stereo-chessboard")
def test_opencv_stereo_against_opencv(tmp_path, capsys):
    folder = _opencv_folder(tmp_path)
    out = tmp_path / "calibration.toml"
    assert run_cli([str(folder), "--board", "chessboard:9x6:0.025", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    rms = [float(x) for x in re.findall(r"rig RMS ([\d.]+) px", printed)]
    assert len(rms) == 2 and max(rms) < 0.3  # OpenCV's own left fit: 0.39 px including one 1.18 px view
    left, right = load_calibration(out)
    assert (left.name, right.name) == ("left", "right")

    # left intrinsics against left_intrinsics.yml (fitted by OpenCV with fx = fy forced):
    # measured fx 533.2 fy 533.3 vs 535.9 (-0.5 %), cx 342.2 vs 342.3, cy 234.0 vs 235.6;
    # where the board was seen (within 0.7 half diagonals of the centre) the two models send a ray
    # at most 3.5 px apart (mostly the 0.5 % in f); in the unobserved image corners their k3
    # (0.11 vs 0.24) extrapolate differently, up to 16 px.
    stored = cv2.FileStorage(str(OPENCV / "left_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    K_cv = stored.getNode("camera_matrix").mat()
    d_cv = stored.getNode("distortion_coefficients").mat().ravel()
    stored.release()
    assert np.allclose(left.matrix[[0, 1], [0, 1]], K_cv[0, 0], rtol=0.01)
    assert np.allclose(left.matrix[:2, 2], K_cv[:2, 2], atol=3.0)
    reference = Camera("left", (640, 480), K_cv, d_cv, np.eye(3), np.zeros(3))
    assert _ray_error(left, reference, reach=0.7) < 4.0

    # the stereo pose against OpenCV's: measured baseline 83.18 vs 83.45 mm (-0.3 %; 3.33 squares),
    # directions 0.18 degrees apart, rotations 0.16 degrees (fed our corners and intrinsics,
    # cv2.stereoCalibrate with fixed intrinsics and this bundle adjustment agree to 1e-6)
    R_cv, T_cv, _ = _opencv_reference_stereo(0.025)
    T = right.translation - right.rotation @ left.rotation.T @ left.translation
    R = right.rotation @ left.rotation.T
    assert abs(np.linalg.norm(T) - np.linalg.norm(T_cv)) < 0.01 * np.linalg.norm(T_cv)
    direction = np.degrees(np.arccos(np.dot(T, T_cv) / np.linalg.norm(T) / np.linalg.norm(T_cv)))
    assert direction < 0.4
    assert np.degrees(rotation_angle(R.T @ R_cv)) < 0.3


# ------------------------------------------------------------------------------------------------ #
# caliscope 4-camera ChArUco


def _caliscope_cameras() -> list[Camera]:
    document = tomllib.loads((CALISCOPE_FILES / "camera_array.toml").read_text())
    return [
        Camera(
            f"cam_{key}", table["size"], table["matrix"], table["distortions"], table["rotation"], table["translation"]
        )
        for key, table in sorted(document["cameras"].items())
    ]


def test_caliscope_camera_array_loads_and_round_trips(tmp_path):
    """caliscope's camera_array.toml as four 1280x720 cameras; its world is camera 1's frame (measured:
    cam_1 3.3 mm and 0.24 degrees from the origin, the others 1.2-1.7 m out); written and read back by
    our calibration file to round-off."""
    cameras = _caliscope_cameras()
    assert [c.name for c in cameras] == ["cam_0", "cam_1", "cam_2", "cam_3"]
    assert all(c.size == (1280, 720) for c in cameras)
    assert np.linalg.norm(cameras[1].center) < 0.004 and np.degrees(rotation_angle(cameras[1].rotation)) < 0.3
    assert all(1.0 < np.linalg.norm(c.center) < 2.0 for c in cameras if c.name != "cam_1")
    save_calibration(cameras, tmp_path / "caliscope.toml")
    for ours, theirs in zip(load_calibration(tmp_path / "caliscope.toml"), cameras):
        assert ours.name == theirs.name and ours.size == theirs.size
        for a, b in (
            (ours.matrix, theirs.matrix),
            (ours.distortions, theirs.distortions),
            (ours.rotation, theirs.rotation),
            (ours.translation, theirs.translation),
        ):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


@needs_shared("caliscope-4cam", "extrinsic")
def test_caliscope_rig_against_caliscope(tmp_path, capsys):
    reference = _caliscope_cameras()
    intrinsics = tmp_path / "caliscope_intrinsics.toml"
    save_calibration(reference, intrinsics)
    out = tmp_path / "calibration.toml"
    board = tomllib.loads((CALISCOPE_FILES / "charuco.toml").read_text())
    assert board["inverted"] and board["columns"] == 4 and board["rows"] == 5
    square = board["square_size_override_cm"] / 100
    spec = f"charuco:4x5:{square}:{0.75 * square}:DICT_4X4_1000:inverted"
    assert (
        run_cli([str(CALISCOPE / "extrinsic"), "--board", spec, "--out", str(out), "--fix-intrinsics", str(intrinsics)])
        == 0
    )
    printed = capsys.readouterr().out
    ours = load_calibration(out)
    assert [c.name for c in ours] == [c.name for c in reference]
    assert np.allclose(ours[0].rotation, np.eye(3)) and np.allclose(ours[0].translation, 0.0)
    # bundle adjustment beats the chained start in every camera
    after = [float(x) for x in re.findall(r"rig RMS ([\d.]+) px", printed)]
    before = [float(x) for x in re.findall(r"before adjustment ([\d.]+) px", printed)]
    assert all(a < b for a, b in zip(after, before)) and max(after) < 1.5

    # caliscope's world is (to 3 mm and 0.2 degrees) camera 1's frame: compare every camera's pose
    # relative to camera 1. Measured: cam_0 3.5 mm 0.12 deg, cam_2 4.3 mm 0.15 deg, cam_3 4.1 mm
    # 0.39 deg. Most of that is caliscope's: fed caliscope's own corners (xy.csv) and intrinsics,
    # this bundle adjustment lands as far from camera_array.toml, and the four cameras' frames are
    # up to 20 ms apart (timestamps.csv) while the board moves.
    for index in range(4):
        R_ours, c_ours = _relative(ours, 1, index)
        R_ref, c_ref = _relative(reference, 1, index)
        assert np.linalg.norm(c_ours - c_ref) < 0.02, index
        assert np.degrees(rotation_angle(R_ours.T @ R_ref)) < 1.0, index


# ------------------------------------------------------------------------------------------------ #
# Pose2Sim / Qualisys intrinsics


def _qualisys_cameras(size) -> dict[str, Camera]:
    root = ET.parse(POSE2SIM_FILES / "Calib.qca.txt").getroot()
    cameras = {}
    for element in root.iter("camera"):
        i = {key: float(value) for key, value in element.find("intrinsic").attrib.items()}
        K = (
            np.array([[i["focalLengthU"], 0, i["centerPointU"]], [0, i["focalLengthV"], i["centerPointV"]], [0, 0, 64]])
            / 64
        )
        d = [
            i["radialDistortion1"],
            i["radialDistortion2"],
            i["tangentalDistortion1"],
            i["tangentalDistortion2"],
            i["radialDistortion3"],
        ]
        cameras[element.get("serial")] = Camera(element.get("serial"), size, K, d, np.eye(3), np.zeros(3))
    return cameras


def test_pose2sim_calibration_is_the_qualisys_export_converted():
    """pose2sim-balancing's calibration.toml against the rig's Qualisys export: focal lengths and
    principal points are Qualisys's 1/64 px values divided by 64, the distortions too (measured
    exactly: k1 -0.046 in Calib.qca.txt, -7.2e-4 in calibration.toml), and the camera centres are
    Qualisys's positions in mm as metres (measured to 2e-15 m)."""
    balancing = {c.name: c for c in load_calibration(POSE2SIM_FILES / "calibration.toml")}
    assert list(balancing) == ["cam01", "cam02", "cam03", "cam04"]
    qualisys = _qualisys_cameras((1088, 1920))
    root = ET.parse(POSE2SIM_FILES / "Calib.qca.txt").getroot()
    for element in root.iter("camera"):
        name = element.get("serial")
        ours, q = balancing[name], qualisys[name]
        assert ours.size == (1088, 1920)
        np.testing.assert_allclose(ours.matrix, q.matrix, rtol=1e-12)
        np.testing.assert_allclose(
            np.asarray(ours.distortions)[:4], np.asarray(q.distortions)[:4] / 64, rtol=1e-9, atol=1e-15
        )
        position = [float(element.find("transform").get(axis)) / 1000.0 for axis in "xyz"]
        np.testing.assert_allclose(ours.center, position, rtol=0, atol=1e-9)
    assert all(np.all(np.abs(c.distortions[:2]) < 0.003) for c in balancing.values())


@needs_shared("pose2sim-intrinsics")
def test_pose2sim_intrinsics_against_qualisys(tmp_path):
    folder = tmp_path / "p2s"
    folder.mkdir()
    for source in sorted(POSE2SIM.glob("int_cam*_img")):
        (folder / source.name[4:9]).symlink_to(source)
    out = tmp_path / "calibration.toml"
    assert run_cli([str(folder), "--board", "chessboard:4x7:0.1", "--out", str(out), "--intrinsics-only"]) == 0
    ours = load_calibration(out)
    qualisys = _qualisys_cameras(ours[0].size)
    balancing = {c.name: c for c in load_calibration(POSE2SIM_FILES / "calibration.toml")}
    assert [c.name for c in ours] == ["cam01", "cam02", "cam03", "cam04"]
    k = []
    for camera in ours:
        q = qualisys[camera.name]
        # focal lengths: measured -0.65, +0.18, -0.30, -0.07 %; 6 views of a small board
        assert np.allclose(camera.matrix[[0, 1], [0, 1]], q.matrix[[0, 1], [0, 1]], rtol=0.01)
        assert np.allclose(balancing[camera.name].matrix[[0, 1], [0, 1]], q.matrix[[0, 1], [0, 1]], rtol=1e-6)
        # principal points: measured (+31, -13), (+21, -24), (+43, -27), (+17, -30) px, the same sign in
        # every camera (a different sensor origin in Qualisys? six views leave ~10 px of noise)
        assert np.all(np.abs(camera.matrix[:2, 2] - q.matrix[:2, 2]) < 50)
        k.append(camera.distortions[:2] - q.distortions[:2])
    # Qualisys's k1, k2 are OpenCV's normalised-coordinate coefficients: mean difference over the
    # four cameras measured k1 +0.0014, k2 -0.019 (calibration.toml holds them divided by 64)
    mean = np.mean(k, axis=0)
    assert abs(mean[0]) < 0.01 and abs(mean[1]) < 0.04
    assert all(np.all(np.abs(c.distortions[:2]) < 0.003) for c in balancing.values())


# ------------------------------------------------------------------------------------------------ #
# synthetic rigs

SQUARE = 0.04


def _rig() -> list[Camera]:
    """Three 640x480 cameras above a board at the origin, one mounted upside down, one on its side."""
    distortions = (-0.18, 0.06, 0.0005, -0.0004, 0.0)
    return [
        look_at_camera("a", (0.30, -0.25, 0.75), (0, 0, 0), focal=620.0, distortions=distortions, up=(0, 1, 0)),
        look_at_camera("b", (-0.35, -0.15, 0.70), (0, 0, 0), focal=600.0, distortions=distortions, up=(0, -1, 0)),
        look_at_camera("c", (0.05, 0.35, 0.72), (0, 0, 0), focal=640.0, distortions=distortions, up=(1, 0, 0)),
    ]


def _board_poses(count: int, rig: list[Camera], seed: int = 0) -> list[np.ndarray]:
    """world_from_board poses of a 9x6 board near the origin, face up, fully in view of every camera."""
    rng = np.random.default_rng(seed)
    corners = parse_board(f"chessboard:9x6:{SQUARE}").object_points
    centre = corners.mean(axis=0)
    face_up = np.diag([1.0, -1.0, -1.0])
    poses = []
    while len(poses) < count:
        tilt = cv2.Rodrigues(rng.uniform(-0.45, 0.45, 3) * [1, 1, 2])[0]
        R = tilt @ face_up
        t = rng.uniform([-0.08, -0.08, -0.05], [0.08, 0.08, 0.15]) - R @ centre
        world = corners @ R.T + t
        ok = True
        for camera in rig:
            pixels = camera.project(world)
            depth = world @ camera.rotation[2] + camera.translation[2]
            inside = (pixels > 25).all() and (pixels < np.array(camera.size) - 25).all()
            facing = (R[:, 2] @ (world[0] - camera.center)) > 0  # board z points away from the camera
            ok &= bool(inside and facing and (depth > 0).all())
        if ok:
            poses.append(from_rotation(R, t))
    return poses


_RAYS: dict[tuple, np.ndarray] = {}


def _rays(camera: Camera) -> np.ndarray:
    """Viewing rays (x_n, y_n, 1) of the camera's 2x supersampled pixel grid (cached)."""
    key = (camera.size, camera.matrix.tobytes(), camera.distortions.tobytes())
    if key not in _RAYS:
        w, h = camera.size
        u, v = np.meshgrid((np.arange(2 * w) + 0.5) / 2 - 0.5, (np.arange(2 * h) + 0.5) / 2 - 0.5)
        pixels = np.stack([u.ravel(), v.ravel()], 1).astype(np.float32).reshape(-1, 1, 2)
        normalised = cv2.undistortPoints(pixels, camera.matrix, camera.distortions).reshape(-1, 2)
        _RAYS[key] = np.concatenate([normalised, np.ones((len(normalised), 1))], 1)
    return _RAYS[key]


def _render(camera: Camera, world_from_board: np.ndarray, rng) -> np.ndarray:
    """A grey 9x6 chessboard (one square of white margin) on a grey background, 2x supersampled."""
    w, h = camera.size
    rays = _rays(camera)
    camera_from_board = camera.camera_from_world @ world_from_board
    R, t = camera_from_board[:3, :3], camera_from_board[:3, 3]
    # board point X = R^T (lambda d - t) with X_z = 0
    a, b = R.T @ t, rays @ R  # (3,), (n, 3): R^T d
    lam = a[2] / b[:, 2]
    X = lam[:, None] * b - a
    i, j = np.floor(X[:, 0] / SQUARE).astype(int) + 1, np.floor(X[:, 1] / SQUARE).astype(int) + 1
    board = (i >= 0) & (i <= 9) & (j >= 0) & (j <= 6)
    margin = (i >= -1) & (i <= 10) & (j >= -1) & (j <= 7)
    image = np.full(len(rays), 90.0)
    image[margin] = 230.0
    image[board & ((i + j) % 2 == 0)] = 25.0
    image[lam <= 0] = 90.0
    image = cv2.resize(image.reshape(2 * h, 2 * w), (w, h), interpolation=cv2.INTER_AREA)
    image += rng.normal(0, 2.0, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


def _write_views(folder: Path, rig: list[Camera], poses: list[np.ndarray], visible=None, seed: int = 1) -> None:
    rng = np.random.default_rng(seed)
    for c, camera in enumerate(rig):
        (folder / camera.name).mkdir(parents=True)
        for f, pose in enumerate(poses):
            shown = visible is None or f in visible[c]
            image = _render(camera, pose, rng) if shown else np.full((camera.size[1], camera.size[0]), 90, np.uint8)
            cv2.imwrite(str(folder / camera.name / f"{f:06d}.png"), image)


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    folder = tmp_path_factory.mktemp("synthetic")
    rig = _rig()
    poses = _board_poses(14, rig)
    _write_views(folder / "views", rig, poses)
    return folder / "views", rig, poses


def test_synthetic_images_recover_rig_and_board_world(synthetic, tmp_path, capsys):
    folder, rig, poses = synthetic
    out = tmp_path / "calibration.toml"
    assert run_cli([str(folder), "--board", f"chessboard:9x6:{SQUARE}", "--out", str(out), "--world", "board"]) == 0
    ours = load_calibration(out)
    for camera, truth in zip(ours, rig):
        assert np.allclose(camera.matrix[[0, 1], [0, 1]], truth.matrix[[0, 1], [0, 1]], rtol=0.01)
        assert np.allclose(camera.matrix[:2, 2], truth.matrix[:2, 2], atol=4.0)
        assert _ray_error(camera, truth, reach=0.5) < 2.0  # where the board was seen; measured 1.2 px
    # --world board: the board of frame 0 lies face up on the floor, so the truth's world
    # (world_from_board(0) = diag(1, -1, -1) there) is ours moved by world_from_board(0)
    floor = np.diag([1.0, -1.0, -1.0, 1.0])
    truth_from_ours = poses[0] @ inverse(floor)
    for camera, truth in zip(ours, rig):
        centre = truth_from_ours[:3, :3] @ camera.center + truth_from_ours[:3, 3]
        assert np.linalg.norm(centre - truth.center) < 0.004
        R = camera.rotation @ truth_from_ours[:3, :3].T
        assert np.degrees(rotation_angle(R.T @ truth.rotation)) < 0.2
        assert camera.center[2] > 0.5  # above the floor


def _projected_views(rig: list[Camera], poses: list[np.ndarray], noise: float, seed: int = 2):
    rng = np.random.default_rng(seed)
    board = parse_board(f"chessboard:9x6:{SQUARE}")
    views = []
    for camera in rig:
        found = {}
        for f, pose in enumerate(poses):
            pixels = camera.project(board.object_points @ pose[:3, :3].T + pose[:3, 3]) + rng.normal(0, noise, (54, 2))
            found[f] = Detection(np.arange(54), pixels)
        views.append(found)
    return board, views


def test_synthetic_corners_bundle_adjustment_improves_and_recovers():
    rig = _rig()
    poses = _board_poses(20, rig, seed=5)
    board, views = _projected_views(rig, poses, noise=0.3)
    # start from intrinsics 1 % off: the adjustment with --refine-intrinsics must fix them
    start = [
        replace(
            camera,
            matrix=camera.matrix * [[1.01, 1, 1], [1, 0.99, 1], [1, 1, 1]],
            rotation=np.eye(3),
            translation=np.zeros(3),
        )
        for camera in rig
    ]
    fixed = calibrate_rig(board, start, views)
    refined = calibrate_rig(board, start, views, refine_intrinsics=True)
    assert all(a < b for a, b in zip(refined.rms, fixed.rms))
    assert all(abs(rms - 0.3 * np.sqrt(2)) < 0.1 for rms in refined.rms)  # the noise floor: 0.42 px
    assert all(a < b for a, b in zip(refined.rms, refined.initial_rms))
    for camera, truth in zip(refined.cameras, rig):  # measured: f within 0.5 px, c within 2.5 px
        assert np.allclose(camera.matrix[[0, 1], [0, 1]], truth.matrix[[0, 1], [0, 1]], rtol=0.003)
        assert np.allclose(camera.matrix[:2, 2], truth.matrix[:2, 2], atol=3.0)
    exact = [replace(c, rotation=np.eye(3), translation=np.zeros(3)) for c in rig]
    result = calibrate_rig(board, exact, views)
    for index in range(3):
        R_ours, c_ours = _relative(result.cameras, 0, index)
        R_true, c_true = _relative(rig, 0, index)
        assert np.linalg.norm(c_ours - c_true) < 0.001
        assert np.degrees(rotation_angle(R_ours.T @ R_true)) < 0.05


def test_robust_pose_average_rejects_flipped_estimates():
    rng = np.random.default_rng(0)
    truth = cv2.Rodrigues(np.array([0.3, -0.2, 0.1]))[0]
    rotations = [cv2.Rodrigues(rng.normal(0, 0.002, 3))[0] @ truth for _ in range(20)]
    rotations += [cv2.Rodrigues(np.array([0.0, 0.5, 0.0]))[0] @ truth for _ in range(5)]  # IPPE's mirror pose
    translations = [np.array([0.5, 0, 0]) + rng.normal(0, 0.001, 3) for _ in range(20)] + [np.array([0.2, 0.1, 0])] * 5
    from tracker.calibrate.extrinsics import robust_mean_pose

    pose, kept = robust_mean_pose(from_rotation(np.array(rotations), np.array(translations)))
    assert kept == 20
    assert np.degrees(rotation_angle(pose[:3, :3].T @ truth)) < 0.1
    assert np.linalg.norm(pose[:3, 3] - [0.5, 0, 0]) < 0.002
    assert np.allclose(chordal_mean(np.array([truth] * 3)), truth)


# ------------------------------------------------------------------------------------------------ #
# errors


def _calibrate_error(argv: list[str]) -> str:
    with pytest.raises(TrackerInputError) as error:
        run_cli(argv)
    message = str(error.value)
    assert "\n" not in message
    return message


def test_error_board_not_found(tmp_path):
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        for f in range(3):
            cv2.imwrite(str(tmp_path / name / f"{f:06d}.png"), np.full((120, 160), 128, np.uint8))
    message = _calibrate_error([str(tmp_path), "--board", "chessboard:9x6:0.03", "--out", str(tmp_path / "o.toml")])
    assert "9x6 chessboard (inner corners)" in message and "a" in message and "3 frames" in message
    message = _calibrate_error(
        [str(tmp_path), "--board", "charuco:4x5:0.054:0.04:DICT_4X4_1000", "--out", str(tmp_path / "o.toml")]
    )
    assert "4x5 ChArUco board (squares, DICT_4X4_1000)" in message and ":inverted" in message
    assert not (tmp_path / "o.toml").exists()


def test_error_symmetric_chessboard(tmp_path):
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        cv2.imwrite(str(tmp_path / name / "000000.png"), np.zeros((10, 10), np.uint8))
    for size in ("8x6", "6x6", "7x5"):
        message = _calibrate_error(
            [str(tmp_path), "--board", f"chessboard:{size}:0.03", "--out", str(tmp_path / "o.toml")]
        )
        assert size in message and "odd" in message and "ChArUco" in message


def test_error_camera_sharing_no_view(synthetic, tmp_path):
    _, rig, poses = synthetic
    folder = tmp_path / "split"
    _write_views(folder, rig, poses, visible=[set(range(8)), set(range(8)), set(range(8, 14))])
    message = _calibrate_error([str(folder), "--board", f"chessboard:9x6:{SQUARE}", "--out", str(tmp_path / "o.toml")])
    assert "'c' shares no board view" in message and str(folder / "c") in message
    # intrinsics alone need no shared views
    assert (
        run_cli(
            [str(folder), "--board", f"chessboard:9x6:{SQUARE}", "--out", str(tmp_path / "o.toml"), "--intrinsics-only"]
        )
        == 0
    )


def test_error_too_few_views(synthetic, tmp_path):
    _, rig, poses = synthetic
    folder = tmp_path / "few"
    _write_views(folder, rig[:2], poses[:6], visible=[set(range(6)), {0, 1, 2}])
    message = _calibrate_error([str(folder), "--board", f"chessboard:9x6:{SQUARE}", "--out", str(tmp_path / "o.toml")])
    assert "too few board views" in message and "in 3 of 6 frames" in message and "at least 5" in message
    assert str(folder / "b") in message


def test_error_bad_specs_and_options(tmp_path):
    for spec, words in [
        ("chessboard:9x6", "3 fields"),
        ("square:9x6:0.03", "unknown board kind"),
        ("chessboard:9by6:0.03", "COLSxROWS"),
        ("chessboard:9x6:-1", "positive"),
        ("charuco:4x5:0.05:0.06:DICT_4X4_50", "smaller than the square"),
        ("charuco:4x5:0.05:0.04:DICT_9X9_50", "unknown ArUco dictionary"),
        ("charuco:12x12:0.05:0.04:DICT_4X4_50", "needs 72 markers"),
    ]:
        with pytest.raises(TrackerInputError, match=words):
            parse_board(spec)
    assert parse_board("charuco:4x5:0.054:0.040:4X4_1000:inverted").inverted
    assert parse_board("chessboard:9x6:0.03", inverted=True).inverted
    (tmp_path / "a").mkdir()
    cv2.imwrite(str(tmp_path / "a" / "000000.png"), np.zeros((10, 10), np.uint8))
    save_calibration([look_at_camera("other", (0, -3, 1))], tmp_path / "known.toml")
    message = _calibrate_error(
        [
            str(tmp_path),
            "--board",
            "chessboard:9x6:0.03",
            "--out",
            str(tmp_path / "o.toml"),
            "--fix-intrinsics",
            str(tmp_path / "known.toml"),
        ]
    )
    assert "no camera named 'a'" in message
    message = _calibrate_error([str(tmp_path / "nothing"), "--board", "chessboard:9x6:0.03", "--out", "o.toml"])
    assert "not a folder" in message


def test_an_error_in_one_camera_stops_the_board_search_of_the_others(tmp_path):
    """A camera whose frames change size fails at once, and the other camera's search stops with it."""
    import cv2

    from tracker.calibrate.board import parse_board
    from tracker.calibrate.sources import CameraViews, detect_all

    good = tmp_path / "good"
    bad = tmp_path / "bad"
    good.mkdir()
    bad.mkdir()
    for index in range(40):
        cv2.imwrite(str(good / f"{index:06d}.png"), np.full((48, 64), 128, np.uint8))
    for index, size in enumerate(((48, 64), (40, 64))):
        cv2.imwrite(str(bad / f"{index:06d}.png"), np.full(size, 128, np.uint8))
    cameras = [CameraViews("bad", bad), CameraViews("good", good)]
    with pytest.raises(TrackerInputError, match="give every frame of a camera the same size"):
        detect_all(parse_board("chessboard:7x6:0.025"), cameras, workers=1, progress=False)
    assert cameras[1].searched == 0  # never started: the failure cancelled it


def test_face_on_views_warn_that_the_focal_length_is_undetermined():
    """Boards seen square-on at different places and distances fit any focal length: a warning, not a result."""
    from tracker.calibrate.intrinsics import calibrate_intrinsics

    board = parse_board(f"chessboard:9x6:{SQUARE}")
    K = np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 1]])
    rng = np.random.default_rng(3)
    views = {}
    for f in range(8):
        tvec = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.04, 0.04), rng.uniform(0.35, 0.6)])
        pixels, _ = cv2.projectPoints(board.object_points, np.zeros(3), tvec - board.object_points.mean(0), K, None)
        views[f] = Detection(np.arange(54), pixels.reshape(-1, 2) + rng.normal(0, 0.1, (54, 2)))
    with pytest.warns(UserWarning, match="leave the focal length uncertain"):
        calibrate_intrinsics(board, views, (640, 480))


def test_tilted_views_pin_the_focal_length_without_warning(recwarn):
    rig = _rig()
    board, views = _projected_views(rig, _board_poses(12, rig), noise=0.2)
    from tracker.calibrate.intrinsics import calibrate_intrinsics

    found = calibrate_intrinsics(board, views[0], rig[0].size)
    assert abs(found.matrix[0, 0] - rig[0].matrix[0, 0]) < 0.02 * rig[0].matrix[0, 0]
    assert not [w for w in recwarn if "focal length" in str(w.message)]
