"""The buffers one search of a frame fills (:class:`Workspace`), the seconds it spends per stage, and what a viewer
is shown of it (:class:`Inspection`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from tracker.landmarks.body_landmarks import LANDMARKS
from tracker.tracking.colours import FACTOR
from tracker.tracking.measure import Statistics
from tracker.tracking.ownership import Ownership
from tracker.tracking.samples import Placed, Samples


@dataclass(frozen=True)
class Inspection:
    """What the edge search saw at one set of poses (for viewers and the shape fit): per sample its camera,
    component, pixel and normal, the searched interval ``[lo, hi]`` along the normal, the edge offset (NaN if
    none) and the IRLS weight, its ``quadric``, its contour ``point`` (3,) in its component's frame and its
    Jacobian row L (6,) (:class:`tracker.tracking.samples.Samples`)."""

    camera: np.ndarray
    component: np.ndarray
    pixel: np.ndarray
    normal: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    offset: np.ndarray
    weight: np.ndarray
    quadric: np.ndarray
    point: np.ndarray
    jacobian: np.ndarray


STAGES = ("grey", "outline", "ownership", "measure", "region", "solve")


@dataclass
class StageTimes:
    """Seconds spent per stage since creation: copying the grey images into the frame buffer (with their
    smoothing unless reader threads smoothed them, ``step(..., smoothed=True)``), outline sampling and
    visibility, search limits (ownership), edge search and Jacobians (with the landmarks), the region cue (its lines
    and the colours learnt), prior + chain solve + coercion."""

    seconds: dict = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))

    def add(self, stage: str, started: float) -> float:
        now = time.perf_counter()
        self.seconds[stage] += now - started
        return now


@dataclass
class Workspace:
    """The buffers an edge search fills, and the seconds it spent in them: each camera's image as the search reads
    it, ``images`` (C, H, W) uint8; the outline ``samples`` and their camera-frame quadrics ``placed``; the search
    limits (``ownership``'s buffers, and ``lo``/``hi`` of the samples, set by :meth:`Tracker.sample`); each sample's
    edge offset and IRLS weight (capacity,); the information C_i (N, 6, 6) and eta_i (N, 6) summed from them (and
    from the landmarks, whose misfits per camera the solve leaves in ``misfit`` (C, 33)); the evidence of each part
    that the cues which place it read in the frame's last iteration, ``evidence`` (N, 6, 6), and the parts of which
    any cue read something, ``seen`` (N,) bool (:meth:`tracker.tracking.cue.Cue.evidence`); each camera's half-size
    colour image as colour bins, ``bins`` (C, H', W'), when the frame came with one in every camera and no camera's
    is of a single colour, as a black frame a camera dropped is (``coloured``; the region cue would read it as the
    background everywhere and shrink every outline there onto nothing, docs/region.md), and the region cue's mean
    and variance per sample (:func:`tracker.tracking.region_lines.region_kernel`); the last edge search's
    :class:`~tracker.tracking.measure.Statistics`.

    A tracker steps in its own (:attr:`Tracker.work`); an inspection searches in a spare one
    (:meth:`Tracker.inspect`), so that it leaves the tracker as it was."""

    images: np.ndarray
    ownership: Ownership
    samples: Samples
    placed: Placed
    offset: np.ndarray
    weight: np.ndarray
    information: np.ndarray
    eta: np.ndarray
    misfit: np.ndarray
    evidence: np.ndarray
    seen: np.ndarray
    times: StageTimes
    bins: np.ndarray
    region_mean: np.ndarray
    region_variance: np.ndarray
    coloured: bool = False
    statistics: Statistics | None = None  # the edge search's counts and robust mean offset (EdgeCue.measure)
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    outside: np.ndarray | None = None
    depth: np.ndarray | None = None
    profiles: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None  # the region cue's lines scored at
    # the sampling (line_profiles: likelihood, start, first, length)

    def limits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The samples' search limits as :meth:`Tracker.sample` set them: ``lo``, ``hi``, ``outside``, ``depth``."""
        assert self.lo is not None and self.hi is not None and self.outside is not None and self.depth is not None
        return self.lo, self.hi, self.outside, self.depth

    @classmethod
    def around(cls, images: np.ndarray, ownership: Ownership) -> Workspace:
        """Fresh buffers for a search in ``images`` with the search limits of ``ownership``, whose model, rig and
        capacity size the others."""
        capacity, n = len(ownership.lo), ownership.model.size
        half = ownership.rig.size // FACTOR
        return cls(
            images,
            ownership,
            Samples.allocate(capacity),
            Placed.allocate(len(ownership.rig.names), ownership.model.quadric.shape[0]),
            np.zeros(capacity),
            np.zeros(capacity),
            np.zeros((n, 6, 6)),
            np.zeros((n, 6)),
            np.full((len(ownership.rig.names), len(LANDMARKS)), np.nan),
            np.zeros((n, 6, 6)),
            np.zeros(n, bool),
            StageTimes(),
            np.zeros((len(half), int(half[:, 1].max()), int(half[:, 0].max())), np.int16),
            np.zeros(capacity),
            np.zeros(capacity),
        )

    def spare(self, images: np.ndarray) -> Workspace:
        """Buffers of the same sizes for a search in ``images`` beside this one's (:meth:`Ownership.spare
        <tracker.tracking.ownership.Ownership.spare>`)."""
        return Workspace.around(images, self.ownership.spare())
