"""Calibrated cameras: intrinsics, lens distortion, extrinsics; calibration TOML load and save.

A world point X projects to pixels in three steps (OpenCV conventions):

    X_c = R X + t                                   world -> camera (rotation, translation)
    x_n = (X_c,x / X_c,z,  X_c,y / X_c,z)           ideal normalised coordinates
    u   = K d(x_n)                                  lens distortion d, then the camera matrix K

For the pinhole model d is the Brown-Conrady model with OpenCV's coefficients
(k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 [tx ty]]]]); with r^2 = x^2 + y^2:

    x' = x (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y' = y (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y

plus the thin prism's s1 r^2 + s2 r^4 (x') and s3 r^2 + s4 r^4 (y'), then the tilted sensor's
projection by tx, ty (tracker/geometry/lens.py writes these out for the tracker's kernels).

For ``fisheye`` cameras d is OpenCV's equidistant model (k1..k4), theta = atan(r):
x' = x theta_d / r with theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8).
The pixel centre of the top-left pixel is (0, 0).

The calibration file is the multi-camera TOML of anipose/aniposelib and Pose2Sim
(docs/formats.md): one table per camera, rotations as Rodrigues vectors.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import tomli_w

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError
from tracker.geometry.lens import FISHEYE_LENGTHS, PINHOLE_LENGTHS
from tracker.tomlfile import read_toml

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
_UNIT_TO_METRES = {"m": 1.0, "mm": 1e-3}
_MM_GUESS_DISTANCE = 50.0  # a median camera distance above this many "metres" is surely millimetres
_REQUIRED_KEYS = ("name", "size", "matrix", "distortions", "rotation", "translation")
_ROTATION_TOLERANCE = 1e-5  # largest |R^T R - I| of a 3x3 rotation: rotations written to six decimals pass


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera; arrays are float64 and read-only.

    ``rotation`` R (3x3) and ``translation`` t (3,) map world to camera:
    X_c = R X_w + t. ``size`` is (width, height) in pixels.
    """

    name: str
    size: tuple[int, int]
    matrix: np.ndarray
    distortions: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    fisheye: bool = False

    def __post_init__(self) -> None:
        shapes = {"matrix": (3, 3), "distortions": (-1,), "rotation": (3, 3), "translation": (3,)}
        for field, shape in shapes.items():
            array = np.array(getattr(self, field), dtype=np.float64).reshape(shape)
            array.setflags(write=False)
            object.__setattr__(self, field, array)
        object.__setattr__(self, "size", (int(self.size[0]), int(self.size[1])))
        object.__setattr__(self, "fisheye", bool(self.fisheye))

    @property
    def camera_from_world(self) -> np.ndarray:
        """The extrinsics as a 4x4 transform [[R, t], [0, 1]]: X_camera = camera_from_world @ X_world."""
        transform = np.eye(4)
        transform[:3, :3] = self.rotation
        transform[:3, 3] = self.translation
        return transform

    def with_camera_from_world(self, camera_from_world: np.ndarray) -> Camera:
        """This camera with its extrinsics set from a 4x4 camera_from_world (R its upper left 3x3,
        t its last column's top three)."""
        return replace(self, rotation=camera_from_world[:3, :3], translation=camera_from_world[:3, 3])

    @property
    def center(self) -> np.ndarray:
        """The camera's optical centre in world coordinates, c = -R^T t."""
        return -self.rotation.T @ self.translation

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixels (M, 2) of world points (M, 3), with lens distortion.

        Points behind the camera (X_c,z <= 0) give meaningless pixels; callers
        cull them.
        """
        points_camera = np.asarray(points_world, dtype=np.float64).reshape(-1, 3) @ self.rotation.T + self.translation
        return self.distort_normalized(points_camera[:, :2] / points_camera[:, 2:3])

    def distort_normalized(self, xn: np.ndarray) -> np.ndarray:
        """Pixels u = K d(x_n) of ideal normalised coordinates x_n (M, 2)."""
        xn = _points(xn)
        if len(xn) == 0:
            return np.zeros((0, 2))
        if self.fisheye:
            pixels = cv2.fisheye.distortPoints(xn, self.matrix, self.distortions)
        else:
            # OpenCV drops the skew K[0,1]: project without it, then add s * y_d
            homogeneous = np.concatenate([xn, np.ones((len(xn), 1, 1))], axis=2)
            pixels, _ = cv2.projectPoints(homogeneous, np.zeros(3), np.zeros(3), self._unskewed, self.distortions)
            pixels = pixels.reshape(-1, 2)
            pixels[:, 0] += self.matrix[0, 1] * (pixels[:, 1] - self.matrix[1, 2]) / self.matrix[1, 1]
        return pixels.reshape(-1, 2)

    @property
    def _unskewed(self) -> np.ndarray:
        matrix = self.matrix.copy()
        matrix[0, 1] = 0.0
        return matrix

    def undistort_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Ideal normalised coordinates x_n (M, 2) of pixels (M, 2): the inverse of distort_normalized.

        OpenCV's fixed-point iteration, run to 1e-14 so the round trip is exact
        to well below 1e-6 px for ordinary lenses.
        """
        pixels = _points(pixels)
        if len(pixels) == 0:
            return np.zeros((0, 2))
        if self.fisheye:
            xn = cv2.fisheye.undistortPoints(pixels, self.matrix, self.distortions, criteria=_UNDISTORT_CRITERIA)
        else:
            pixels = pixels.copy()
            pixels[:, 0, 0] -= self.matrix[0, 1] * (pixels[:, 0, 1] - self.matrix[1, 2]) / self.matrix[1, 1]
            xn = cv2.undistortPoints(pixels, self._unskewed, self.distortions, criteria=_UNDISTORT_CRITERIA)
        return xn.reshape(-1, 2)


