"""A rig of calibrated cameras as the numba kernels read it: flat arrays of every camera's intrinsics, pose, lens
model and image size."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker.errors import TrackerInputError
from tracker.geometry.lens import COEFFICIENTS, FISHEYE, FISHEYE_LENGTHS, PINHOLE, PINHOLE_LENGTHS


@dataclass(frozen=True)
class Rig:
    """Flat camera arrays: intrinsics ``matrix`` (C,3,3), ``camera_from_world`` (C,4,4), the lens model
    as ``lens`` (C,) int64 kind and ``distortion`` (C,14) coefficients (:mod:`tracker.geometry.lens`),
    ``size`` (C,2) width and height."""

    names: tuple[str, ...]
    matrix: np.ndarray
    camera_from_world: np.ndarray
    lens: np.ndarray
    distortion: np.ndarray
    size: np.ndarray

    @classmethod
    def from_cameras(cls, cameras) -> Rig:
        """The rig of ``cameras``; TrackerInputError for a camera whose lens model the kernels do not know
        (a calibration file cannot give one: :func:`tracker.camera.load_calibration` refuses it)."""
        lens = np.zeros(len(cameras), np.int64)
        distortion = np.zeros((len(cameras), COEFFICIENTS))
        for k, cam in enumerate(cameras):
            d = np.asarray(cam.distortions, dtype=np.float64).ravel()
            lengths = FISHEYE_LENGTHS if cam.fisheye else PINHOLE_LENGTHS
            if len(d) not in lengths:
                raise TrackerInputError(
                    f"camera {cam.name!r}: {len(d)} {'fisheye' if cam.fisheye else 'pinhole'} distortion "
                    f"coefficients are no lens model the tracker knows; give {' or '.join(map(str, lengths))} "
                    "(OpenCV order)"
                )
            lens[k] = FISHEYE if cam.fisheye else PINHOLE
            distortion[k, : len(d)] = d
        return cls(
            names=tuple(c.name for c in cameras),
            matrix=np.array([c.matrix for c in cameras], dtype=np.float64),
            camera_from_world=np.array([c.camera_from_world for c in cameras], dtype=np.float64),
            lens=lens,
            distortion=distortion,
            size=np.array([c.size for c in cameras], dtype=np.int64),
        )
