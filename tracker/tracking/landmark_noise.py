"""The keypoints' learnt noise: how far each landmark may lie from the tracked body's before it pulls, and how
firmly the edges hold the limb that places it (docs/keypoints.md, "Fusion with the edges").

A landmark's zone ``t`` (:func:`tracker.tracking.keypoint_cue.keypoint_kernel`) is learnt from its misfits in the
recent frames whose edges held the body (:func:`learnt_tolerance`), for this detector on this subject.  Where the
edges do not hold a limb (the component that places a joint landmark, :func:`tracker.landmarks.body_landmarks.placers`,
fitted its outline's edges worse than ``KeypointSettings.edge_misfit`` in the last frame's last iteration,
:func:`tracker.tracking.measure.component_misfits`), its landmarks pull from the floor zone with no fade, and that
frame does not teach their zones (:meth:`LandmarkNoise.held`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

NOISE_WINDOW = 30  # tracked frames whose landmark misfits set the keypoints' noise zones
NOISE_LEAST = 5  # misfits a landmark needs before its zone is learnt
HOLD_SPAN = 0.5  # LandmarkNoise.held falls from 1 to 0 over this share of keypoints.edge_misfit about it


def learnt_tolerance(history: np.ndarray, *, floor: float, multiple: float, ceiling: float, least: int) -> np.ndarray:
    """Each landmark's noise zone (K,), a share of the body's image size: ``multiple`` times the median of its
    recent misfits ``history`` (W, K) (NaN: not seen), between ``floor`` and ``ceiling``; ``floor`` for a
    landmark seen fewer than ``least`` times."""
    seen = np.isfinite(history).sum(axis=0)
    typical = np.full(history.shape[1], floor)
    known = seen >= least
    if known.any():
        typical[known] = multiple * np.nanmedian(history[:, known], axis=0)
    return np.clip(typical, floor, ceiling)


@dataclass(frozen=True)
class LandmarkNoise:
    """What a tracker has learnt of its landmarks' noise, carried from frame to frame (and whole to a tracker for
    other cameras, in the old rig's pixels): the recent tracked frames' misfits ``misfits`` (NOISE_WINDOW, K) per
    landmark (NaN: none; the next frame's goes to row ``row % NOISE_WINDOW``), each landmark's zone ``tolerance``
    (K,) learnt from them, and each component's edge misfit ``edge_misfit`` (N,), px, the median |m| of its
    samples in the last frame's last iteration (0 before the first frame: held)."""

    misfits: np.ndarray
    row: int
    tolerance: np.ndarray
    edge_misfit: np.ndarray

    @classmethod
    def start(cls, landmarks: int, components: int, floor: float) -> LandmarkNoise:
        """Nothing learnt yet: every zone at ``floor``, every component held."""
        return cls(np.full((NOISE_WINDOW, landmarks), np.nan), 0, np.full(landmarks, floor), np.zeros(components))

    def held(self, placer: np.ndarray, limit: float) -> np.ndarray:
        """How firmly the edges hold each landmark's placing component ``placer`` (K,) (every landmark not at a
        joint, -1, is held), from 1 to 0 (K,): 1 where its outline fitted them within 3/4 of ``limit``
        (``keypoints.edge_misfit``) in the last frame's last iteration (:attr:`edge_misfit`), 0 beyond 5/4 of it,
        linear between, so that a misfit near the limit shifts the landmark's zone and fade a little rather than all
        at once."""
        misfit = self.edge_misfit[np.maximum(placer, 0)]
        return np.where(placer < 0, 1.0, np.clip(0.5 - (misfit - limit) / (HOLD_SPAN * limit), 0.0, 1.0))

    def learnt(
        self, misfit: np.ndarray, held: np.ndarray, *, floor: float, multiple: float, ceiling: float
    ) -> LandmarkNoise:
        """This noise with a frame's landmark misfits ``misfit`` (C, K) (per camera; their median over the cameras)
        added to the recent ones and each landmark's zone set from them (:func:`learnt_tolerance`, between ``floor``
        and ``ceiling``, ``multiple`` times the median; nothing learnt for ``multiple`` 0).  Only for frames whose
        edges held the body, and only for the landmarks whose limb they held (``held`` (K,) at least 1/2,
        :meth:`held`): a limb that strays from right detections must not widen their zone."""
        if multiple <= 0:
            return self
        seen = np.isfinite(misfit)
        frame = np.full(misfit.shape[1], np.nan)
        for j in np.flatnonzero(seen.any(axis=0)):
            frame[j] = np.median(misfit[seen[:, j], j])
        frame[held < 0.5] = np.nan
        misfits = self.misfits.copy()
        misfits[self.row % NOISE_WINDOW] = frame
        tolerance = learnt_tolerance(misfits, floor=floor, multiple=multiple, ceiling=ceiling, least=NOISE_LEAST)
        return dataclasses.replace(self, misfits=misfits, row=self.row + 1, tolerance=tolerance)
