"""``keypoints.npz``: the detector's landmarks for frames of a recording, per camera (docs/formats.md).

Arrays, F frames, C cameras, 33 landmarks (:data:`tracker.landmarks.body_landmarks.LANDMARKS`):

    frame (F,) int64                     frame index in the recording
    camera_names (C,) str
    landmark_names (33,) str
    pixels (F, C, 33, 2) float64         image position, pixels (NaN: no person found)
    confidence (F, C, 33) float64        visibility, 0..1 (0: no person found)
    world (F, C, 33, 3) float64          metric world landmarks, metres, origin between the hips
    detector () str                      what made them, the landmark model named in it (a cache of another detector
                                         is not reused: :func:`tracker.landmarks.detector.detector_name`)
    recording () str                     the recording's fingerprint (optional; "" when unknown)
    mask (F, C, 256, 256) uint8          the person's segmentation, probability x 255, over ``square`` (optional)
    square (F, C, 3) float64             centre x, y and side of the mask's square, image pixels (NaN: no mask)

Written atomically and compressed (the masks are mostly zero); loads without pickle.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError
from tracker.landmarks.body_landmarks import LANDMARKS
from tracker.landmarks.crop import CROP
from tracker.npzfile import read_npz


@dataclass(frozen=True)
class Keypoints:
    """The landmarks of frames ``frame`` (F,) in cameras ``camera_names``: pixels (F, C, 33, 2),
    confidence (F, C, 33), world (F, C, 33, 3); what made them (``detector``, "" when not known); and the person's
    masks (F, C, CROP, CROP) uint8 over their squares (F, C, 3), None when not known (a file without them)."""

    frame: np.ndarray
    camera_names: tuple[str, ...]
    pixels: np.ndarray
    confidence: np.ndarray
    world: np.ndarray
    detector: str = ""
    recording: str = ""
    mask: np.ndarray | None = None
    square: np.ndarray | None = None

    def at_frames(self, frames: np.ndarray) -> Keypoints:
        """The same keypoints for the frame numbers ``frames`` only (each must be held), in that order."""
        index = {int(frame): row for row, frame in enumerate(self.frame)}
        return self.rows(np.array([index[int(frame)] for frame in frames], np.int64))

    def rows(self, index) -> Keypoints:
        """The keypoints of the frames at ``index`` (a slice or an array of row numbers) only."""
        return Keypoints(
            self.frame[index],
            self.camera_names,
            self.pixels[index],
            self.confidence[index],
            self.world[index],
            self.detector,
            self.recording,
            None if self.mask is None else self.mask[index],
            None if self.square is None else self.square[index],
        )

    def masks(self) -> tuple[np.ndarray, np.ndarray]:
        """The masks (F, C, CROP, CROP) and their squares (F, C, 3), all zero and NaN when not known."""
        frames, cameras = self.confidence.shape[:2]
        if self.mask is None or self.square is None:
            return np.zeros((frames, cameras, CROP, CROP), np.uint8), np.full((frames, cameras, 3), np.nan)
        return self.mask, self.square


def save_keypoints(path: str | os.PathLike, keypoints: Keypoints) -> None:
    """Write ``keypoints`` to ``path`` (keypoints.npz), atomically."""
    arrays: dict[str, Any] = {  # Any: numpy's stub reads ** keys as savez's allow_pickle
        "frame": np.asarray(keypoints.frame, dtype=np.int64),
        "camera_names": np.array(keypoints.camera_names, dtype=str),
        "landmark_names": np.array(LANDMARKS, dtype=str),
        "pixels": np.asarray(keypoints.pixels, dtype=np.float64),
        "confidence": np.asarray(keypoints.confidence, dtype=np.float64),
        "world": np.asarray(keypoints.world, dtype=np.float64),
        "detector": np.array(keypoints.detector, dtype=str),
        "recording": np.array(keypoints.recording, dtype=str),
    }
    if keypoints.mask is not None and keypoints.square is not None:
        arrays["mask"] = np.asarray(keypoints.mask, dtype=np.uint8)
        arrays["square"] = np.asarray(keypoints.square, dtype=np.float64)
    atomic_write(path, lambda file: np.savez_compressed(file, **arrays))


def load_keypoints(path: str | os.PathLike) -> Keypoints:
    """Read a keypoints.npz, checking its arrays agree with each other; a bad file is a one-line error."""
    path = Path(path)
    arrays = read_npz(path, "a keypoints file", "delete it to detect again")
    missing = {"frame", "camera_names", "landmark_names", "pixels", "confidence", "world", "detector"} - set(arrays)
    if missing:
        raise TrackerInputError(f"{path}: no {', '.join(sorted(missing))}; delete it to detect again")
    frames, cameras = len(arrays["frame"]), len(arrays["camera_names"])
    shapes = {
        "pixels": (frames, cameras, len(LANDMARKS), 2),
        "confidence": (frames, cameras, len(LANDMARKS)),
        "world": (frames, cameras, len(LANDMARKS), 3),
    }
    if "mask" in arrays or "square" in arrays:
        shapes |= {"mask": (frames, cameras, CROP, CROP), "square": (frames, cameras, 3)}
    for key, shape in shapes.items():
        if key not in arrays:
            raise TrackerInputError(f"{path}: a mask without its square, or the reverse; delete it to detect again")
        if arrays[key].shape != shape:
            raise TrackerInputError(
                f"{path}: {key} is {arrays[key].shape}, expected {shape}; delete it to detect again"
            )
    if tuple(arrays["landmark_names"]) != LANDMARKS:
        raise TrackerInputError(f"{path}: its landmarks are not BlazePose's 33; delete it to detect again")
    return Keypoints(
        arrays["frame"],
        tuple(str(name) for name in arrays["camera_names"]),
        arrays["pixels"],
        arrays["confidence"],
        arrays["world"],
        str(arrays["detector"]),
        str(arrays["recording"]) if "recording" in arrays else "",
        arrays.get("mask"),
        arrays.get("square"),
    )
