"""Camera projection, distortion and calibration TOML load/save."""

from __future__ import annotations

import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
import tomli_w
from conftest import SHARED_DATA, TEST_DATA, needs_shared

from tracker.camera import Camera, load_calibration, look_at_camera, save_calibration
from tracker.errors import TrackerInputError

K = np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])
DISTORTIONS = {
    4: [-0.2, 0.05, 0.001, -0.002],
    5: [-0.25, 0.08, 0.001, -0.0015, -0.01],
    8: [-0.25, 0.08, 0.001, -0.0015, -0.01, 0.02, 0.01, 0.005],
}


def make_camera(name: str = "cam0", distortions=DISTORTIONS[5], fisheye: bool = False, seed: int = 0) -> Camera:
    rng = np.random.default_rng(seed)
    rotation = cv2.Rodrigues(rng.normal(scale=0.3, size=3))[0]
    return Camera(name, (640, 480), K, np.array(distortions), rotation, np.array([0.1, -0.2, 3.0]), fisheye)


def brown(xn: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Pixels of normalised points by the Brown-Conrady formula written out (OpenCV's rational form)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = np.concatenate([d, np.zeros(8 - len(d))])
    x, y = xn[:, 0], xn[:, 1]
    r2 = x * x + y * y
    radial = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]])


@pytest.mark.parametrize("length", sorted(DISTORTIONS))
def test_project_matches_pinhole_brown_formula(length: int) -> None:
    camera = make_camera(distortions=DISTORTIONS[length])
    rng = np.random.default_rng(1)
    points = camera.center + rng.normal(size=(50, 3)) * 0.5 + camera.rotation[2] * 3.0  # in front of the camera
    local = points @ camera.rotation.T + camera.translation
    expected = brown(local[:, :2] / local[:, 2:], camera.distortions)
    np.testing.assert_allclose(camera.project(points), expected, atol=1e-9)


