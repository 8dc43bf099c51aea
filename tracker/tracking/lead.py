"""The limb lead (docs/keypoints.md): a limb the edges could not reach, moved to its landmarks and the frame tracked
again, kept where the limb's edges fit better.

A limb's edges are searched a few pixels either side of its predicted outline: a limb that moved farther since the
last frame (a fast swing, a low frame rate, a re-seed that left no velocity) lies beyond them, and its edges then
hold it on whatever lies within reach, against the landmarks that say where it is (their pull is bounded, like an
edge sample's).  So where the frame's landmarks still lie far off a limb once tracked (:meth:`Lead.led_limbs`), that
limb is moved to them (:meth:`Lead.move_limbs`) and the frame tracked again from there.  The edges arbitrate, as they
do a re-seed (:mod:`tracker.seeding.recovery`): the led pose is kept only when the led components' outlines find
their edges closer (:func:`tracker.tracking.measure.support`) than the tracked ones did; a detector that is wrong
where the edges are right (a faceless mannequin's wrists) is then outvoted.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from tracker.landmarks.body_landmarks import limbs
from tracker.model import Model
from tracker.tracking.measure import Statistics, support
from tracker.tracking.workspace import Workspace

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker

CROSSED_VIEWS = 3  # views in which a left/right pair must fit better swapped to say the tracked limbs crossed over
LEAD_ITERATIONS = 3  # solves of the landmarks alone that move a limb they lead (Lead.move_limbs)
PIN = 1e6  # the prior's multiple that holds the components a lead does not move at their predicted poses


class Lead:
    """The limbs each landmark can lead, ``limbs`` (K, N) bool (:func:`tracker.landmarks.body_landmarks.limbs`),
    each limb's root landmarks, ``roots`` (K, K), and the landmarks that lead a leg, ``leads_leg`` (K,)."""

    def __init__(self, model: Model, component: np.ndarray, legs: np.ndarray):
        self.limbs = limbs(model, component)
        top = np.where(self.limbs.any(axis=1), self.limbs.argmax(axis=1), -1)  # breadth-first: the limb's first part
        self.roots = (component[None, :] == top[:, None]) & (top[:, None] >= 0)  # (K, K): each limb's root
        self.leads_leg = (self.limbs & legs[None]).any(axis=1)

    def retry(self, tracker: Tracker, stats: Statistics, keypoints: tuple[np.ndarray, np.ndarray]) -> Statistics:
        """Try again the limbs the edges could not reach, led by the landmarks ``keypoints`` (pixels, confidence; the
        module docstring); the frame's statistics (``stats`` as tracked, unless the try is kept)."""
        work = tracker.work
        pixels, confidence = keypoints
        led, crossed = self.led_limbs(tracker, pixels, confidence)
        if not led.any():
            return stats
        tracked, anchor = tracker.poses, tracker.anchor
        robust_c = tracker.settings.solve.robust_c

        def fit(buffers: Workspace) -> float:
            """How closely the led components' outlines found their edges in ``buffers``' last measurement."""
            s = buffers.samples
            return support(buffers.offset, s.component, count=s.count, chosen=led, robust_c=robust_c)

        before = fit(work)
        tracker.work, tracker.retry = tracker.retry, work  # the try searches in the spare buffers, the frame's kept
        tracker.work.coloured = work.coloured
        self.move_limbs(tracker, led, keypoints, swaps=not crossed)
        for iteration in range(tracker.settings.solve.iterations):
            again = tracker.iterate(iteration)
        tried = tracker.work
        if fit(tried) > before:
            return again
        tracker.work, tracker.retry = work, tried  # the edges side with the tracked pose
        tracker.poses, tracker.anchor = tracked, anchor
        return stats

    def led_limbs(self, tracker: Tracker, pixels: np.ndarray, confidence: np.ndarray) -> tuple[np.ndarray, bool]:
        """The components (N,) bool that the landmarks ``pixels`` at ``confidence`` lead at the tracker's current
        poses: the limbs of the landmarks that lie more than ``keypoints.lead`` of the body's image size beyond their
        learnt noise zone (:class:`~tracker.tracking.landmark_noise.LandmarkNoise`) off their image, in the median
        over the views that see them (their detections already checked to agree, :mod:`tracker.landmarks.consistency`;
        one view may be all there is: the edges arbitrate, :meth:`retry`), where the landmarks at the limb's root (the
        shoulder of an arm, the hip of a leg) lie within that of theirs: a limb is led from a trunk in place; a trunk
        off its landmarks is the recovery's (:mod:`tracker.seeding.recovery`), and leading its limbs would hide it
        from it.

        A left/right pair that fits better swapped in every view that sees it, :data:`CROSSED_VIEWS` or more, says the
        tracked limbs crossed over (a leg taken for the other as they pass): its landmarks, left out of the pull as a
        detector's swap, would then hold nothing (a detector's own swap is one view's, or two's alike from behind).
        Both limbs are led by their landmarks as detected, with the swap check off, however near; returns the led
        components and whether any was led so."""
        st, landmarks, work = tracker.settings.keypoints, tracker.landmarks, tracker.work
        checked, free = np.empty_like(work.misfit), np.empty_like(work.misfit)
        scratch = np.zeros_like(work.information), np.zeros_like(work.eta)
        zone, information, eta = landmarks.floor, scratch[0], scratch[1]
        _, rejected = landmarks.pull(
            tracker, pixels, confidence, zone=zone, information=information, eta=eta, misfit=checked
        )
        crossed = np.zeros(checked.shape[1], bool)
        if rejected:  # some pair fits better swapped in some view: where in every view that sees it?
            landmarks.pull(
                tracker, pixels, confidence, zone=zone, information=information, eta=eta, misfit=free, swaps=False
            )
            crossed = (np.isfinite(free).sum(axis=0) >= CROSSED_VIEWS) & ~np.isfinite(checked).any(axis=0)
        misfit = np.where(crossed, free, checked)
        seen = np.isfinite(misfit)
        views = seen.sum(axis=0)
        far = np.array([np.median(misfit[seen[:, j], j]) if views[j] else 0.0 for j in range(misfit.shape[1])])
        judged = views >= 1
        off = judged & ((far > st.lead + landmarks.noise.tolerance) | crossed)
        placed = judged & ~off
        rooted = self.roots.any(axis=1) & ~(self.roots & ~placed).any(axis=1)
        led = off & rooted
        if st.lead_off_mask:
            somewhere, everywhere = self.limbs_off_mask(tracker)
            sure = (confidence >= st.confidence).any(axis=0)
            astray = (self.limbs & somewhere[None]).any(axis=1)
            led |= sure & astray & (~self.leads_leg | (self.limbs & everywhere[None]).any(axis=1))
        return self.limbs[led].any(axis=0), bool((off & rooted & crossed).any())

    def limbs_off_mask(self, tracker: Tracker) -> tuple[np.ndarray, np.ndarray]:
        """The parts (N,) bool that lie off the person's mask of some view at the current poses, and those off it in
        every view that judges them: off a view's mask is under half of a part's axis points on it, of those within
        the image and the mask's square (:meth:`tracker.tracking.person.PersonMasks.shares`), in a view whose mask has
        the trunk (the parts of no limb) on it (half of its points or more, over its parts on average).  A part hidden
        in that view (:meth:`tracker.tracking.person.PersonMasks.see`), or hidden as guessed, is not off it.

        A segmenter's mask covers the limbs that the edges lose: in blur, at a low frame rate, or along one view's ray,
        where the other views' edges are weak and the landmarks within their learnt zones do not pull.  Such a limb is
        led by its landmarks (:meth:`led_limbs`), and the edges arbitrate as for any lead: an arm off the mask of any
        view, a leg only off every view's (a leg off one view's mask and on another's is hidden by a table in that
        view; docs/keypoints.md, "A limb beyond the edges' reach")."""
        person = tracker.person
        masked = person.masked()
        n = tracker.model.size
        if not masked:
            return np.zeros(n, bool), np.zeros(n, bool)
        shares = np.array([person.shares(camera, tracker.poses) for camera in masked])
        trunk = shares[:, ~self.limbs.any(axis=0)]
        counted = np.isfinite(trunk)
        with np.errstate(invalid="ignore", divide="ignore"):
            on = np.where(counted, trunk, 0.0).sum(axis=1) / counted.sum(axis=1) >= 0.5
            away = shares < 0.5
        judged = np.isfinite(shares) & on[:, None]
        off = away & on[:, None] & ~tracker.hidden[None] & ~person.off_mask[masked]
        return off.any(axis=0), (away | ~judged).all(axis=0) & judged.any(axis=0)

    def move_limbs(
        self, tracker: Tracker, led: np.ndarray, keypoints: tuple[np.ndarray, np.ndarray], *, swaps: bool = True
    ) -> None:
        """Move the components ``led`` (N,) bool to the landmarks ``keypoints`` (pixels, confidence), alone:
        :data:`LEAD_ITERATIONS` solves of the landmarks on them, from the floor zone with no fade, while the other
        components are held where they are (their prior times :data:`PIN`) and the prior about each step's start
        damps the led ones.  The moved pose becomes the frame's prediction (the anchor).  ``swaps``: as in
        :meth:`tracker.tracking.keypoint_cue.KeypointCue.pull`."""
        work, landmarks = tracker.work, tracker.landmarks
        pixels, confidence = keypoints
        component = landmarks.component
        chosen = np.where((component >= 0) & led[np.maximum(component, 0)], confidence, 0.0)
        prior = np.where(led[:, None, None], tracker.prior, PIN * tracker.prior)
        information, eta, misfit = np.empty_like(work.information), np.empty_like(work.eta), np.empty_like(work.misfit)
        for _ in range(LEAD_ITERATIONS):
            tracker.anchor = tracker.poses
            information[:] = 0.0
            eta[:] = 0.0
            landmarks.pull(
                tracker,
                pixels,
                chosen,
                zone=landmarks.floor,
                information=information,
                eta=eta,
                misfit=misfit,
                swaps=swaps,
            )
            tracker.poses = tracker.solved(information, eta, prior=prior, poses=tracker.poses)
        tracker.anchor = tracker.poses
