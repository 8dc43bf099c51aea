"""The buffers an outline sampling fills (:func:`tracker.tracking.outline.sample_outlines`): the samples of every
visible outline, and every quadric placed in every camera's frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Samples:
    """Struct-of-arrays buffers of outline samples; the first ``count`` rows are valid.

    ``camera``, ``component``, ``quadric`` indices; ``pixel`` and ``normal`` in the
    recorded (distorted) image; ``jacobian`` the row L (6); ``point`` the contour
    point in its component's frame.
    """

    camera: np.ndarray
    component: np.ndarray
    quadric: np.ndarray
    pixel: np.ndarray
    normal: np.ndarray
    jacobian: np.ndarray
    point: np.ndarray
    count: int = 0

    @classmethod
    def allocate(cls, capacity: int) -> Samples:
        return cls(
            camera=np.zeros(capacity, np.int64),
            component=np.zeros(capacity, np.int64),
            quadric=np.zeros(capacity, np.int64),
            pixel=np.zeros((capacity, 2)),
            normal=np.zeros((capacity, 2)),
            jacobian=np.zeros((capacity, 6)),
            point=np.zeros((capacity, 3)),
        )

    @property
    def capacity(self) -> int:
        return len(self.camera)


@dataclass
class Placed:
    """Buffers for :func:`place`: every quadric in every camera's frame (see there)."""

    camera_from: np.ndarray
    quadric: np.ndarray
    clip: np.ndarray
    sphere: np.ndarray
    cone: np.ndarray

    @classmethod
    def allocate(cls, cameras: int, quadrics: int) -> Placed:
        return cls(
            np.zeros((cameras, quadrics, 4, 4)),
            np.zeros((cameras, quadrics, 4, 4)),
            np.zeros((cameras, quadrics, 4, 4)),
            np.zeros((cameras, quadrics, 4)),
            np.zeros((cameras, quadrics, 6)),
        )