def test_pose_and_center() -> None:
    camera = make_camera()
    np.testing.assert_allclose(camera.camera_from_world @ np.append(camera.center, 1.0), [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(camera.camera_from_world[:3, :3], camera.rotation)
    assert not camera.rotation.flags.writeable
    moved = np.array(camera.camera_from_world)
    moved[:3, 3] += [0.1, 0.2, 0.3]
    other = camera.with_camera_from_world(moved)
    assert np.array_equal(other.camera_from_world, moved) and other.name == camera.name
    assert np.array_equal(other.matrix, camera.matrix) and not other.translation.flags.writeable


@pytest.mark.parametrize("fisheye", [False, True])
def test_undistort_then_distort_round_trip(fisheye: bool) -> None:
    camera = make_camera(distortions=[0.1, -0.02, 0.01, -0.003] if fisheye else DISTORTIONS[5], fisheye=fisheye)
    rng = np.random.default_rng(2)
    pixels = rng.uniform([0, 0], [640, 480], size=(500, 2))
    assert np.abs(camera.distort_normalized(camera.undistort_pixels(pixels)) - pixels).max() < 1e-6
    xn = rng.uniform(-0.5, 0.5, size=(500, 2))
    assert np.abs(camera.undistort_pixels(camera.distort_normalized(xn)) - xn).max() * K[0, 0] < 1e-6


def test_empty_point_sets() -> None:
    camera = make_camera()
    assert camera.project(np.zeros((0, 3))).shape == (0, 2)
    assert camera.undistort_pixels(np.zeros((0, 2))).shape == (0, 2)


def test_toml_round_trip(tmp_path: Path) -> None:
    cameras = [make_camera(f"cam{i}", DISTORTIONS[length], seed=i) for i, length in enumerate((4, 5, 8))]
    cameras.append(make_camera("wide", [0.1, -0.02, 0.01, -0.003], fisheye=True, seed=9))
    path = tmp_path / "out" / "calibration.toml"
    save_calibration(cameras, path)
    loaded = load_calibration(path)
    assert [c.name for c in loaded] == [c.name for c in cameras]
    for before, after in zip(cameras, loaded):
        assert after.size == before.size and after.fisheye == before.fisheye
        for field in ("matrix", "distortions", "rotation", "translation"):
            np.testing.assert_allclose(getattr(after, field), getattr(before, field), atol=1e-12)
    assert [p.name for p in path.parent.iterdir()] == ["calibration.toml"]  # no temporary file left


def table(**changes) -> dict:
    values = {
        "name": "cam0",
        "size": [640.0, 480.0],  # Pose2Sim writes floats
        "matrix": K.tolist(),
        "distortions": [0.0, 0.0, 0.0, 0.0],
        "rotation": [0.0, 0.0, 0.0],
        "translation": [0.0, 0.0, 3.0],
    }
    values.update(changes)
    return {key: value for key, value in values.items() if value is not None}


def write(path: Path, document: dict) -> Path:
    path.write_bytes(tomli_w.dumps(document).encode())
    return path


def test_loads_pose2sim_style_file(tmp_path: Path) -> None:
    path = write(tmp_path / "calib.toml", {"cam_01": table(), "cam_02": table(name="cam1"), "metadata": {"error": 0.3}})
    cameras = load_calibration(path)
    assert [c.name for c in cameras] == ["cam0", "cam1"]
    assert cameras[0].size == (640, 480)
    np.testing.assert_allclose(cameras[0].rotation, np.eye(3))


def test_mm_units_are_converted(tmp_path: Path) -> None:
    path = write(
        tmp_path / "calib.toml", {"cam_0": table(translation=[100.0, 0.0, 3000.0]), "metadata": {"units": "mm"}}
    )
    np.testing.assert_allclose(load_calibration(path)[0].translation, [0.1, 0.0, 3.0])


def test_implausible_metres_are_read_as_mm_with_a_warning(tmp_path: Path) -> None:
    document = {
        "cam_0": table(translation=[0.0, 0.0, 3000.0]),
        "cam_1": table(name="b", translation=[0.0, 0.0, 2500.0]),
    }
    path = write(tmp_path / "calib.toml", document)
    with pytest.warns(UserWarning, match="millimetres"):
        cameras = load_calibration(path)
    np.testing.assert_allclose([c.translation[2] for c in cameras], [3.0, 2.5])


def test_metres_load_without_warning(tmp_path: Path) -> None:
    path = write(tmp_path / "calib.toml", {"cam_0": table()})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_allclose(load_calibration(path)[0].translation, [0.0, 0.0, 3.0])


BAD_TABLES = {
    "missing key": (table(matrix=None), "'matrix'"),
    "matrix not 3x3": (table(matrix=[[1.0, 0.0], [0.0, 1.0]]), "shape"),
    "matrix singular": (table(matrix=[[500.0, 0.0, 320.0], [0.0, 0.0, 240.0], [0.0, 0.0, 1.0]]), "invertible"),
    "nan": (table(translation=[0.0, float("nan"), 3.0]), "NaN"),
    "inf": (table(distortions=[float("inf"), 0.0, 0.0, 0.0]), "NaN or infinity"),
    "size zero": (table(size=[0, 480]), "size"),
    "size fraction": (table(size=[640.5, 480]), "size"),
    "distortion length": (table(distortions=[0.0, 0.0, 0.0]), "distortions"),
    "fisheye distortion length": (table(distortions=[0.0] * 5, fisheye=True), "distortions"),
    "not numbers": (table(rotation=["a", "b", "c"]), "rotation"),
    "rotation matrix not orthonormal": (
        table(rotation=[[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]),
        "'rotation' is a 3x3 matrix but not a rotation (R^T R is 3 off the identity)",
    ),
    "rotation matrix a reflection": (
        table(rotation=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
        "'rotation' is a 3x3 matrix but not a rotation (its determinant is -1)",
    ),
    "negative focal length": (
        table(matrix=[[-500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]),
        "focal lengths fx = -500, fy = 510, not both positive; use the calibration in OpenCV's convention",
    ),
    "negative fy": (table(matrix=[[500.0, 0.0, 320.0], [0.0, -510.0, 240.0], [0.0, 0.0, 1.0]]), "fy = -510"),
    "principal point right of the image": (
        table(matrix=[[500.0, 0.0, 640.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]),
        "principal point (cx, cy) = (640, 240) outside the 640x480 image; check that matrix and size belong",
    ),
    "principal point above the image": (
        table(matrix=[[500.0, 0.0, 320.0], [0.0, 510.0, -0.6], [0.0, 0.0, 1.0]]),
        "(cx, cy) = (320, -0.6) outside",
    ),
    "empty name": (table(name=""), "name"),
}


@pytest.mark.parametrize("case", sorted(BAD_TABLES))
def test_bad_camera_table_names_file_and_table(tmp_path: Path, case: str) -> None:
    bad, expected = BAD_TABLES[case]
    path = write(tmp_path / "rig.toml", {"cam_0": table(name="a"), "cam_bad": bad})
    with pytest.raises(TrackerInputError) as error:
        load_calibration(path)
    message = str(error.value)
    assert "rig.toml" in message and "[cam_bad]" in message and expected in message
    assert "\n" not in message


@pytest.mark.parametrize(
    "case, content, expected",
    [
        ("not toml", b"[cam_0\nname = ", "TOML"),
        ("no cameras", b'[metadata]\nunits = "m"\n', "no camera"),
        ("duplicate names", tomli_w.dumps({"a": table(), "b": table()}).encode(), "distinct"),
        ("bad units", tomli_w.dumps({"a": table(), "metadata": {"units": "inch"}}).encode(), "units"),
        ("binary", bytes(range(256)), "TOML"),
    ],
)
def test_bad_file_names_file(tmp_path: Path, case: str, content: bytes, expected: str) -> None:
    path = tmp_path / "rig.toml"
    path.write_bytes(content)
    with pytest.raises(TrackerInputError, match=expected) as error:
        load_calibration(path)
    assert "rig.toml" in str(error.value)


def test_missing_file_names_file(tmp_path: Path) -> None:
    with pytest.raises(TrackerInputError, match="nowhere.toml"):
        load_calibration(tmp_path / "nowhere.toml")


def test_loads_the_real_pose2sim_rig() -> None:
    """The Pose2Sim demo's calibration (floats for sizes, metres): four portrait cameras about 3-4 m out
    (pose2sim-balancing's calibration.toml, committed in tests/data/pose2sim)."""
    cameras = load_calibration(TEST_DATA / "pose2sim" / "calibration.toml")
    assert [c.name for c in cameras] == ["cam01", "cam02", "cam03", "cam04"]
    assert all(c.size == (1088, 1920) for c in cameras)
    distances = [np.linalg.norm(c.center[:2]) for c in cameras]
    assert all(1.5 < d < 6.0 for d in distances)
    # every camera sees the middle of the lab (about 1 m above the floor at the origin) inside its image
    for camera in cameras:
        u, v = camera.project(np.array([[0.0, 0.0, 1.0]]))[0]
        assert 0 <= u < camera.size[0] and 0 <= v < camera.size[1]


def test_a_camera_at_the_edges_of_what_is_one_loads(tmp_path: Path) -> None:
    """The principal point on the image's outermost pixel centres' half-pixel border, and a 3x3 rotation written to six
    decimals (R^T R off the identity by more than 1e-6), are a camera; the rotation is kept as written."""
    rotation = np.round(cv2.Rodrigues(np.array([0.3, -1.2, 0.7]))[0], 6)
    corner = table(matrix=[[500.0, 0.0, -0.5], [0.0, 510.0, 479.5], [0.0, 0.0, 1.0]], rotation=rotation.tolist())
    (camera,) = load_calibration(write(tmp_path / "rig.toml", {"cam_0": corner}))
    assert camera.matrix[0, 2] == -0.5 and camera.matrix[1, 2] == 479.5
    assert np.array_equal(camera.rotation, rotation) and np.abs(rotation.T @ rotation - np.eye(3)).max() > 1e-6


REPO = Path(__file__).resolve().parents[1]
CALIBRATIONS = [
    *sorted((REPO / "calib").glob("*.toml")),
    REPO / "recordings" / "demo" / "calibration.toml",
    TEST_DATA / "pose2sim" / "calibration.toml",
]


@pytest.mark.parametrize("path", CALIBRATIONS, ids=lambda path: str(path.relative_to(REPO)))
def test_every_calibration_that_comes_with_the_tracker_loads(path: Path) -> None:
    assert len(load_calibration(path)) >= 3


@needs_shared()
def test_every_calibration_of_the_real_data_loads() -> None:
    """../shared/data's calibration.toml files (the Pose2Sim rig; caliscope's camera_array.toml is another format,
    read by tests/test_calibrate.py)."""
    found = sorted(SHARED_DATA.glob("*/calibration.toml"))
    assert found and all(len(load_calibration(path)) == 4 for path in found)


def test_look_at_camera_centres_target():
    cam = look_at_camera(
        "x", (3.0, -2.0, 1.5), (0.1, 0.2, 0.9), size=(640, 480), focal=500.0, distortions=(-0.1, 0.02, 0, 0)
    )
    np.testing.assert_allclose(cam.project(np.array([[0.1, 0.2, 0.9]]))[0], [319.5, 239.5], atol=1e-9)
    up = cam.project(np.array([[0.1, 0.2, 1.2]]))[0]
    assert up[1] < 239.5  # world up is image up
    np.testing.assert_allclose(cam.center, [3.0, -2.0, 1.5], atol=1e-12)
