"""Which landmarks lie on the person: the detector's segmentation mask as a test of what a view shows.

The landmark model places all 33 landmarks whether they are seen or not, and its visibility score
does not always say which: a person seated behind a desk gets knees and ankles where legs would be,
scored 0.9 in some views.  The same network also outputs a segmentation mask, the probability that
each pixel shows the person, and a desk in front of the legs is not the person.  A landmark is
taken as seen in a view when it lies on the mask (probability at least :data:`LEVEL`) widened by
:data:`SLACK` (a joint near the outline, the mask's soft edge), and so is a part of the model whose outline
mostly does.

The mask is read like the landmarks, in a square around the person (:func:`tracker.landmarks.crop.around`,
so a small body fills the crop), and kept in that square's pixels.  docs/fit-model.md, "Partly in view".

The video-mode detector of tracking segments the person in the same pass that places the landmarks
(:class:`tracker.landmarks.detector.Detection`); :func:`on_person` drops the landmarks off that mask, so the hips
and knees it guesses behind a table do not pull the tracked body onto the table (docs/keypoints.md).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.landmarks.crop import Region, around, crop_from_image, cut, to_image
from tracker.landmarks.detector import native_logs_muted, pose_solution, rgb_of
from tracker.landmarks.store import Keypoints

LEVEL = 0.5
"""The mask's probability from which a pixel shows the person."""

SLACK = 0.02
"""How far off the mask a point still counts as on the person, as a share of the square's side (3-12 % of the
body's extent, by the square): a joint near the outline, the mask's soft edge, an outline a few pixels out."""

MARGINS = (1.5, 2.5, 4.0, 6.0)
"""The squares the mask is read in, as multiples of the landmarks' extent, tried in turn until the network
finds the person in one: tight first, so that little else is in it (hallucinated landmarks of hidden legs can
leave a square off-centre)."""

AGREE = 0.1
"""The network's own landmarks in the square must lie this close to the given ones (median distance, as a share
of their extent), or the mask is someone else's: a person in a photo on the wall, a passer-by."""


@dataclass(frozen=True)
class PersonMask:
    """Where the person is in one image: the ``region`` square the mask was read in, and ``person`` (n, n) bool,
    its crop of the mask widened by :data:`SLACK`."""

    region: Region
    person: np.ndarray

    @classmethod
    def widened(cls, region: Region, probability: np.ndarray, slack: float) -> PersonMask:
        """The person where the network's ``probability`` (n, n) over ``region`` is at least :data:`LEVEL`, widened by
        ``slack`` of the side (a disc)."""
        reach = max(1, round(slack * probability.shape[0]))
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
        return cls(region, cv2.dilate((probability >= LEVEL).astype(np.uint8), disc) > 0)

    def covers(self, pixels: np.ndarray) -> np.ndarray:
        """Whether each image point ``pixels`` (M, 2) lies on the person (M,) bool; not if outside the square or
        not finite."""
        size = self.person.shape[0]
        finite = np.isfinite(pixels).all(axis=1)
        affine = crop_from_image(self.region, size)
        crop = np.where(finite[:, None], pixels, -1e9) @ affine[:, :2].T + affine[:, 2]
        at = np.floor(crop).astype(np.int64)
        inside = finite & (at >= 0).all(axis=1) & (at < size).all(axis=1)
        out = np.zeros(len(pixels), bool)
        out[inside] = self.person[at[inside, 1], at[inside, 0]]
        return out


FAR_OFF = 0.06
"""How far off its detection's mask (at :data:`LEVEL`) a landmark must lie to be dropped in tracking
(:func:`on_person`), a share of the square's side: three times :data:`SLACK`, so that an ankle or a wrist at the
mask's soft edge stays (at SLACK the demo's, dropped at a re-seed, left it 12 mm off and drifting to 37 mm)."""


def on_person(keypoints: Keypoints) -> Keypoints:
    """``keypoints`` with no confidence where a landmark lies more than :data:`FAR_OFF` off its own detection's mask
    of the person; views without a mask, and keypoints without masks, as they were."""
    if keypoints.mask is None or keypoints.square is None:
        return keypoints
    confidence = keypoints.confidence.copy()
    for f, k in zip(*np.nonzero(np.isfinite(keypoints.square).all(axis=2) & (confidence > 0).any(axis=2))):
        (x, y, side), mask = keypoints.square[f, k], keypoints.mask[f, k]
        person = PersonMask.widened(Region((float(x), float(y)), float(side)), mask / 255.0, FAR_OFF)
        confidence[f, k, ~person.covers(keypoints.pixels[f, k])] = 0.0
    return dataclasses.replace(keypoints, confidence=confidence)


class Segmenter:
    """BlazePose in still-image mode with its segmentation output: :meth:`mask` of one image at a time."""

    def __init__(self) -> None:
        with native_logs_muted():
            self._pose = pose_solution().Pose(static_image_mode=True, model_complexity=1, enable_segmentation=True)

    def mask(self, image: np.ndarray, pixels: np.ndarray) -> PersonMask | None:
        """The person in a BGR or grey uint8 ``image`` whose landmarks ``pixels`` (33, 2) were found in it, read in
        a square around them (:data:`MARGINS`); None when they are not finite or no square shows the network that
        person (its own landmarks within :data:`AGREE` of them: not someone else in the square)."""
        rgb = rgb_of(image)
        for margin in MARGINS:
            region = around(pixels, margin)
            if region is None:
                return None
            with native_logs_muted():
                found = self._pose.process(cut(rgb, region))
            if found.segmentation_mask is None or not _same_person(found, region, pixels):
                continue
            return PersonMask.widened(region, found.segmentation_mask, SLACK)
        return None

    def close(self) -> None:
        """Free the network."""
        self._pose.close()


def _same_person(found, region: Region, pixels: np.ndarray) -> bool:
    """Whether the landmarks the network ``found`` in ``region``'s crop are those of the person at ``pixels``."""
    size = found.segmentation_mask.shape[0]
    seen = np.array([(point.x * size, point.y * size) for point in found.pose_landmarks.landmark])
    finite = np.isfinite(pixels).all(axis=1)
    extent = float((pixels[finite].max(axis=0) - pixels[finite].min(axis=0)).max())
    gap = np.linalg.norm(to_image(seen, region, size)[finite] - pixels[finite], axis=1)
    return bool(np.median(gap) <= AGREE * extent)
