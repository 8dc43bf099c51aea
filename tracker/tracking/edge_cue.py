"""The edge cue (docs/method-tracking.md, section 3): each outline sample searches its line for the nearest
grey-level edge within its limits, and the offsets' IRLS-weighted statistics give each component's ``C_i`` and
``eta_i`` (:func:`tracker.tracking.measure.measure_kernel`).  Its search's counts and robust mean offset judge the
frame's status.  Its images are the grey ones reduced and smoothed (:func:`smooth`)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import cv2
import numpy as np

from tracker.tracking.cue import Frame, Iteration
from tracker.tracking.measure import Statistics, measure_kernel, reduction
from tracker.tracking.settings import Settings, scaled_to
from tracker.tracking.workspace import Workspace

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker


def reductions(settings: Settings, cameras) -> np.ndarray:
    """Each camera's :func:`reduction` under ``settings`` (integer (C,)): the factor its images are searched at."""
    return np.array([reduction(int(min(camera.size)), settings.images.work_side) for camera in cameras], np.int64)


def smooth(image: np.ndarray, sigma: float, work_side: int = 0) -> np.ndarray:
    """A grey image as the edge search reads it: reduced by :func:`reduction` (each pixel the mean of a block of
    f x f, the rows and columns past the last whole block dropped) and smoothed so that the whole is a Gaussian of
    about ``sigma`` full-size pixels (none for sigma 0).

    The block mean already smooths by (f^2 - 1) / 12 squared full-size pixels, so the Gaussian on the reduced
    image takes the rest, at a fraction of the cost of blurring the full-size image (docs/speed.md).  The search
    reads the reduced image at full-size coordinates (:func:`tracker.tracking.measure.measure_kernel`), so nothing
    else changes.
    """
    f = reduction(min(image.shape[:2]), work_side)
    if f > 1:
        height, width = image.shape[0] // f, image.shape[1] // f
        image = cv2.resize(image[: height * f, : width * f], (width, height), interpolation=cv2.INTER_AREA)
        sigma = math.sqrt(max(sigma**2 - (f * f - 1) / 12.0, 0.0)) / f
    return cv2.GaussianBlur(image, (0, 0), sigma) if sigma > 0 else image


def smoother(settings: Settings, cameras) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`smooth` at the blur that a :class:`~tracker.tracking.frame_loop.Tracker` of ``settings`` uses for the
    images of ``cameras`` (``blur_sigma`` scaled to their largest short side, :func:`scaled_to`)."""
    sigma = scaled_to(settings, max(min(camera.size) for camera in cameras)).edges.blur_sigma
    return functools.partial(smooth, sigma=sigma, work_side=settings.images.work_side)


class EdgeCue:
    """The edges along the outline, searched in the images a tracker loaded (:class:`~tracker.tracking.cue.Cue`)."""

    name = "edges"
    stage = "measure"
    places = True

    def __init__(self, tracker: Tracker):
        """The edges need nothing of the tracker beyond what each call hands them."""

    def restart(self) -> None:
        return None

    def warm_up(self, tracker: Tracker) -> None:
        return None

    def prepare(self, tracker: Tracker, frame: Frame) -> None:
        return None

    def add(self, tracker: Tracker, work: Workspace, iteration: Iteration) -> None:
        work.statistics = self.measure(tracker, work, search_range=iteration.search_range, twist=iteration.twist)

    def learn(self, tracker: Tracker, status: int, *, kept: bool) -> None:
        return None

    def evidence(self, tracker: Tracker, work: Workspace, added: np.ndarray) -> np.ndarray:
        return added

    def inspect(self, tracker: Tracker, work: Workspace) -> tuple[np.ndarray, np.ndarray]:
        return self.read(work)

    @staticmethod
    def read(work: Workspace) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's edge offset (NaN: none) and IRLS weight in ``work``'s last search, copied."""
        n = work.samples.count
        return work.offset[:n].copy(), work.weight[:n].copy()

    @staticmethod
    def measure(tracker: Tracker, work: Workspace, *, search_range: int, twist: np.ndarray) -> Statistics:
        """Search the edge of every sample in ``work`` (moved by ``twist`` since sampling) in its images and fill
        its C_i, eta_i (measure_kernel); the pass's counts and robust mean offset (NaN where nothing was found)."""
        s, st = work.samples, tracker.settings
        visible, found, sum_wm, sum_w = measure_kernel(
            work.images,
            tracker.search_size,
            tracker.reduction,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            s.jacobian,
            twist,
            search_range,
            st.edges.threshold,
            st.solve.robust_c,
            tracker.model.size,
            work.offset,
            work.weight,
            work.information,
            work.eta,
            work.lo,
            work.hi,
        )
        return Statistics(visible, found, sum_wm / sum_w if sum_w > 0 else float("nan"))
