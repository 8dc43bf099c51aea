"""The interface every cue of the solve stands behind (docs/method-tracking.md, section 6).

A cue is one source of information about the body's motion in a frame: the edges along the outline
(:mod:`tracker.tracking.edge_cue`), the keypoint detector's landmarks (:mod:`tracker.tracking.keypoint_cue`), the
colours either side of the outline (:mod:`tracker.tracking.region_cue`).  In every iteration of a frame the tracker
asks each cue in turn to add its information ``C_i`` and ``eta_i`` about each component's twist at the current poses
(:meth:`Cue.add`), then solves the whole tree once for them all.  A cue is told of a new frame's inputs
(:meth:`Cue.prepare`), says what its readings of the frame tell of each part (:meth:`Cue.evidence`), learns from the
frame once it is tracked (:meth:`Cue.learn`), forgets what it learnt when the
tracker starts afresh (:meth:`Cue.restart`), and shows what it reads to a viewer (:meth:`Cue.inspect`).  What it
learns lives in its own state; the buffers of one search, shared by all cues, in the
:class:`~tracker.tracking.workspace.Workspace` it is handed, since a viewer's inspection or a lead's retry searches
in a spare one.

A new cue is a module with a class of this shape and one line in :data:`tracker.tracking.cues.CUES`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.workspace import Workspace


@dataclass(frozen=True)
class Frame:
    """What a frame brings to the cues besides its images: the detector's landmarks, pixels (C, 33, 2) and
    confidence (C, 33) float64, or None."""

    keypoints: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(frozen=True)
class Iteration:
    """One iteration of a frame as the cues see it: its number ``index`` of ``count``, the edge search's range
    (pixels either side, :meth:`tracker.tracking.frame_loop.Tracker.search_range`), whether the outlines were just
    sampled afresh (``resampled``), and each component's body twist since they were (``twist`` (N, 6); zero when just
    sampled), by which every sample is moved along its line to first order."""

    index: int
    count: int
    search_range: int
    resampled: bool
    twist: np.ndarray

    @property
    def last(self) -> bool:
        """Whether this is the frame's last iteration."""
        return self.index == self.count - 1


class Cue(Protocol):
    """One cue of the solve (the module docstring)."""

    name: str
    """What a viewer's inspection calls it (:meth:`tracker.tracking.frame_loop.Tracker.inspect_cues`)."""
    stage: str
    """The stage of :class:`~tracker.tracking.workspace.StageTimes` its seconds count to."""
    places: bool
    """Whether its readings place a part where the images show it (the outline's edges and colours), or only say
    that something sees it (a detector's landmarks, which it also guesses where nothing shows them): only the
    first hold a part (:mod:`tracker.tracking.held`)."""

    def restart(self) -> None:
        """Forget what was learnt: the tracker goes on from a new first pose."""
        ...

    def warm_up(self, tracker: Tracker) -> None:
        """Run the kernels that the tracker's blank iterations do not (compiles them, or loads numba's cache), and
        leave what was learnt as it was."""
        ...

    def prepare(self, tracker: Tracker, frame: Frame) -> np.ndarray | None:
        """Take a new frame's inputs; the components (N,) bool this cue says are hidden from every view in it, or
        None."""
        ...

    def add(self, tracker: Tracker, work: Workspace, iteration: Iteration) -> None:
        """Add this cue's information at the tracker's current poses to ``work.information`` and ``work.eta``."""
        ...

    def learn(self, tracker: Tracker, status: int, *, kept: bool) -> None:
        """Learn from the frame just tracked (in ``tracker.work``) with ``status``; ``kept``: False where the frame
        kept the poses it started from rather than those its cues moved it to."""
        ...

    def evidence(self, tracker: Tracker, work: Workspace, added: np.ndarray) -> np.ndarray:
        """The information (N, 6, 6) this cue's readings of the frame give about each part, as the evidence that the
        images hold it (:mod:`tracker.tracking.held`): ``added``, what it added to ``work.information`` in the frame's
        last iteration, or a reading of its own at the same poses."""
        ...

    def inspect(self, tracker: Tracker, work: Workspace) -> tuple[np.ndarray, np.ndarray] | None:
        """What this cue reads of each sample in ``work``, sampled and searched at the poses shown: an offset (NaN:
        none) and a weight per sample, or None where it reads nothing per sample."""
        ...
