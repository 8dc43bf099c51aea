"""The detector over frames of a recording, one landmarker per camera, reusing a cache that matches."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError
from tracker.io.recording import Recording, frames
from tracker.keypoints.detector import DETECTOR, Detector
from tracker.keypoints.store import Keypoints, load_keypoints, save_keypoints


def cached(path: Path, recording: Recording, start: int, stop: int) -> Keypoints | None:
    """The keypoints of frames start..stop-1 in ``path`` if it holds them (and maybe more) for these cameras
    from this detector."""
    if not path.is_file():
        return None
    try:
        found = load_keypoints(path)
    except TrackerInputError:
        return None
    names = tuple(camera.name for camera in recording.cameras)
    rows = {int(frame): row for row, frame in enumerate(found.frame)}
    if found.detector != DETECTOR or found.camera_names != names or not all(f in rows for f in range(start, stop)):
        return None
    return found.rows([rows[frame] for frame in range(start, stop)])


def detect_recording(
    recording: Recording,
    start: int = 0,
    stop: int | None = None,
    *,
    cache: str | os.PathLike | None = None,
    progress: Callable[..., Iterable] = lambda iterable, total=None: iterable,
) -> tuple[Keypoints, bool]:
    """The landmarks of frames start..stop-1 in every camera of ``recording``, and whether they came from
    ``cache`` (a keypoints.npz holding these frames, of the same cameras and detector); otherwise they are
    detected and, with ``cache``, written there.  ``progress(iterable, total=)`` wraps the frames (e.g. a tqdm bar)."""
    stop = recording.frame_count if stop is None else stop
    if cache is not None and (reused := cached(Path(cache), recording, start, stop)) is not None:
        return reused, True
    count, cameras = stop - start, len(recording.cameras)
    pixels = np.full((count, cameras, 33, 2), np.nan)
    confidence = np.zeros((count, cameras, 33))
    world = np.full((count, cameras, 33, 3), np.nan)
    with ExitStack() as stack:
        detectors = [Detector() for _ in range(cameras)]
        for detector in detectors:
            stack.callback(detector.close)
        for index, images in progress(frames(recording, start, stop, colour=True), total=count):
            for camera, (detector, image) in enumerate(zip(detectors, images)):
                detection, row = detector(image), index - start
                pixels[row, camera] = detection.pixels
                confidence[row, camera] = detection.confidence
                world[row, camera] = detection.world
    keypoints = Keypoints(
        np.arange(start, stop), tuple(camera.name for camera in recording.cameras), pixels, confidence, world
    )
    if cache is not None:
        save_keypoints(cache, keypoints)
    return keypoints, False
