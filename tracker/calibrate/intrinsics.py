"""Intrinsics of one camera from its board views: camera matrix K and lens distortion.

Zhang's method as OpenCV implements it (``cv2.calibrateCamera``): each view's homography between
the board plane and the image gives two linear constraints on the image of the absolute conic
B = K^-T K^-1, which give a first K; the views' poses follow, and Levenberg-Marquardt then
minimises the reprojection error

    E = sum_views sum_corners || u_vk - K d( pi(R_v X_k + t_v) ) ||^2

over K (fx, fy, cx, cy), the distortion d (k1 k2 p1 p2 k3, OpenCV's Brown-Conrady model, see
tracker/camera.py) and every view's pose (R_v, t_v). The reported RMS is sqrt(E / corners).

Views: at most ``max_views`` enter the fit, chosen by farthest-point sampling over a descriptor
of where the board is and how it is seen (centre, apparent size, foreshortening), so that many
near-identical frames of a video do not crowd out the few informative tilted ones. Views whose
own RMS exceeds max(1 px, 3 x the median) after a first fit (a misread corner, motion blur) are
dropped and the fit is repeated once.

Radial terms are only estimated where the corners reach: with rho the 99th percentile of the
corners' distances from the image centre, in units of the half diagonal, k3 (the r^6 term) is held
at 0 unless there are at least ``FULL_MODEL_VIEWS`` views and rho >= ``K3_REACH`` (0.6), and k2 too when
rho < ``K2_REACH`` (0.4). A polynomial fitted to the middle of the image alone extrapolates wildly towards the
corners (k3 of -8 and +10 on caliscope's small board, whose corners stay within a quarter of the
half diagonal in one camera).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.calibrate.board import Board, Detection

MIN_VIEWS = 5  # fewer board views do not determine K and the distortion
FULL_MODEL_VIEWS = 10  # from this many views on, k3 is estimated too
K3_REACH = 0.6  # k3 is held at 0 where the corners reach less far (rho, see the module docstring)
K2_REACH = 0.4  # and k2 too below this reach
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)


@dataclass(frozen=True)
class Intrinsics:
    matrix: np.ndarray  # 3x3 K
    distortions: np.ndarray  # (5,) k1 k2 p1 p2 k3
    rms: float  # reprojection RMS (px) over the views used
    views: int  # views used


def view_descriptor(pixels: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Where and how a board view sits in the image: centre, apparent size, foreshortening (unitless)."""
    width, height = size
    scale = float(max(width, height))
    centre = pixels.mean(axis=0)
    covariance = np.cov((pixels - centre).T / scale) + 1e-12 * np.eye(2)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    extent = np.sqrt(eigenvalues.sum())
    elongation = 1.0 - np.sqrt(eigenvalues[0] / eigenvalues[1])
    angle = 2.0 * np.arctan2(eigenvectors[1, 1], eigenvectors[0, 1])
    return np.array(
        [
            centre[0] / scale,
            centre[1] / scale,
            2.0 * extent,
            0.5 * elongation * np.cos(angle),
            0.5 * elongation * np.sin(angle),
        ]
    )


def select_views(detections: dict[int, Detection], size: tuple[int, int], limit: int) -> list[int]:
    """Up to ``limit`` frame indices, spread by farthest-point sampling of their view descriptors."""
    frames = sorted(detections)
    if len(frames) <= limit:
        return frames
    features = np.array([view_descriptor(detections[f].pixels, size) for f in frames])
    # start with the largest view, then always add the view farthest from those chosen
    chosen = [int(np.argmax(features[:, 2]))]
    distance = np.linalg.norm(features - features[chosen[0]], axis=1)
    while len(chosen) < limit:
        index = int(np.argmax(distance))
        chosen.append(index)
        distance = np.minimum(distance, np.linalg.norm(features - features[index], axis=1))
    return sorted(frames[i] for i in chosen)


def calibrate_intrinsics(
    board: Board, detections: dict[int, Detection], size: tuple[int, int], *, max_views: int = 40
) -> Intrinsics:
    """K and distortion of one camera from its board detections (at least MIN_VIEWS; the caller checks)."""
    frames = select_views(detections, size, max_views)
    for attempt in range(2):
        rms, matrix, distortions, per_view, tilt = _fit(board, [detections[f] for f in frames], size)
        limit = max(1.0, 3.0 * float(np.median(per_view)))
        keep = [f for f, error in zip(frames, per_view) if error <= limit]
        if attempt == 1 or len(keep) == len(frames) or len(keep) < MIN_VIEWS:
            break
        frames = keep
    _check_tilt(matrix, tilt, size)
    return Intrinsics(matrix, distortions, rms, len(frames))


MIN_TILT_DEG = 10.0  # the largest board tilt below which the views do not pin down the focal length


def _check_tilt(matrix: np.ndarray, tilt: float, size: tuple[int, int]) -> None:
    """Warn when the views leave the focal length undetermined: boards all seen face-on (the largest angle
    between a board's normal and the optical axis, ``tilt`` degrees, under MIN_TILT_DEG) fit any focal
    length at a matching distance, so the reprojection RMS looks perfect while fx is arbitrary."""
    if tilt < MIN_TILT_DEG:
        warnings.warn(
            f"camera of {size[0]}x{size[1]} pixels: the board views leave the focal length uncertain "
            f"(fx = {matrix[0, 0]:.1f} px, boards tilted {tilt:.1f} degrees at most); show the board "
            "tilted by 20-45 degrees in several directions",
            stacklevel=3,
        )


def corner_reach(views: list[Detection], size: tuple[int, int]) -> float:
    """rho: the 99th percentile of the corners' distances from the image centre / the half diagonal."""
    pixels = np.concatenate([view.pixels for view in views])
    half = np.array(size, dtype=np.float64) / 2.0
    return float(np.percentile(np.linalg.norm(pixels - half, axis=1), 99) / np.linalg.norm(half))


def _fit(board: Board, views: list[Detection], size: tuple[int, int]):
    reach = corner_reach(views, size)
    objects = [board.object_points[view.ids].astype(np.float32) for view in views]
    images = [view.pixels.astype(np.float32).reshape(-1, 1, 2) for view in views]
    flags = 0 if len(views) >= FULL_MODEL_VIEWS and reach >= K3_REACH else cv2.CALIB_FIX_K3
    if reach < K2_REACH:
        flags |= cv2.CALIB_FIX_K2
    rms, matrix, distortions, rvecs, tvecs = cv2.calibrateCamera(
        objects, images, tuple(size), None, None, flags=flags, criteria=_CRITERIA
    )
    tilt = max(float(np.degrees(np.arccos(min(1.0, abs(cv2.Rodrigues(rvec)[0][2, 2]))))) for rvec in rvecs)
    per_view = []
    for obj, img, rvec, tvec in zip(objects, images, rvecs, tvecs):
        projected, _ = cv2.projectPoints(obj, rvec, tvec, matrix, distortions)
        per_view.append(float(np.sqrt(np.mean(np.sum((projected - img).reshape(-1, 2) ** 2, axis=1)))))
    return float(rms), matrix, distortions.ravel()[:5].astype(np.float64), per_view, tilt
