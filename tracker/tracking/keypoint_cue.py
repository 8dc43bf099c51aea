"""The keypoint cue: 2-D landmarks pulling on model points, summed into the edges' information.

A detected landmark ``d`` (recorded pixels, in camera k) is the image of a point ``X`` fixed in
component i's frame.  With ``u(E_i)`` its predicted image (camera_from_world P_k, the camera's calibrated
lens model, :func:`tracker.geometry.lens.distort`) and ``J = du/dalpha`` (2 x 6) its Jacobian with respect to the
component's body twist, the same chain as an outline sample's row (docs/method-tracking.md, section 3),

    J = J_d (1/Z) [K2 | -(p - c0)] R D(X),   D(X) = [I3 | -[X]x],

the residual ``r = d - u`` adds, per component, summed over landmarks and cameras,

    C_i += w J^T J,   eta_i += w J^T r,   w = s q (e / |r|) / ((c + e) (1 + (e / a)^2)),   e = |r| - t

where ``q`` is the detection's confidence, ``c`` the robust constant (IRLS, as the edges), ``s``
the cue's weight against the edges and ``t`` the detector's noise in that image (a share of the
predicted body's size there): a landmark within ``t`` of its prediction is not used (e <= 0), so a
detector's scatter and bias never pull against the edges, while a body that has drifted off is
pulled back by the excess.  So one tree solve fuses both cues.  The noise is learnt per landmark
(:mod:`tracker.tracking.landmark_noise`): how far the detector's landmark lies from the tracked body's while the
edges hold it, for this detector on this subject.  Where the edges do not hold a limb (the component that places a
joint landmark, :func:`placers`, fitted its outline's edges worse than ``KeypointSettings.edge_misfit`` in the last
frame's last iteration, :func:`tracker.tracking.measure.component_misfits`: it follows clutter, or nothing), the
landmarks it places pull from the floor zone with no fade (``reach`` inf) until they bring it back (docs/keypoints.md,
"Fusion with the edges"); near that limit the zone and the fade pass from one to the other over a span
(:meth:`tracker.tracking.landmark_noise.LandmarkNoise.held`).  Left/right swaps are rejected, not fused: for each
left/right pair seen in a camera, when the two detections fit the predicted images better the other way round (summed
distance), neither is used in that camera, and a pair that fits barely better as detected counts in part
(:data:`SWAP_MARGIN`).  Every one of these choices is continuous in the poses, so that a last-bit change of a pose
changes the solve by about as much (docs/keypoints.md, "The same result on every machine").
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from tracker.geometry.lens import distort
from tracker.landmarks.body_landmarks import LANDMARKS, cue_points, left_right_pairs, placers
from tracker.landmarks.guessed import bone_lengths, guessed, hidden_parts
from tracker.status import TRACKED
from tracker.tracking.cue import Frame, Iteration
from tracker.tracking.landmark_noise import LandmarkNoise
from tracker.tracking.measure import component_misfits
from tracker.tracking.outline import component_row

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.workspace import Workspace

SWAP_MARGIN = 0.02
"""Share of the body's image size by which a left/right pair must fit better as detected than swapped to count
in full (:func:`keypoint_kernel`); below it, its weight falls linearly to zero where the two fit alike."""


@njit(cache=True)
def project_point(k_mat, lens, dist, camera_from_component, point):
    """Recorded pixel (2,) of ``point`` (3,) of a component and its Jacobian (2, 6) with respect to the
    component's body twist, through the lens model ``lens``, ``dist`` (:mod:`tracker.geometry.lens`);
    NaN when the point is behind the camera."""
    e = camera_from_component
    x_cam = e[:3, :3] @ point + e[:3, 3]
    jac = np.zeros((2, 6))
    if x_cam[2] <= 1e-9:
        return np.full(2, np.nan), jac
    depth = x_cam[2]
    px = k_mat[0, 0] * x_cam[0] / depth + k_mat[0, 1] * x_cam[1] / depth + k_mat[0, 2]
    py = k_mat[1, 1] * x_cam[1] / depth + k_mat[1, 2]
    u, v, j00, j01, j10, j11 = distort(k_mat, lens, dist, px, py)
    for row in range(2):
        gx, gy = (j00, j01) if row == 0 else (j10, j11)
        rx, ry, rz = component_row(k_mat, e, px, py, depth, gx, gy)
        jac[row, 0] = rx
        jac[row, 1] = ry
        jac[row, 2] = rz
        jac[row, 3] = point[1] * rz - point[2] * ry
        jac[row, 4] = point[2] * rx - point[0] * rz
        jac[row, 5] = point[0] * ry - point[1] * rx
    return np.array([u, v]), jac


@njit(cache=True, nogil=True)
def keypoint_kernel(
    poses,
    gains,
    camera_from_world,
    matrix,
    lens,
    distortion,
    component,
    point,
    pairs,
    pixels,
    confidence,
    min_confidence,
    robust_c,
    scale,
    tolerance,
    reach,
    information,
    eta,
    misfit,
):
    """Add every usable landmark's w J^T J and w J^T r to ``information`` (N, 6, 6) and ``eta`` (N, 6), each view's
    landmarks placed by the ``poses`` (C, N, 4, 4) of that camera's capture time and its Jacobians scaled by its
    ``gains`` (C,), how far its view moves as the poses move (docs/sync.md).

    ``camera_from_world``, ``matrix``, ``lens`` and ``distortion`` are the rig's
    (:class:`tracker.tracking.rig.Rig`); ``pixels`` (C, K, 2) and ``confidence`` (C, K) are one frame's
    detections; a landmark is used when its component is >= 0, its confidence at least ``min_confidence``, its pixel
    finite, and it is not half of a left/right pair of ``pairs`` (P, 2) that fits better swapped: a pair's weight
    falls from full, where swapping it would lengthen its two residuals by :data:`SWAP_MARGIN` of the body's size or
    more, to zero where swapping would not lengthen them, so that a pair on the fence counts a little rather than all
    or nothing.  Each residual is shrunk by the detector's noise, ``tolerance`` (K,) times the predicted body's size
    in that image (the diagonal of its landmarks' bounding box): a landmark within it is not used, one further is
    weighted by its excess e = |r| - radius, w = s q (e / |r|) / ((c + e) (1 + (e / (reach size))^2)), so its pull
    grows from zero at the zone's edge and fades again beyond ``reach`` (K,) times the body's size (a wrong detection,
    or a body that far off, is left to the recovery; inf: no fade).  ``misfit`` (C, K) receives |r| over the body's
    size for every usable landmark, NaN for the others.  Returns (landmarks used, pairs
    rejected)."""
    cameras, count = pixels.shape[0], pixels.shape[1]
    misfit[:] = np.nan
    used = 0
    rejected = 0
    predicted = np.full((count, 2), np.nan)
    jacobians = np.zeros((count, 2, 6))
    usable = np.zeros(count, np.bool_)
    trust = np.ones(count)
    for k in range(cameras):
        low = np.full(2, np.inf)
        high = np.full(2, -np.inf)
        for j in range(count):
            i = component[j]
            predicted[j] = np.nan
            if i >= 0:
                predicted[j], jacobians[j] = project_point(
                    matrix[k], lens[k], distortion[k], camera_from_world[k] @ poses[k, i], point[j]
                )
                jacobians[j] *= gains[k]
                if np.isfinite(predicted[j, 0]):
                    low = np.minimum(low, predicted[j])
                    high = np.maximum(high, predicted[j])
            usable[j] = (
                i >= 0
                and confidence[k, j] >= min_confidence
                and np.isfinite(pixels[k, j, 0])
                and np.isfinite(pixels[k, j, 1])
                and np.isfinite(predicted[j, 0])
            )
        size = np.sqrt(((high - low) ** 2).sum()) if high[0] >= low[0] else 0.0
        trust[:] = 1.0
        for p in range(pairs.shape[0]):
            a, b = pairs[p, 0], pairs[p, 1]
            if usable[a] and usable[b] and size > 0.0:
                straight = np.linalg.norm(pixels[k, a] - predicted[a]) + np.linalg.norm(pixels[k, b] - predicted[b])
                swapped = np.linalg.norm(pixels[k, a] - predicted[b]) + np.linalg.norm(pixels[k, b] - predicted[a])
                margin = (swapped - straight) / (SWAP_MARGIN * size)
                trust[a] = trust[b] = min(max(margin, 0.0), 1.0)
                if margin <= 0.0:
                    rejected += 1
        for j in range(count):
            if not usable[j] or trust[j] <= 0.0:
                continue
            r = pixels[k, j] - predicted[j]
            length = np.sqrt(r[0] * r[0] + r[1] * r[1])
            if size > 0.0:
                misfit[k, j] = length / size
            radius = tolerance[j] * size
            excess = length - radius
            if radius > 0.0 and excess <= 0.0:
                continue
            share = excess / length if radius > 0.0 else 1.0
            fade = excess / (reach[j] * size) if size > 0.0 else 0.0
            w = scale * trust[j] * confidence[k, j] * share / ((robust_c + excess) * (1.0 + fade * fade))
            jac = jacobians[j]
            information[component[j]] += w * (jac.T @ jac)
            eta[component[j]] += w * (jac.T @ r)
            used += 1
    return used, rejected


MISFIT_CAP = 0.3  # share of the body's size beyond which a landmark's misfit counts no more (KeypointCue.misfit)


class KeypointCue:
    """The detector's landmarks as a cue of the solve (:class:`~tracker.tracking.cue.Cue`): their pull on the model
    points they mark (:func:`keypoint_kernel`), from each landmark's zone of learnt noise
    (:class:`~tracker.tracking.landmark_noise.LandmarkNoise`, :attr:`noise`, carried whole to a tracker for other
    cameras); and the frame's checks against them, by the tracker's motion model (:meth:`misfit`), its lead
    (:mod:`tracker.tracking.lead`) and its drag check (:meth:`dragged`)."""

    name = "keypoints"
    stage = "measure"
    places = False

    def __init__(self, tracker: Tracker):
        model, settings, poses = tracker.model, tracker.settings, tracker.poses
        self.settings = settings.keypoints
        self.robust_c = settings.solve.robust_c
        self.model = model
        self.component, self.point = cue_points(model)
        self.pairs = left_right_pairs(LANDMARKS)
        self.placer = placers(model, self.component, self.point)
        self.bone_lengths = bone_lengths(poses, self.component, self.point)  # the legs' (tracker.landmarks.guessed)
        self.floor = (np.full(len(LANDMARKS), self.settings.tolerance), np.full(len(LANDMARKS), np.inf))
        self.noise = LandmarkNoise.start(len(LANDMARKS), model.size, self.settings.tolerance)
        self.frame: tuple[np.ndarray, np.ndarray] | None = None  # the frame's landmarks: pixels, confidence

    def restart(self) -> None:
        return None

    def warm_up(self, tracker: Tracker) -> None:
        work = tracker.work
        component_misfits(work.offset, work.samples.component, work.samples.count, self.model.size)

    def prepare(self, tracker: Tracker, frame: Frame) -> np.ndarray | None:
        """Take the frame's landmarks; with ``hide_guessed`` and two views or more, the legs the detector guessed
        (:func:`tracker.landmarks.guessed.guessed`) lose their landmarks, and their parts are hidden."""
        self.frame = None
        if frame.keypoints is None:
            return None
        pixels, confidence = (np.ascontiguousarray(array, np.float64) for array in frame.keypoints)
        self.frame = (pixels, confidence)
        if not self.settings.hide_guessed or len(tracker.cameras) < 2:
            return None
        legs = guessed(tracker.cameras, pixels, confidence, lengths=self.bone_lengths)
        if not legs.any():
            return None
        self.frame = (pixels, np.where(legs[None], 0.0, confidence))
        return hidden_parts(self.model, self.component, legs)

    def add(self, tracker: Tracker, work: Workspace, iteration: Iteration) -> None:
        """Add the landmarks' pull to the edges' information.  A landmark whose placing component the edges did not
        hold in the last frame (:meth:`LandmarkNoise.held <tracker.tracking.landmark_noise.LandmarkNoise.held>`)
        pulls from the floor zone with no fade."""
        if self.frame is not None:
            self.add_landmarks(tracker, work, self.frame)

    def add_landmarks(
        self, tracker: Tracker, work: Workspace, keypoints: tuple[np.ndarray, np.ndarray]
    ) -> tuple[int, int]:
        """:meth:`add` of the landmarks ``keypoints``, pixels (C, 33, 2) at confidence (C, 33) float64, into ``work``;
        returns (landmarks used, left/right pairs rejected)."""
        pixels, confidence = keypoints
        st = self.settings
        held = self.noise.held(self.placer, st.edge_misfit)
        with np.errstate(divide="ignore"):
            reach = st.reach / held
        zone = held * self.noise.tolerance + (1.0 - held) * st.tolerance
        return self.pull(
            tracker,
            pixels,
            confidence,
            zone=(zone, reach),
            information=work.information,
            eta=work.eta,
            misfit=work.misfit,
        )

    def learn(self, tracker: Tracker, status: int, *, kept: bool) -> None:
        """Note how closely each component's outline fitted its edges in the frame's last search (how firmly the edges
        hold each landmark's limb), and in a tracked frame learn the landmarks' noise from their misfits."""
        work, st = tracker.work, self.settings
        edge_misfit = component_misfits(work.offset, work.samples.component, work.samples.count, self.model.size)
        self.noise = dataclasses.replace(self.noise, edge_misfit=edge_misfit)
        if self.frame is not None and status == TRACKED:
            self.noise = self.noise.learnt(
                work.misfit,
                self.noise.held(self.placer, st.edge_misfit),
                floor=st.tolerance,
                multiple=st.noise_multiple,
                ceiling=st.tolerance_max,
            )

    def evidence(self, tracker: Tracker, work: Workspace, added: np.ndarray) -> np.ndarray:
        """The information of every landmark seen with confidence, as if each stood for its limb wherever it lies:
        the pull of :meth:`pull` from no zone and with no fade, so that a landmark lying within its zone, which pulls
        nothing, still says that the images see its part."""
        information = np.zeros_like(added)
        if self.frame is not None:
            none = (np.zeros(len(LANDMARKS)), np.full(len(LANDMARKS), np.inf))
            pixels, confidence = self.frame
            scratch = np.zeros_like(work.eta), np.empty_like(work.misfit)
            self.pull(
                tracker, pixels, confidence, zone=none, information=information, eta=scratch[0], misfit=scratch[1]
            )
        return information

    def inspect(self, tracker: Tracker, work: Workspace) -> None:
        return None

    def pull(
        self, tracker: Tracker, pixels, confidence, *, zone, information, eta, misfit, poses=None, swaps: bool = True
    ) -> tuple[int, int]:
        """Add the pull of the landmarks ``pixels`` (C, K, 2) at ``confidence`` (C, K) at ``poses`` (default: the
        tracker's current ones) (:func:`keypoint_kernel`) to ``information`` and ``eta``, and their misfits to
        ``misfit``, each from its noise zone with its fade, ``zone`` = (zone (K,), reach (K,)); a left/right pair
        that fits better swapped is left out unless ``swaps`` is False."""
        pairs = self.pairs if swaps else self.pairs[:0]
        rig = tracker.rig
        return keypoint_kernel(
            tracker.seen(tracker.poses if poses is None else poses),
            tracker.gains,
            rig.camera_from_world,
            rig.matrix,
            rig.lens,
            rig.distortion,
            self.component,
            self.point,
            pairs,
            pixels,
            confidence,
            self.settings.confidence,
            self.robust_c,
            self.settings.weight,
            zone[0],
            zone[1],
            information,
            eta,
            misfit,
        )

    def misfit(
        self, tracker: Tracker, poses: np.ndarray, keypoints: tuple[np.ndarray, np.ndarray] | None = None
    ) -> float:
        """How far the frame's landmarks (or ``keypoints``: pixels (C, 33, 2), confidence (C, 33)) lie off ``poses``
        (N, 4, 4): the mean over the usable landmarks of every view of their image distance as a share of the
        body's size there (:func:`keypoint_kernel`), each counted up to :data:`MISFIT_CAP` (a wrong detection weighs
        no more than a limb that far off); 0 without any."""
        if keypoints is None:
            assert self.frame is not None  # the frame's (prepare)
            keypoints = self.frame
        pixels, confidence = (np.ascontiguousarray(array, np.float64) for array in keypoints)
        work = tracker.work
        misfit = np.empty_like(work.misfit)
        scratch = (np.zeros_like(work.information), np.zeros_like(work.eta))
        self.pull(
            tracker,
            pixels,
            confidence,
            zone=self.floor,
            information=scratch[0],
            eta=scratch[1],
            misfit=misfit,
            poses=poses,
        )
        seen = np.isfinite(misfit)
        return float(np.minimum(misfit[seen], MISFIT_CAP).mean()) if seen.any() else 0.0

    def dragged(self, tracker: Tracker) -> bool:
        """Whether the frame's edges and colours dragged the body off its landmarks: they lie off the tracked poses
        by more than ``drag`` of the body's size beyond how far they lay off the poses the frame was tracked from
        (its prediction, or a kept lead's, the tracker's ``anchor``; :meth:`misfit`).  Behind a table, the table
        top's edges can tip a whole trunk over onto it within one frame's iterations, though every view's landmarks
        say it stands (docs/keypoints.md, "Dragged off the landmarks"); no trunk turns that far in a frame, and the
        frame then keeps the poses it started from."""
        if self.frame is None or self.settings.drag <= 0:
            return False
        return self.misfit(tracker, tracker.poses) > self.misfit(tracker, tracker.anchor) + self.settings.drag