def look_at_camera(
    name: str,
    eye,
    target=(0.0, 0.0, 1.0),
    *,
    size=(640, 480),
    focal: float = 560.0,
    distortions=(0.0, 0.0, 0.0, 0.0),
    up=(0.0, 0.0, 1.0),
) -> Camera:
    """A camera at ``eye`` looking at ``target`` with ``up`` pointing up in the image.

    OpenCV axes (x right, y down, z forward); fx = fy = ``focal``; principal point
    at the image centre ((w - 1)/2, (h - 1)/2 with pixel centres at integers).
    """
    eye = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look_at_camera: the viewing direction is parallel to `up`; choose another up vector")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward])
    w, h = int(size[0]), int(size[1])
    matrix = np.array([[focal, 0.0, (w - 1) / 2.0], [0.0, focal, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return Camera(name, (w, h), matrix, np.asarray(distortions, dtype=np.float64), rotation, -rotation @ eye)


def _points(points: np.ndarray) -> np.ndarray:
    """(M, 2) points as the contiguous float64 (M, 1, 2) array OpenCV wants."""
    return np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 1, 2))


def load_calibration(path: str | os.PathLike) -> list[Camera]:
    """Cameras of an anipose/Pose2Sim calibration TOML, in file order, translations in metres.

    ``[metadata] units = "mm"`` converts translations to metres. Without a units
    key, a rig whose median camera distance |t| exceeds 50 is taken to be in
    millimetres (with a warning). Each camera must be one: finite numbers, positive
    focal lengths, the principal point inside the image, a rotation (a Rodrigues
    vector, or a 3x3 matrix with orthonormal rows and determinant +1). Every
    problem raises TrackerInputError naming the file, the camera table and the fix.
    """
    path = Path(path)
    document = read_toml(path, "calibration", "give the path of a calibration.toml")

    scale = _units_scale(path, document.get("metadata", {}))
    tables = {key: value for key, value in document.items() if key != "metadata" and isinstance(value, dict)}
    if not tables:
        raise TrackerInputError(
            f"{path}: no camera tables; add one [cam_N] table per camera with keys {', '.join(_REQUIRED_KEYS)}"
        )
    cameras = [_parse_camera(path, table, values) for table, values in tables.items()]

    seen: dict[str, str] = {}
    for table, camera in zip(tables, cameras):
        if camera.name in seen:
            raise TrackerInputError(
                f"{path}: [{table}] camera name {camera.name!r} is also used by [{seen[camera.name]}]; "
                "give every camera a distinct name"
            )
        seen[camera.name] = table

    if scale is None:
        scale = 1.0
        median_distance = float(np.median([np.linalg.norm(camera.translation) for camera in cameras]))
        if median_distance > _MM_GUESS_DISTANCE:
            scale = _UNIT_TO_METRES["mm"]
            warnings.warn(
                f"{path}: median camera distance {median_distance:g} is implausible in metres, "
                'reading translations as millimetres; add [metadata] units = "mm" (or "m") to say so',
                stacklevel=2,
            )
    if scale == 1.0:
        return cameras
    return [replace(camera, translation=camera.translation * scale) for camera in cameras]


def _units_scale(path: Path, metadata: Any) -> float | None:
    """Metres per unit from ``[metadata] units``; None when the file does not say."""
    if not isinstance(metadata, dict):
        raise TrackerInputError(f"{path}: 'metadata' must be a table; write it as [metadata]")
    units = metadata.get("units")
    if units is None:
        return None
    if units not in _UNIT_TO_METRES:
        raise TrackerInputError(
            f"{path}: [metadata] units = {units!r} is not supported; use {' or '.join(map(repr, _UNIT_TO_METRES))}"
        )
    return _UNIT_TO_METRES[units]


def _parse_camera(path: Path, table: str, values: dict[str, Any]) -> Camera:
    """One camera table -> Camera, validating every key."""

    def fail(problem: str, fix: str) -> TrackerInputError:
        return TrackerInputError(f"{path}: [{table}] {problem}; {fix}")

    def array(key: str, shapes: tuple[tuple[int, ...], ...], fix: str) -> np.ndarray:
        try:
            value = np.array(values[key], dtype=np.float64)
        except (ValueError, TypeError):
            raise fail(f"'{key}' is not an array of numbers", fix) from None
        if value.shape not in shapes:
            raise fail(f"'{key}' has shape {value.shape}", fix)
        if not np.all(np.isfinite(value)):
            raise fail(f"'{key}' holds NaN or infinity", fix)
        return value

    missing = [key for key in _REQUIRED_KEYS if key not in values]
    if missing:
        raise fail(
            f"missing key {', '.join(map(repr, missing))}", f"every camera table needs {', '.join(_REQUIRED_KEYS)}"
        )
    name = values["name"]
    if not isinstance(name, str) or not name.strip():
        raise fail(f"'name' = {name!r} is not a non-empty string", 'write name = "cam0"')

    size = array("size", ((2,),), "write size = [width, height] in pixels")
    if np.any(size <= 0) or np.any(size != np.round(size)):
        raise fail(
            f"'size' = {size.tolist()} is not two positive whole numbers", "write size = [width, height] in pixels"
        )

    matrix = array("matrix", ((3, 3),), "write matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
    if not np.allclose(matrix[2], [0.0, 0.0, 1.0]) or np.linalg.cond(matrix) > 1e12:
        raise fail(
            "'matrix' is not an invertible camera matrix with last row [0, 0, 1]",
            "write matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
        )
    if matrix[0, 0] <= 0 or matrix[1, 1] <= 0:
        raise fail(
            f"'matrix' has focal lengths fx = {matrix[0, 0]:g}, fy = {matrix[1, 1]:g}, not both positive",
            "use the calibration in OpenCV's convention (x right, y down, z forward: fx, fy > 0 in pixels)",
        )
    width, height = size
    if not (-0.5 <= matrix[0, 2] <= width - 0.5 and -0.5 <= matrix[1, 2] <= height - 0.5):
        raise fail(
            f"'matrix' puts the principal point (cx, cy) = ({matrix[0, 2]:g}, {matrix[1, 2]:g}) outside the "
            f"{width:g}x{height:g} image",
            "check that matrix and size belong to the same camera and image size (cx, cy in pixels, near the centre)",
        )

    fisheye = values.get("fisheye", False)
    if not isinstance(fisheye, bool):
        raise fail(f"'fisheye' = {fisheye!r} is not a boolean", "write fisheye = true or false")
    lengths = FISHEYE_LENGTHS if fisheye else PINHOLE_LENGTHS
    distortions = array(
        "distortions",
        tuple((n,) for n in lengths),
        f"write {'fisheye ' if fisheye else ''}distortions as {' or '.join(map(str, lengths))} numbers "
        f"({'k1 k2 k3 k4' if fisheye else 'k1 k2 p1 p2 [k3 ...]'}, OpenCV order)",
    )

    rotation = array("rotation", ((3,), (3, 3)), "write rotation as a Rodrigues vector [rx, ry, rz] (world -> camera)")
    if rotation.shape == (3,):
        rotation = cv2.Rodrigues(rotation)[0]
    else:
        off = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
        if off > _ROTATION_TOLERANCE or np.linalg.det(rotation) < 0:
            problem = f"R^T R is {off:.2g} off the identity" if off > _ROTATION_TOLERANCE else "its determinant is -1"
            raise fail(
                f"'rotation' is a 3x3 matrix but not a rotation ({problem})",
                "write rotation as a Rodrigues vector [rx, ry, rz], or a 3x3 matrix with orthonormal rows and "
                "determinant +1 (world -> camera)",
            )

    translation = array("translation", ((3,),), "write translation = [tx, ty, tz] (world -> camera)")
    return Camera(name, (int(size[0]), int(size[1])), matrix, distortions, rotation, translation, fisheye)


def save_calibration(cameras: list[Camera], path: str | os.PathLike) -> None:
    """Write cameras as an anipose/Pose2Sim calibration TOML (metres), atomically.

    Tables are named cam_0, cam_1, ... (zero-padded when there are more than ten,
    so anipose, which sorts table names, keeps the order).
    """
    digits = len(str(max(len(cameras) - 1, 0)))
    document: dict[str, Any] = {}
    for index, camera in enumerate(cameras):
        document[f"cam_{index:0{digits}d}"] = {
            "name": camera.name,
            "size": list(camera.size),
            "matrix": camera.matrix.tolist(),
            "distortions": camera.distortions.tolist(),
            "rotation": cv2.Rodrigues(camera.rotation)[0].ravel().tolist(),
            "translation": camera.translation.tolist(),
            "fisheye": camera.fisheye,
        }
    document["metadata"] = {"units": "m"}
    atomic_write(path, lambda file: tomli_w.dump(document, file))
