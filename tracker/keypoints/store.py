"""``keypoints.npz``: the detector's landmarks for frames of a recording, per camera (docs/formats.md).

Arrays, F frames, C cameras, 33 landmarks (:data:`tracker.keypoints.detector.LANDMARKS`):

    frame (F,) int64                     frame index in the recording
    camera_names (C,) str
    landmark_names (33,) str
    pixels (F, C, 33, 2) float64         image position, pixels (NaN: no person found)
    confidence (F, C, 33) float64        visibility, 0..1 (0: no person found)
    world (F, C, 33, 3) float64          metric world landmarks, metres, origin between the hips
    detector () str                      what made them (a cache of another detector is not reused)
    recording () str                     the recording's fingerprint (optional; "" when unknown)

Written atomically; loads without pickle.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError
from tracker.keypoints.detector import DETECTOR
from tracker.tracking.keypoint_cue import LANDMARKS


@dataclass(frozen=True)
class Keypoints:
    """The landmarks of frames ``frame`` (F,) in cameras ``camera_names``: pixels (F, C, 33, 2),
    confidence (F, C, 33), world (F, C, 33, 3)."""

    frame: np.ndarray
    camera_names: tuple[str, ...]
    pixels: np.ndarray
    confidence: np.ndarray
    world: np.ndarray
    detector: str = DETECTOR
    recording: str = ""

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
        )


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
    atomic_write(path, lambda file: np.savez(file, **arrays))


def load_keypoints(path: str | os.PathLike) -> Keypoints:
    """Read a keypoints.npz, checking its arrays agree with each other; a bad file is a one-line error."""
    path = Path(path)
    if not path.is_file():
        raise TrackerInputError(f"{path}: keypoints file not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as error:
        raise TrackerInputError(f"{path}: not a readable keypoints.npz ({error}); delete it to detect again") from None
    missing = {"frame", "camera_names", "landmark_names", "pixels", "confidence", "world", "detector"} - set(arrays)
    if missing:
        raise TrackerInputError(f"{path}: no {', '.join(sorted(missing))}; delete it to detect again")
    frames, cameras = len(arrays["frame"]), len(arrays["camera_names"])
    shapes = {
        "pixels": (frames, cameras, len(LANDMARKS), 2),
        "confidence": (frames, cameras, len(LANDMARKS)),
        "world": (frames, cameras, len(LANDMARKS), 3),
    }
    for key, shape in shapes.items():
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
    )
