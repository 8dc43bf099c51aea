"""The detector beside a live tracker: it never makes the tracker wait.

A worker process runs one landmarker per camera.  The tracker offers it a frame set (the JPEGs as
the cameras delivered them) every ``step``-th frame; the worker takes it only when it is free, so
it runs at its own pace and frame sets it has no time for are skipped.  Each detection comes back
tagged with the number of the frame it was captured in, checked across the views
(:mod:`tracker.landmarks.consistency`), and the tracker uses it in the first frame after it
arrives, moved to that frame by the tracked motion since its capture (:func:`transferred`): a
landmark's misfit at its capture time pulls on the pose now.
"""

from __future__ import annotations

import multiprocessing
import queue
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from tracker import stop_signals
from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_world
from tracker.landmarks.consistency import consistent
from tracker.landmarks.detector import (
    Detector,
    detect_views,
    detector_name,
    native_logs_muted,
    require_detector,
    view_threads,
)
from tracker.landmarks.store import Keypoints

_CLOSE_WAIT = 2.0
"""Seconds the worker gets to finish its frame set when the run ends, before it is stopped."""

READY = "ready"
"""What the worker puts on its results once its landmarkers are loaded."""

_START_WAIT = 120.0
"""Seconds the worker may take to load its landmarkers."""


def _work(cameras: list[Camera], jobs, results, landmark_model: str) -> None:
    """The worker process: detect every frame set taken from ``jobs`` (None ends it) with ``landmark_model``, the views
    side by side in threads, and put (number, pixels, confidence) of the checked landmarks on ``results``; an error is
    put instead and ends it.  Its landmarkers load their networks before it says it is ready.  The stop signals are the
    parent's to handle (:mod:`tracker.stop_signals`)."""
    stop_signals.ignore()
    try:
        with native_logs_muted(), ThreadPoolExecutor(view_threads(len(cameras)), "view") as pool:
            detectors = [Detector(landmark_model=landmark_model) for _ in cameras]
            list(pool.map(Detector.warm_up, detectors))
            names = tuple(camera.name for camera in cameras)
            results.put(READY)
            while (job := jobs.get()) is not None:
                number, jpegs = job
                pixels = np.full((len(cameras), len(LANDMARKS), 2), np.nan)
                confidence = np.zeros((len(cameras), len(LANDMARKS)))
                images = [None if jpeg is None else cv2.imdecode(jpeg, cv2.IMREAD_COLOR) for jpeg in jpegs]
                for camera, found in enumerate(detect_views(detectors, images, cameras=cameras, pool=pool)):
                    pixels[camera], confidence[camera] = found.pixels, found.confidence
                world = np.full((1, len(cameras), len(LANDMARKS), 3), np.nan)
                raw = Keypoints(
                    np.array([number]), names, pixels[None], confidence[None], world, detector_name(landmark_model)
                )
                checked = consistent(raw, cameras)[0]
                results.put((number, checked.pixels[0], checked.confidence[0]))
    except BaseException as error:  # handed to the tracker, raised there
        results.put(error)


class LiveDetector:
    """A worker process detecting the frame sets offered to it when it is free, with ``landmark_model`` (module
    docstring)."""

    def __init__(self, cameras: list[Camera], step: int, *, landmark_model: str):
        require_detector(landmark_model)
        self.step = step
        context = multiprocessing.get_context("spawn")
        with stop_signals.held():
            self.jobs = context.Queue()
            self.results = context.Queue()
            self.worker = context.Process(
                target=_work,
                args=(cameras, self.jobs, self.results, landmark_model),
                name="keypoint detector",
                daemon=True,
            )
            stop_signals.start(self.worker)
        self.busy = False
        self.arrived: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.offered = self.taken = self.used = 0

    def wait_until_ready(self) -> None:
        """Block until the worker has loaded its landmarkers (a second or two), so that the first frame sets
        offered are not skipped while it starts; raises its error, or TrackerInputError when it does not start."""
        try:
            item = self.results.get(timeout=_START_WAIT)
        except queue.Empty:
            raise TrackerInputError(
                f"the keypoint detector did not start within {_START_WAIT:g} s; run with --keypoints off"
            ) from None
        if isinstance(item, BaseException):
            raise item

    def offer(self, number: int, jpegs: list[np.ndarray | None]) -> bool:
        """Hand frame ``number``'s JPEGs (one per camera of the rig, None for a camera without a frame) to
        the worker if it is the step's turn and the worker is free; whether it took them."""
        self._collect()
        if number % self.step:
            return False
        self.offered += 1
        if self.busy:
            return False
        self.jobs.put((number, jpegs))
        self.busy, self.taken = True, self.taken + 1
        return True

    def newest(self) -> tuple[int, np.ndarray, np.ndarray] | None:
        """The newest detection not yet handed out (frame number, pixels (C, 33, 2), confidence (C, 33)),
        or None; never waits."""
        self._collect()
        if not self.arrived:
            return None
        newest = self.arrived[-1]
        self.arrived.clear()
        self.used += 1
        return newest

    def _collect(self) -> None:
        """Take what the worker finished off its queue."""
        while True:
            try:
                item = self.results.get_nowait()
            except queue.Empty:
                return
            if isinstance(item, BaseException):
                raise item
            self.arrived.append(item)
            self.busy = False

    def close(self) -> None:
        """End the worker (it finishes the frame set in hand first, for a while)."""
        self.jobs.put(None)
        self.worker.join(_CLOSE_WAIT)
        stop_signals.end(self.worker)


def transferred(
    pixels: np.ndarray,
    then: np.ndarray,
    now: np.ndarray,
    *,
    cameras: list[Camera],
    component: np.ndarray,
    point: np.ndarray,
) -> np.ndarray:
    """Landmark pixels (C, K, 2) detected when the body was at poses ``then`` (N, 4, 4), moved to where the
    same misfit lies with the body at ``now``: each landmark shifted by how far its model point's image
    (``point`` (K, 3) in component ``component`` (K,), -1 for none: not moved) moved between the two."""
    moved = pixels.copy()
    marked = np.flatnonzero(component >= 0)
    then_world = landmark_world(then, component, point)[marked]
    now_world = landmark_world(now, component, point)[marked]
    for camera_index, camera in enumerate(cameras):
        moved[camera_index, marked] += camera.project(now_world) - camera.project(then_world)
    return moved
