"""The frame loop (docs/method-tracking.md, section 6): predict, then per iteration ask every cue, solve, coerce.

Per frame the poses are predicted by the motion model (:mod:`tracker.tracking.motion_model`: none, constant
velocity, or the second-order Kalman filter of :mod:`tracker.tracking.motion_prior`), then each IRLS iteration
samples the visible outlines in every camera (every ``resample_every``-th iteration; between, each sample slides
along its line with its component, to first order), limits each sample's search half way to the next predicted
edge that is not its own boundary (:mod:`tracker.tracking.ownership`), asks every cue
(:data:`tracker.tracking.cues.CUES`: the edges, the landmarks, the colour regions) for its information ``C_i`` and
``eta_i``, adds a weak Gaussian prior ``P`` about the predicted pose (so that every ``C_i`` is invertible, section 3,
and the iterations cannot drift along directions the images do not observe; with the Kalman filter the information
of its predicted covariance, at least P), solves the whole tree for one twist per component (section 4), applies
``E_i <- E_i exp(alpha_i)`` and coerces the joints exact (section 5) (:mod:`tracker.tracking.solve`).  The search
range shrinks from iteration to iteration (coarse to fine).  With landmarks, a limb they place far from where the
edges left it is moved to them and the frame tracked again (:mod:`tracker.tracking.lead`), and a frame whose edges
dragged the body off them keeps the poses it started from.  Each part is then held by the images, or only by the
prior and the joints (:mod:`tracker.tracking.held`), and the frame's status comes from the parts held: the share of
their samples that found an edge, those edges' robust mean offset, and how many of the parts they are.  Where the
cameras are not frame-locked, each view sees the poses moved on to its own capture time, to first order
(:meth:`Tracker.seen`, docs/sync.md).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from tracker.chain import marginal_information, motion_basis
from tracker.io.readers import WithChroma, reduced
from tracker.landmarks.body_landmarks import TRUNK_TURN, trunk
from tracker.model import Model
from tracker.status import HELD, LOST, TRACKED, UNCERTAIN
from tracker.tracking import motion_prior
from tracker.tracking.colours import colour_bins, colour_grids, colour_reduction
from tracker.tracking.cue import Cue, Frame, Iteration
from tracker.tracking.cues import CUES
from tracker.tracking.edge_cue import EdgeCue, reductions, smooth
from tracker.tracking.held import held_codes, outline_motion
from tracker.tracking.keypoint_cue import KeypointCue
from tracker.tracking.lead import Lead
from tracker.tracking.measure import Statistics
from tracker.tracking.motion_model import LATENESS, MODELS, constant_velocity, motion_since, views_at
from tracker.tracking.outline import sample_outlines
from tracker.tracking.ownership import Ownership
from tracker.tracking.person import PersonMasks
from tracker.tracking.rig import Rig
from tracker.tracking.settings import DYNAMICS, Settings, scaled_to
from tracker.tracking.solve import hold_kernel, narrowing, update_kernel
from tracker.tracking.workspace import Inspection, Workspace

C = TypeVar("C")


@dataclass(frozen=True)
class FrameResult:
    """A frame as tracked: its ``poses`` (N, 4, 4), ``status`` (:mod:`tracker.status`), the edges' robust mean offset
    ``residual`` (pixels), the ``share`` of its outline ``samples`` that found an edge and their number; which parts the
    images hold, ``held`` (N,) int8 (:data:`tracker.status.HELD`, ...; :mod:`tracker.tracking.held`); and, from a
    tracker that is ``measuring``, what its cues said of each component's pose (:meth:`Tracker.measured`), which a
    smoother over the whole recording weighs it by."""

    poses: np.ndarray
    status: int
    residual: float
    share: float
    samples: int
    held: np.ndarray
    information: np.ndarray | None = None


class Tracker:
    """Tracks one body in a fixed rig, frame after frame."""

    def __init__(self, model: Model, cameras, initial_poses: np.ndarray, settings: Settings = Settings()):
        if settings.motion.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {DYNAMICS}")
        self.model, self.cameras = model, list(cameras)
        self.rig = Rig.from_cameras(cameras)
        self.settings = settings = scaled_to(settings, int(self.rig.size.min(axis=1).max()))
        n, st = model.size, settings.solve
        self.prior = np.ascontiguousarray(
            np.broadcast_to(np.diag(np.array([st.prior_translation] * 3 + [st.prior_rotation] * 3, float)), (n, 6, 6))
        )
        self.floor = self.prior.copy()  # the solve's fixed prior, which the Kalman filter's replaces (motion_model)
        self.basis = motion_basis(model.constraint_projector, model.constraint_rows)
        self.measuring = False  # whether step gives each frame's information (measured): a smoother will read it
        self.judging: Workspace | None = None  # judged's buffers over the frame just tracked, made when first asked
        self.reduction = reductions(settings, cameras)
        self.search_size = self.rig.size // self.reduction[:, None]  # each camera's image as the edge search reads it
        reach = max(settings.outline.search_range, settings.outline.final_search_range)
        self.work = Workspace.around(
            np.zeros((len(cameras), *self.search_size[:, ::-1].max(axis=0)), np.uint8),
            Ownership(model, self.rig, settings.outline.capacity, reach),
        )
        self.retry = self.work.spare(self.work.images)  # a lead's try (Lead.retry): the same images, colours, clock
        self.retry.bins, self.retry.times = self.work.bins, self.work.times
        self.hidden = np.zeros(n, bool)  # the parts hidden from every view in this frame (step)
        self.still = np.zeros((n, 6))
        self.lateness = np.zeros(len(cameras))  # frames each view of this frame was captured after it (step)
        self.poses = model.coerce(initial_poses)
        self.cues: tuple[Cue, ...] = tuple(kind(self) for kind in CUES)
        self.landmarks = next(cue for cue in self.cues if isinstance(cue, KeypointCue))
        self.person = PersonMasks(model, cameras, colour_grids(self.rig.size, settings.images.work_side), settings)
        self.lead = Lead(model, self.landmarks.component, self.person.legs)
        self.trunk = trunk(model, self.landmarks.component)
        self.dynamics = MODELS[settings.motion.dynamics]()
        self.restart(initial_poses)
        self.sampled_poses = self.poses

    def with_cameras(self, cameras) -> Tracker:
        """A tracker for the rig ``cameras`` that goes on from this one: the same model and (pixel-scaled)
        settings, from the current poses, with its motion (:class:`~tracker.tracking.motion_prior.Motion`) and the
        keypoints' learnt noise (:class:`~tracker.tracking.landmark_noise.LandmarkNoise`, in the old rig's pixels),
        each carried whole; buffers and timings start afresh."""
        other = Tracker(self.model, cameras, self.poses, self.settings)
        other.motion, other.landmarks.noise = self.motion, self.landmarks.noise
        return other

    def restart(self, poses: np.ndarray) -> None:
        """Go on from ``poses`` (coerced) as from a first pose: no motion carried over, the motion model started
        afresh about them, and every cue's learning forgotten (:meth:`tracker.tracking.cue.Cue.restart`)."""
        for cue in self.cues:
            cue.restart()
        self.poses = self.anchor = self.model.coerce(poses)
        self.motion = self.dynamics.start(self)
        self.start = self.poses  # the poses the frame in hand started from: the last frame's (step)

    def cue(self, kind: type[C]) -> C:
        """The tracker's cue of class ``kind``."""
        return next(cue for cue in self.cues if isinstance(cue, kind))

    def warm_up(self) -> None:
        """Run every kernel once on a blank frame (compiles them, or loads numba's cache) and restore the state."""
        poses, anchor = self.poses.copy(), self.anchor
        constant_velocity(poses, poses, self.settings.motion.damping)
        self.iterate(0)
        self.iterate(1)
        for cue in self.cues:
            cue.warm_up(self)
        self.poses, self.anchor = poses, anchor

    def smooth(self, image: np.ndarray) -> np.ndarray:
        """The edge search's input: a grey image reduced and smoothed by a Gaussian of ``blur_sigma`` pixels
        (:func:`tracker.tracking.edge_cue.smooth`).  Thread-safe, so reader threads can run it beside the tracker
        (``step(..., smoothed=True)``)."""
        return smooth(image, self.settings.edges.blur_sigma, self.settings.images.work_side)

    def bin_colours(self, chroma: np.ndarray) -> np.ndarray:
        """The colour bins (H', W') int16 of a half-size colour image, reduced as the region cue reads it
        (:func:`tracker.tracking.colours.colour_reduction`, :func:`tracker.tracking.colours.colour_bins`).
        Thread-safe, so reader threads can run it beside the tracker (``chroma=tracker.bin_colours`` to
        :func:`tracker.io.recording.frames`)."""
        chroma = reduced(chroma, colour_reduction(min(chroma.shape[:2]), self.settings.images.work_side))
        bins = np.empty(chroma.shape[:2], np.int16)
        colour_bins(chroma, bins)
        return bins

    def see_person(self, masks: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Take each camera's person mask for the frame to track (:meth:`tracker.tracking.person.PersonMasks.see`)."""
        self.person.see(masks, self.poses)

    def load_images(self, images, smoothed: bool = False, work: Workspace | None = None) -> None:
        """Copy one grey image per camera (with its colour, :class:`tracker.io.readers.WithChroma`, if it has one)
        into the frame buffer of ``work`` (default: the tracker's), reduced and smoothed (:meth:`smooth`) unless
        ``smoothed`` says they already are.  A frame is in colour when every camera's is and none is of one colour
        (a camera's dropped frame, which the region cue would read as the background everywhere)."""
        work = self.work if work is None else work
        started = time.perf_counter()
        coloured = True
        for k, image in enumerate(images):
            if isinstance(image, WithChroma):
                bins = image.chroma if image.chroma.ndim == 2 else self.bin_colours(image.chroma)  # 2-D: binned in a
                # reader thread already
                h, w = bins.shape
                work.bins[k, :h, :w] = bins
                image = image.image
                coloured &= bool(bins.min() != bins.max())
            else:
                coloured = False
            searched = image if smoothed else self.smooth(image)
            h, w = searched.shape
            work.images[k, :h, :w] = searched
        work.coloured = coloured and len(images) > 0
        work.times.add("grey", started)

    def search_range(self, iteration: int) -> int:
        """Coarse to fine when final_search_range > 0 (:func:`tracker.tracking.solve.narrowing`)."""
        outline, iterations = self.settings.outline, self.settings.solve.iterations
        if outline.final_search_range <= 0 or iterations < 2:
            return outline.search_range
        step = min(iteration, iterations - 1)
        return narrowing(outline.search_range, outline.final_search_range, step=step, steps=iterations)

    def iterate(self, iteration: int = 0) -> Statistics:
        """One IRLS iteration at the current poses: sample (every ``resample_every``-th iteration; between, each
        sample moves along its normal by its Jacobian row times its component's motion since), limit the searches,
        ask every cue, solve, update, coerce; the edge search's statistics."""
        work, count = self.work, self.settings.solve.iterations
        search_range = self.search_range(iteration)
        resampled = iteration % max(self.settings.outline.resample_every, 1) == 0
        if resampled:
            self.sample(work, self.poses, search_range)
            self.sampled_poses = self.poses
        twist = self.still if resampled else motion_since(self.sampled_poses, self.poses)
        now = Iteration(iteration, count, search_range, resampled, twist)
        started = time.perf_counter()
        work.information[:] = 0.0
        work.eta[:] = 0.0
        if now.last:
            work.evidence[:] = 0.0
            work.seen[:] = False
        for cue in self.cues:
            before = work.information.copy() if now.last else None
            cue.add(self, work, now)
            if before is not None:
                evidence = cue.evidence(self, work, work.information - before)
                work.seen |= evidence.any(axis=(1, 2))
                if cue.places:
                    work.evidence += evidence
            started = work.times.add(cue.stage, started)
        self.poses = self.solved(work.information, work.eta, prior=self.prior, poses=self.poses)
        work.times.add("solve", started)
        assert work.statistics is not None  # the edge cue's
        return work.statistics

    def solved(self, information: np.ndarray, eta: np.ndarray, *, prior: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """``poses`` after one solve of ``information`` and ``eta`` with ``prior`` about the anchor, the trunk held
        near rest (:meth:`hold_trunk`), stepped and coerced (:func:`tracker.tracking.solve.update_kernel`)."""
        m = self.model
        if self.settings.solve.trunk_hold > 0:
            self.hold_trunk(information, eta, poses)
        joints = (m.parent, m.constraint, m.constraint_projector, m.constraint_rows, m.rest, m.joint_type, m.axis)
        limits = (m.lower, m.upper, m.twist, self.settings.solve.max_turn)
        return update_kernel(information, eta, prior, poses, self.anchor, *joints, *limits)

    def hold_trunk(self, information: np.ndarray, eta: np.ndarray, poses: np.ndarray) -> None:
        """Where a trunk joint (:func:`tracker.landmarks.body_landmarks.trunk`: the torso's on the pelvis) is turned
        more than :data:`~tracker.landmarks.body_landmarks.TRUNK_TURN` from rest, pull its parent towards the turn that
        brings it back to that, ``trunk_hold`` per rad^2 (:func:`tracker.tracking.solve.hold_kernel`): the pelvis's
        pitch about the hips barely moves its outline or the landmarks, and left to drift it folds the trunk to its
        limit (docs/keypoints.md, "The trunk held near rest")."""
        m, hold = self.model, self.settings.solve.trunk_hold
        hold_kernel(information, eta, poses, self.trunk, m.parent, m.rest, TRUNK_TURN, hold)

    def seen(self, poses: np.ndarray) -> np.ndarray:
        """Each camera's view of ``poses`` (C, N, 4, 4): the body at that view's capture time, ``poses`` moved on by
        its :attr:`lateness` in frames of their motion since the last frame's (:attr:`start`,
        :func:`tracker.tracking.motion_model.views_at`); the same poses in every view when the views are on time."""
        if not self.lateness.any():
            return np.ascontiguousarray(np.broadcast_to(poses, (len(self.lateness), *poses.shape)))
        return views_at(np.ascontiguousarray(poses), motion_since(self.start, poses), self.lateness)

    @property
    def gains(self) -> np.ndarray:
        """How far each camera's view moves (C,) as the frame's poses move: 1 + its :attr:`lateness`, since a view
        l frames late moves with the poses and with their motion since the last frame, l times it (:meth:`seen`);
        its Jacobians are scaled by it."""
        return 1.0 + self.lateness

    def sample(self, work: Workspace, poses: np.ndarray, search_range: int) -> None:
        """Sample the visible outlines at ``poses`` into ``work`` and limit each one's search (ownership); the parts
        hidden in a view get an empty search and no region line there."""
        s, outline = work.samples, self.settings.outline
        started = time.perf_counter()
        sample_outlines(self.model, self.seen(poses), self.rig, spacing=outline.spacing, samples=s, placed=work.placed)
        if self.lateness.any():
            s.jacobian[: s.count] *= self.gains[s.camera[: s.count], None]
        started = work.times.add("outline", started)
        if outline.ownership:
            depths = self.settings.region.on and work.coloured
            work.lo, work.hi = work.ownership.limits(work.placed, s, search_range, depths=depths)
        else:
            work.lo, work.hi = work.ownership.lo[: s.count], work.ownership.hi[: s.count]
            work.lo[:], work.hi[:] = -search_range, search_range
            work.ownership.outside[: s.count] = -1
            work.ownership.depth[: s.count] = search_range + 1
        work.outside, work.depth = work.ownership.outside[: s.count], work.ownership.depth[: s.count]
        hidden = self.hidden[None, :] | self.person.off_mask
        if hidden.any():  # no edge or colour weight: an empty search, no region line
            hid = hidden[s.camera[: s.count], s.component[: s.count]]
            work.lo[hid], work.hi[hid], work.outside[hid] = 1, 0, -2
        work.times.add("ownership", started)

    def inspect(self, images=None, *, smoothed=False, poses=None, search_range: int | None = None) -> Inspection:
        """Sample and measure every outline as the last iteration would (or with ``search_range``): at ``poses`` if
        given (else the current ones), in ``images`` if given (one grey image per camera, rig order, already
        :meth:`smooth`-ed if ``smoothed``; else the frame just tracked).

        A query: it searches in buffers of its own (:meth:`Workspace.spare
        <tracker.tracking.workspace.Workspace.spare>`) and leaves the tracker as it was (its poses, the frame's
        images, its motion and what its cues learnt), so a viewer may inspect with the tracker it shows, also from a
        thread of its own while the tracker steps (given ``images`` and ``poses``)."""
        work, _ = self._inspected(images, smoothed, poses, search_range)
        return self._inspection(work, *EdgeCue.read(work))

    def inspect_cues(self, images=None, *, smoothed=False, poses=None, search_range=None) -> dict[str, Inspection]:
        """:meth:`inspect`, and from the same sampling each cue's reading of each sample in place of its edge
        (:meth:`tracker.tracking.cue.Cue.inspect`), by the cue's name; a cue that reads nothing per sample is left
        out."""
        work, _ = self._inspected(images, smoothed, poses, search_range)
        found = {cue.name: cue.inspect(self, work) for cue in self.cues}
        return {name: self._inspection(work, *read) for name, read in found.items() if read is not None}

    def judged(self, images=None, *, poses: np.ndarray, smoothed: bool = False) -> FrameResult:
        """The frame's result at ``poses`` as they stand, without moving them: one measurement of their outlines in
        ``images`` (else the frame just tracked, in buffers kept for these queries) as the last iteration would search
        them (:meth:`inspect`), the share of their samples that found an edge, their robust mean offset and the status
        those give.  A query, like :meth:`inspect`, from the thread that steps the tracker."""
        if images is None and self.judging is None:
            self.judging = self.work.spare(self.work.images)
        work, stats = self._inspected(images, smoothed, poses, None, work=None if images is not None else self.judging)
        held = self.held(work.information, work, seen=np.asarray(work.information.any(axis=(1, 2))))
        share, status = self.judge(stats, work, held)
        return FrameResult(np.array(poses, copy=True), status, stats.residual, share, stats.visible, held)

    def _inspected(
        self, images, smoothed: bool, poses, search_range, work: Workspace | None = None
    ) -> tuple[Workspace, Statistics]:
        """A spare workspace (``work``, else a new one) in which the outlines at ``poses`` (else the current ones) are
        sampled and their edges searched in ``images`` (else the frame just tracked) over ``search_range`` (else the
        last iteration's), and that search's statistics."""
        frame = self.work.images
        if work is None:
            work = self.work.spare(frame if images is None else np.zeros_like(frame))
        if images is not None:
            self.load_images(images, smoothed, work)
        if search_range is None:
            search_range = self.search_range(self.settings.solve.iterations - 1)
        self.sample(work, self.poses if poses is None else poses, search_range)
        return work, EdgeCue.measure(self, work, search_range=search_range, twist=self.still)

    @staticmethod
    def _inspection(work: Workspace, offset: np.ndarray, weight: np.ndarray) -> Inspection:
        """The :class:`~tracker.tracking.workspace.Inspection` of the samples in ``work`` with each one's ``offset``
        and ``weight``."""
        s, n = work.samples, work.samples.count
        assert work.lo is not None and work.hi is not None  # set by sample()
        camera, component, pixel, normal, quadric, point, jacobian = (
            a[:n].copy() for a in (s.camera, s.component, s.pixel, s.normal, s.quadric, s.point, s.jacobian)
        )
        lo, hi = work.lo.copy(), work.hi.copy()
        return Inspection(camera, component, pixel, normal, lo, hi, offset, weight, quadric, point, jacobian)

    def step(self, images, *, smoothed=False, dt: float | None = None, keypoints=None, late=None) -> FrameResult:
        """Track one frame given one grey image per camera (rig order), already :meth:`smooth`-ed or not.

        ``dt``: seconds since the previous frame (default ``1 / frame_rate``).  ``keypoints``: the frame's landmarks,
        (pixels (C, 33, 2), confidence (C, 33)), fused with the edges in every iteration
        (:class:`~tracker.tracking.keypoint_cue.KeypointCue`).  ``late``: seconds (C,) each camera's image was
        captured after the frame's time (a rig that is not frame-locked, :class:`tracker.io.pairing.Pairing`): each
        view's outlines and landmarks are then placed at the poses moved on by that many frames (of ``dt``, at most
        :data:`~tracker.tracking.motion_model.LATENESS`) of their motion since the last frame, and its Jacobians
        scaled to match (:meth:`seen`, :attr:`gains`, docs/sync.md).
        """
        st = self.settings
        frame = Frame(keypoints)
        self.hidden = np.zeros(self.model.size, bool)
        for cue in self.cues:
            hidden = cue.prepare(self, frame)
            if hidden is not None:
                self.hidden |= hidden
        self.load_images(images, smoothed)
        current = self.start = self.poses
        interval = dt if dt is not None and dt > 0 else 1.0 / st.motion.frame_rate  # seconds between the frames
        late = np.zeros(len(self.rig.names)) if late is None else np.asarray(late, float) / interval
        self.lateness = np.clip(late, -LATENESS, LATENESS)
        predicted = self.dynamics.predict(self, current, dt)
        self.anchor = self.poses
        for iteration in range(st.solve.iterations):
            stats = self.iterate(iteration)
        landmarks = self.landmarks.frame
        if landmarks is not None and st.keypoints.lead > 0:
            stats = self.lead.retry(self, stats, landmarks)
        dragged = self.landmarks.dragged(self)
        if dragged:
            self.poses = self.anchor.copy()
        self.dynamics.correct(self, predicted)
        self.motion = dataclasses.replace(self.motion, previous=current)
        held = self.held(self.work.evidence, self.work, seen=self.work.seen)
        share, status = self.judge(stats, self.work, held)
        if dragged and status == TRACKED:
            status = UNCERTAIN  # and nothing learnt from an image the pose was not tracked in
        for cue in self.cues:
            cue.learn(self, status, kept=not dragged)
        measured = self.measured() if self.measuring else None
        return FrameResult(self.poses.copy(), status, stats.residual, share, stats.visible, held, measured)

    def measured(self) -> np.ndarray:
        """What the last solve's cues said of each component's pose, as the information (N, 2, 3, 3) of a weighted
        least-squares estimate, per block (:func:`tracker.tracking.motion_prior.block_information`: the world
        translation, then the rotation in body coordinates): each component's C_i from its cues (the workspace's
        information less the prior added about the prediction) over sigma0_i^2, the variance of unit weight of its
        edge residuals (:func:`tracker.tracking.motion_prior.variance_factor`; 1 without any edge), plus the solve's
        fixed prior, and what the others' say of it through the joints (:func:`tracker.chain.marginal_information`)."""
        work, n, m = self.work, self.work.samples.count, self.model
        scale = motion_prior.variance_factor(
            work.samples.component[:n], work.offset[:n], work.weight[:n], n_components=m.size
        )
        data = (work.information - self.prior) / scale[:, None, None] + self.floor
        joint = marginal_information(data, parent=m.parent, poses=self.poses, basis=self.basis)
        return motion_prior.block_information(joint, self.poses)

    def held(self, evidence: np.ndarray, work: Workspace, *, seen: np.ndarray) -> np.ndarray:
        """Which parts the evidence (N, 6, 6) of the cues that place them holds, per the motion of their outline
        samples in ``work``, the parts ``seen`` (N,) bool by any cue (N,) int8
        (:func:`tracker.tracking.held.held_codes`)."""
        s = work.samples
        assert work.lo is not None and work.hi is not None  # set by sample()
        motion = outline_motion(s.jacobian, s.component, work.lo, work.hi, s.count, self.model.size)
        return held_codes(evidence, motion, within=self.settings.status.held_within, seen=seen)

    def judge(self, stats: Statistics, work: Workspace, held: np.ndarray) -> tuple[float, int]:
        """The share of all the samples that found an edge in the measurement ``stats`` (of ``work``), and the frame
        status that the parts ``held`` (N,) by the images give: the share of their samples that found an edge, the
        robust mean offset of those edges and how many of the parts they are (:meth:`status`).  The parts the images
        do not hold (a leg behind a table) are left to the prior and do not judge the frame."""
        share = stats.found / stats.visible if stats.visible else 0.0
        count = work.samples.count
        chosen = held[work.samples.component[:count]] == HELD
        offset, weight = work.offset[:count][chosen], work.weight[:count][chosen]
        found = ~np.isnan(offset)
        found_share = float(found.mean()) if len(found) else 0.0
        sum_w = weight[found].sum()
        residual = float((weight[found] * np.abs(offset[found])).sum() / sum_w) if sum_w > 0 else float("nan")
        parts = float(np.mean(held == HELD)) if len(held) else 0.0
        return share, self.status(found_share, residual, parts=parts)

    def status(self, share: float, residual: float, *, parts: float = 1.0) -> int:
        """The frame's status from the ``share`` of the held parts' samples that found an edge, the robust mean offset
        ``residual`` (pixels; NaN: none found) of those edges and the share of the ``parts`` the images hold
        (:class:`~tracker.tracking.settings.StatusSettings`)."""
        st = self.settings.status
        if share < st.lost_share or not residual <= st.lost_residual or parts < st.lost_held:
            return LOST
        if share < st.uncertain_share or residual > st.uncertain_residual or parts < st.uncertain_held:
            return UNCERTAIN
        return TRACKED
