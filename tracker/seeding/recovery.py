"""Never stay lost: a tracked pose that strays from the keypoints is seeded again from them.

After each frame tracked with landmarks (checked across the views,
:mod:`tracker.landmarks.consistency`), the tracked pose's landmark points
(:func:`tracker.landmarks.body_landmarks.cue_points`) are projected into every view that has six or more of
them, and their image distances to the detections are taken as shares of the body's size there.
The pose has strayed when the mean over the views of the median distance exceeds :data:`STRAYED`
(:data:`DOUBTED` when the edges too found the frame uncertain), or when a single landmark seen in
two views or more has lain, in the mean over them, :data:`LANDMARK_STRAYED` beyond its learnt noise
zone for :data:`PERSISTENCE` frames in a row: a lost arm or leg moves too few landmarks to shift the
median, and its edges, found on the clutter it strayed to, hold it there against the cue. When it
has strayed, or the frame is lost, and the last :data:`WINDOW` frames all had landmarks (or it strayed
in a frame before they did: started far off, the landmarks' pull brings the body under the threshold
in a few frames while its limbs still hold wrong edges, ``pending``), the model
is fitted to those frames' landmarks, their triangulated points and then their detections
(:mod:`tracker.seeding.pose_fit`; with one view, from the tracked pose fitted to the newest frame's
detections), and snapped to the frame's edges as the first pose is
(:func:`tracker.seeding.first_pose.snap_to_edges`).

A re-seed that the frame's own landmarks called for (not a ``pending`` one), of a frame that is not lost, must
first answer them: the snapped pose must lie nearer them than the tracked pose, in the body's misfit or in that of
the landmarks that strayed for :data:`PERSISTENCE` frames (:meth:`Recovery.nearer`).  A seed fitted to three
frames of wrong landmarks (a view that reads the body's left for its right) can land farther from the frame's
landmarks than the tracked pose, turned about, and a body turned about its vertical axis shows much the same
outline and mask (docs/keypoints.md, "Recovery").

The image then arbitrates: the tracker starts again from the snapped pose, its status saying so
(:data:`tracker.status.RESEEDED`), unless the image backs it no better than the tracked pose (a frame that is not
lost): the share of its outline samples that found an edge plus the share of its body on the person's masks
(:meth:`tracker.tracking.person.PersonMasks.on_person`; the edges alone where the detector gave no mask), which must
exceed the tracked pose's by the standard error of the two shares of samples (:func:`_noise`, 3 % for 400 samples
each): a re-seed throws away the motion the tracker has learnt, and a difference within the shares' own noise says
nothing of which pose is right. Landmarks
that two views agree on can still be wrong, the detector following a bystander or reading an arm the other way
round; a re-seed fitted to them lands off the body's outlines and off its masks, and the tracked pose is kept
(``declined`` counts these). A pose strayed onto clutter finds edges there too, but not the person's mask; and
where the snap takes the seed off the mask (a table's edges drag it), the seed as fitted is judged by its own
edges instead (:meth:`tracker.tracking.frame_loop.Tracker.judged`). Once the detector has given masks, a frame
between its detections (landmarks interpolated, no mask) that is not lost leaves the try to the next frame with
them. A try costs the time of many frames (the fit and the snap), so after a declined one, or one whose
landmarks cannot place the body (which would otherwise be tried again in every frame), the recovery waits
:data:`WINDOW` frames before the next, twice as long after two in a row, and so on (:data:`BACKOFF`); a lost
frame is always tried.

Image distances, not triangulated ones: two views triangulate a detector's few pixels of noise into
centimetres of depth, while the share of the body's size reads the same in any view; the mean over
the views, because a body shifted along one camera's axis shows in the others.  At the true poses the
statistic stays well below :data:`STRAYED` on the demo and the hard suite's renders, while a lost body gives
several times it (docs/keypoints.md has the measurements).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.landmarks.body_landmarks import cue_points, landmark_world
from tracker.landmarks.store import Keypoints
from tracker.model import Model
from tracker.seeding.first_pose import fitted_to_frames, snap_to_edges
from tracker.seeding.pose_fit import fit_to_views
from tracker.status import LOST, RESEEDED, UNCERTAIN
from tracker.tracking.frame_loop import FrameResult, Tracker

STRAYED = 0.10
"""Median image distance between the tracked landmarks and their detections, as a share of the body's size in
the image, beyond which the pose has strayed (module docstring)."""

DOUBTED = 0.05
"""The same share beyond which a frame whose edges are uncertain has strayed: the edges and the landmarks
both say the pose is off."""

LANDMARK_STRAYED = 0.2
"""Mean image distance of one landmark from its detections over the views that see it (two or more), as a share of
the body's size, beyond the landmark's learnt noise zone
(:attr:`tracker.tracking.landmark_noise.LandmarkNoise.tolerance`), that says its limb has strayed when it lasts
:data:`PERSISTENCE` frames in a row.  A faceless mannequin's landmarks stray this far in a few frames at a time even
where it is tracked right, and a try is costly (the fit and the snap): this share and the persistence keep such
frames from trying one (docs/keypoints.md)."""

BACKOFF = 5
"""Re-seeds declined in a row after which the wait before the next try stops doubling: :data:`WINDOW` frames after
the first, twice as many after the second, up to ``WINDOW * 2**BACKOFF``."""

MIN_LANDMARKS = 6
"""Landmarks needed to judge a pose, or to fit one."""

WINDOW = 3
"""Frames of landmarks, the newest first and with none missing between, that a re-seed is fitted to: one frame's
detections may be swapped or wrong, and the body moves little in a few frames."""

PERSISTENCE = 2 * WINDOW
"""Frames in a row a landmark must lie :data:`LANDMARK_STRAYED` off before its limb counts as strayed: a limb lost
on clutter stays lost for tens of frames, while the demo's faceless wrists stray for at most 3 at its tracked
poses."""


@dataclasses.dataclass
class Recovery:
    """Checks each frame tracked with landmarks and seeds the tracker again when it strayed (module docstring);
    ``reseeded`` counts the frames."""

    model: Model
    cameras: list[Camera]
    min_confidence: float = 0.5
    reseeded: int = 0
    declined: int = 0
    refusals: int = 0  # tries since the last re-seed that did not re-seed (declined, or the fit failed)
    wait: int = 0  # frames to go before the next re-seed of a frame that is not lost
    recent: list = dataclasses.field(default_factory=list)  # the last frames' (pixels, confidence), newest first
    pending: bool = False  # the pose strayed, or was lost, in a frame before there were WINDOW frames to fit to
    masked: bool = False  # the detector has given the person's masks: a frame without them waits for one with them

    def __post_init__(self) -> None:
        self.component, self.point = cue_points(self.model)
        self.streak = np.zeros(len(self.component), np.int64)  # frames in a row each landmark lay off

    def misfit(self, poses: np.ndarray, pixels: np.ndarray, confidence: np.ndarray) -> tuple[float, np.ndarray]:
        """How far ``poses`` lie off the landmarks, as shares of the body's size in each view that has
        :data:`MIN_LANDMARKS` of them (module docstring): the mean over those views of the median landmark's image
        distance (NaN when there is none), and each landmark's mean distance (33,) over the views that see it, NaN
        when fewer than two do."""
        tracked = landmark_world(poses, self.component, self.point)
        distances = np.full((len(self.cameras), len(tracked)), np.nan)
        for k, (camera, seen_pixels, seen_confidence) in enumerate(zip(self.cameras, pixels, confidence)):
            usable = (seen_confidence >= self.min_confidence) & np.isfinite(seen_pixels).all(axis=1)
            usable &= np.isfinite(tracked).all(axis=1)
            if usable.sum() < MIN_LANDMARKS:
                continue
            projected = camera.project(tracked[usable])
            size = max(float(np.linalg.norm(np.ptp(projected, axis=0))), 1.0)
            distances[k, usable] = np.linalg.norm(projected - seen_pixels[usable], axis=1) / size
        judged = np.isfinite(distances).any(axis=1)
        body = float(np.mean(np.nanmedian(distances[judged], axis=1))) if judged.any() else float("nan")
        each = np.full(len(tracked), np.nan)
        seen_twice = np.isfinite(distances).sum(axis=0) >= 2
        each[seen_twice] = np.nanmean(distances[:, seen_twice], axis=0)
        return body, each

    def nearer(self, seed: np.ndarray, tracked: np.ndarray, *, pixels: np.ndarray, confidence: np.ndarray) -> bool:
        """Whether the poses ``seed`` lie nearer the frame's landmarks ``pixels`` at ``confidence`` than ``tracked``
        (:meth:`misfit`): the body's misfit, or that of the landmarks that have strayed for :data:`PERSISTENCE`
        frames, is lower."""
        body_seed, each_seed = self.misfit(seed, pixels, confidence)
        body, each = self.misfit(tracked, pixels, confidence)
        if body_seed < body:
            return True
        strayed = (self.streak >= PERSISTENCE) & np.isfinite(each_seed) & np.isfinite(each)
        return bool(strayed.any() and each_seed[strayed].mean() < each[strayed].mean())

    def fitted(self, start: np.ndarray) -> np.ndarray | None:
        """The model fitted to the landmarks of the :data:`WINDOW` recent frames (to their triangulated points,
        then to the detections, :func:`tracker.seeding.first_pose.fitted_to_frames`), or None when they cannot
        place the body; with one view, ``start`` refined against the newest frame's detections."""
        pixels = np.stack([frame_pixels for frame_pixels, _ in self.recent])
        confidence = np.stack([frame_confidence for _, frame_confidence in self.recent])
        if len(self.cameras) < 2:
            if (
                (confidence[0, 0] >= self.min_confidence) & np.isfinite(pixels[0, 0]).all(axis=1)
            ).sum() < MIN_LANDMARKS:
                return None
            return fit_to_views(self.model, start, self.cameras, pixels=pixels[:1], confidence=confidence[:1])
        names = tuple(camera.name for camera in self.cameras)
        frames = np.arange(len(self.recent))  # row numbers: the newest is row 0
        recent = Keypoints(frames, names, pixels, confidence, np.full((*pixels.shape[:3], 3), np.nan))
        try:
            return fitted_to_frames(self.model, self.cameras, recent, frames=len(self.recent))
        except TrackerInputError:  # the landmarks cannot place the body: go on as tracked
            return None

    def back_off(self) -> None:
        """After a try that did not re-seed: wait :data:`WINDOW` frames before the next, twice as long after two
        such tries in a row, and so on up to :data:`BACKOFF` doublings (a lost frame is tried all the same)."""
        self.refusals += 1
        self.wait = WINDOW * 2 ** (min(self.refusals, BACKOFF) - 1)

    def __call__(
        self, tracker: Tracker, images, keypoints: tuple[np.ndarray, np.ndarray] | None, result: FrameResult
    ) -> FrameResult:
        """``result`` of the frame just tracked in ``images`` (smoothed), or, when the pose strayed from
        ``keypoints`` or was lost, the frame tracked again from the pose fitted to them (status RESEEDED)."""
        if keypoints is None:
            self.recent.clear()
            self.streak[:] = 0
            self.pending = False
            return result
        pixels, confidence = keypoints
        self.recent = [keypoints, *self.recent[: WINDOW - 1]]
        body, each = self.misfit(result.poses, pixels, confidence)
        self.streak = np.where(each > LANDMARK_STRAYED + tracker.landmarks.noise.tolerance, self.streak + 1, 0)
        limit = DOUBTED if result.status == UNCERTAIN else STRAYED
        called = body > limit or bool((self.streak >= PERSISTENCE).any())  # by this frame's landmarks
        strayed = called or self.pending
        unmasked = not (tracker.person.trust > 0).any()
        self.masked |= not unmasked
        if result.status != LOST and (self.wait > 0 or not strayed or (self.masked and unmasked)):
            self.wait = max(self.wait - 1, 0)
            return result
        if len(self.recent) < WINDOW and len(self.cameras) >= 2:
            self.pending = True  # tried once there are frames to fit to (module docstring)
            return result
        self.pending = False
        seed = self.fitted(result.poses)
        if seed is None:  # the landmarks cannot place the body: a failed try, as costly as a declined one
            self.back_off()
            return result
        snapped = snap_to_edges(
            self.model, self.cameras, seed, images=images, keypoints=keypoints, settings=tracker.settings, smoothed=True
        )
        if tracker.person.on_person(seed) > tracker.person.on_person(snapped.poses):  # the snap took it off the person
            snapped = tracker.judged(images, poses=seed, smoothed=True)
        unanswered = called and not self.nearer(snapped.poses, result.poses, pixels=pixels, confidence=confidence)
        unbacked = _backing(tracker, snapped) < _backing(tracker, result) + _noise(snapped, result)
        if result.status != LOST and (unanswered or unbacked):
            self.declined += 1
            self.back_off()
            return result  # its landmarks, or the image, side with the tracked pose (module docstring)
        self.refusals = 0
        self.streak[:] = 0
        tracker.restart(snapped.poses)
        self.reseeded += 1
        return dataclasses.replace(snapped, status=RESEEDED)


def _noise(one: FrameResult, other: FrameResult) -> float:
    """The standard error of the difference between two results' shares of samples that found an edge, each over
    its own samples: below it, one backs the frame no better than the other (module docstring)."""
    return float(np.sqrt(sum(r.share * (1.0 - r.share) / max(r.samples, 1) for r in (one, other))))


def _backing(tracker: Tracker, result: FrameResult) -> float:
    """How well the frame's image backs ``result``: the share of its samples that found an edge, plus the share of
    its body on the person's masks (:meth:`tracker.tracking.person.PersonMasks.on_person`; 0 without masks)."""
    return result.share + tracker.person.on_person(result.poses)
