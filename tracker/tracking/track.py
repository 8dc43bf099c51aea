"""The frame loop (docs/method-tracking.md, section 6): render, measure, solve, update, coerce.

Per frame the poses are predicted from the motion model (``Settings.dynamics``: none, constant
velocity, or the second-order Kalman filter of :mod:`tracker.tracking.motion_prior`), then each IRLS
iteration samples the visible outlines in every camera, measures their edges,
adds a weak Gaussian prior ``P = diag(lt I3, lr I3)`` about the predicted pose
(so that every ``C_i`` is invertible, section 3, and the iterations of a frame
cannot drift along directions the images do not observe; with the Kalman filter the
information of its predicted covariance, at least P, per component), solves the whole tree for one twist per
component (section 4), applies ``E_i <- E_i exp(alpha_i)`` and coerces the
joints exact (section 5).  Before measuring, each sample's search is cut half way
to the next predicted edge along its line that is not its own boundary
(:mod:`tracker.tracking.ownership`), so an image edge is only explained by the nearest
predicted outline that can account for it, and the search range shrinks from
iteration to iteration (coarse to fine).  With landmarks, a limb they place far from where the
edges left it is moved to them and the frame tracked again, kept if that limb's edges fit better
(:meth:`Tracker.lead`, docs/keypoints.md).  The frame's status comes from the share of samples
that found an edge and the robust mean residual.  Where the cameras are not frame-locked, each view sees the poses
moved on to its own capture time, to first order (:meth:`Tracker.seen`, docs/sync.md).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np
from numba import njit

from tracker.chain import coerce_kernel, solve_kernel
from tracker.geometry.se3 import between, exp, exp_so3, log, log_so3
from tracker.io.readers import WithChroma, reduced
from tracker.model import Model
from tracker.status import LOST, TRACKED, UNCERTAIN
from tracker.tracking import motion_prior
from tracker.tracking.guessed import axis_points, bone_lengths, guessed, hidden_parts, leg_landmarks
from tracker.tracking.keypoint_cue import (
    LANDMARKS,
    TRUNK_TURN,
    cue_points,
    keypoint_kernel,
    left_right_pairs,
    limbs,
    placers,
    trunk,
)
from tracker.tracking.landmark_noise import LandmarkNoise
from tracker.tracking.measure import Statistics, component_misfits, measure_kernel, reduction, support
from tracker.tracking.motion_prior import Motion
from tracker.tracking.outline import Placed, Rig, Samples, sample_outlines
from tracker.tracking.ownership import Ownership
from tracker.tracking.person import person_grid
from tracker.tracking.region_cue import (
    COLOURS,
    FACTOR,
    Counts,
    Histograms,
    colour_bins,
    colour_grids,
    colour_reduction,
    learn_kernel,
    line_profiles,
    log_table,
    part_table,
    region_kernel,
)

DYNAMICS = ("none", "constant-velocity", "kalman")
CROSSED_VIEWS = 3  # views in which a left/right pair must fit better swapped to say the tracked limbs crossed over
LEAD_ITERATIONS = 3  # solves of the landmarks alone that move a limb they lead (Tracker.lead)
PIN = 1e6  # the prior's multiple that holds the components a lead does not move at their predicted poses
MISFIT_CAP = 0.3  # share of the body's size beyond which a landmark's misfit counts no more (Tracker.landmark_misfit)
BONE_POINTS = (0.25, 0.5, 0.75)  # where along each bone Tracker.on_person reads the mask


@dataclass(frozen=True)
class Settings:
    """Tracking parameters; the defaults suit 640x480 views of a whole body."""

    iterations: int = 6
    spacing: float = 4.0  # pixels between outline samples
    search_range: int = 20  # pixels searched either side of the outline (first iteration)
    final_search_range: int = 6  # last iteration's range (pixels), shrinking geometrically from search_range; 0 = fixed
    threshold: float = 6.0  # minimum grey-level derivative of an edge (per pixel)
    robust_c: float = 2.0  # IRLS weight w = 1 / (c + |m|), pixels
    prior_translation: float = 1e3  # prior about the predicted pose, per m^2
    prior_rotation: float = 10.0  # per rad^2
    blur_sigma: float = 1.0  # Gaussian smoothing before the edge search, pixels
    dynamics: str = "constant-velocity"  # or "none", or "kalman" (tracker.tracking.motion_prior)
    damping: float = 1.0  # share of the last frame's motion carried into the prediction (constant-velocity)
    # dynamics = "kalman" (tracker.tracking.motion_prior): a second-order Kalman filter per component, translation and
    # rotation blocks apart; it predicts the poses, and the information s' P^-1 of its predicted covariance is the prior
    # about them (prior_translation/prior_rotation become its floor).  The defaults below were tuned on rendered
    # recordings at several frame rates and checked on real footage (docs/motion-models.md); treat them as gains
    # rather than physical truths (docs/method-physics.md, section 5).
    frame_rate: float = 60.0  # frames per second of the recording: the filter's time step is 1 / frame_rate
    kalman_q_translation: float = 3.0  # spectral density of the white-noise acceleration, m^2/s^3
    kalman_q_rotation: float = 100.0  # ... of the angular acceleration, rad^2/s^3
    kalman_noise_scale: float = 1.0  # s: measurement noise V = s' C_i^-1 (C_i the component's edge information)
    kalman_residual_variance: bool = True  # s' = s sigma0_i^2 (sum w m^2 / (n_i - 6) of its fit); False: s' = s
    kalman_decay: float = 3.0  # velocity decay rate gamma, 1/s (damping D = gamma M, docs/method-physics.md, section 3)
    uncertain_share: float = 0.6  # share of samples with an edge below which a frame is uncertain
    lost_share: float = 0.3  # ... and lost
    uncertain_residual: float = 3.0  # robust mean offset (px) above which a frame is uncertain
    lost_residual: float = 6.0  # ... and lost
    capacity: int = 40000  # sample buffer size for all cameras together
    ownership: bool = True  # cut each search half way to the next predicted edge of another boundary
    reference_size: int = 480  # the pixel settings above are for images this many pixels on their short side
    work_side: int = 480  # larger images are searched reduced by the largest integer factor that keeps their short
    # side at least this long (:func:`reduction`; their pixel settings still scale with the full size); 0: never
    resample_every: int = 3  # sample the outlines afresh every k-th iteration; between, move them to first order
    keypoint_weight: float = 3.0  # s: a landmark's weight against an edge sample's (tracker.tracking.keypoint_cue)
    keypoint_confidence: float = 0.3  # landmarks less confident are not used (below 0.5 they are used unchecked)
    keypoint_tolerance: float = 0.015  # detector noise, a share of the body's image size: closer landmarks unused
    keypoint_noise_multiple: float = 1.5  # each landmark's zone grows to this many times its median misfit (0: fixed)
    keypoint_tolerance_max: float = 0.15  # ... but no further: a body that far off is pulled back
    keypoint_reach: float = 0.1  # a landmark's pull fades beyond this share of the body's size past its zone
    keypoint_edge_misfit: float = 0.8  # px: where a component's edges fit worse (median |m|), the joint landmarks it
    # places (keypoint_cue.placers) pull from the floor zone (keypoint_tolerance) with no fade
    keypoint_lead: float = 0.06  # share of the body's image size: where the landmarks at a limb's end lie this far
    # beyond their learnt zone off the tracked limb, the landmarks alone move it to them and the frame is tracked
    # again from there, kept if the limb's edges fit better (Tracker.lead); 0: never
    lead_off_mask: bool = True  # an arm off a view's person mask where the trunk is on it, or a leg off every view's,
    # is led too, however near its landmarks (Tracker.limbs_off_mask)
    hide_guessed: bool = True  # legs whose landmarks triangulate to bones under half the model's are guessed by
    # the detector, hidden (a table): their landmarks are dropped and the parts get no edge or colour weight
    # in that frame (tracker.tracking.guessed); and a leg off the person's mask in a view but on it in another is
    # hidden in that view (Tracker.see_person)
    keypoint_drag: float = 0.05  # share of the body's image size: where the frame's landmarks lie off its tracked
    # poses by this much more than off the poses it was tracked from, the edges dragged the body off them, and the
    # frame keeps those poses (Tracker.dragged); 0: never
    check_prediction: bool = True  # constant velocity: where the frame's landmarks lie nearer the last poses than
    # the moved ones, the last motion is not carried on (Tracker.carried); off live, whose landmarks moved with them
    trunk_hold: float = 100.0  # per rad^2: the pelvis pulled back where the trunk's joint turns beyond
    # keypoint_cue.TRUNK_TURN (Tracker.hold_trunk; docs/keypoints.md, "The trunk held near rest"); 0: never
    max_turn: float = float("inf")  # largest rotation (rad) of a component's step in one iteration, before coercion
    # the region cue (tracker.tracking.region_cue), used where the frames come with their colour (WithChroma)
    region: bool = True  # read the colours along the samples' lines too (--region off: edges alone)
    region_weight: float = 0.6  # lambda: a line's weight is lambda / max(sigma^2, region_sigma^2)
    region_sigma: float = 1.0  # full-size pixels: the smallest standard deviation a line's offset is given
    region_amplitude: float = 0.43  # a: the smoothed step H(x) = 1/2 - a tanh(x / 2s) between inside and outside
    region_slope: float = 0.5  # s, full-size pixels
    region_learning_rate: float = 0.2  # h <- (1 - rate) h + rate h_new per frame
    region_every: int = 2  # use every k-th sample's line (each weighs lambda; 2 at 0.6 weighs what 1 at 0.3 did)
    region_inside: int = 4  # pixels in from the outline whose colours are learnt as the part's
    region_outside: int = 10  # ... and out to which they are learnt as the background's (from 4)
    region_agree: float = 2.0  # pixels: once a part's colours are known, only lines whose offset is this close teach
    region_person: float = 0.6  # how far the region cue trusts the person's mask, where the detector gives one
    # (region_cue.with_person: 0 ignores it, 1 takes its word as final)
    region_margin: int = 2  # half-size pixels a line's scores reach beyond its candidates, for the iterations until
    # the next sampling (region_cue.line_profiles): a part that moves further along the line is scored afresh


def scaled_to(settings: Settings, short_side: int) -> Settings:
    """The settings for images ``short_side`` pixels on their short side: spacing, search ranges and blur
    grow with the image beyond ``reference_size`` (an edge spreads over as many more pixels), and the edge
    threshold, a grey-level derivative per pixel, shrinks by the same factor; smaller images keep them."""
    k = max(1.0, short_side / settings.reference_size)
    if k == 1.0:
        return settings
    return dataclasses.replace(
        settings,
        spacing=settings.spacing * k,
        search_range=round(settings.search_range * k),
        final_search_range=round(settings.final_search_range * k),
        blur_sigma=settings.blur_sigma * k,
        threshold=settings.threshold / k,
        keypoint_edge_misfit=settings.keypoint_edge_misfit * k,
        region_sigma=settings.region_sigma * k,
        region_agree=settings.region_agree * k,
        region_slope=settings.region_slope * k,
        region_inside=max(1, round(settings.region_inside * k)),
        region_outside=max(2, round(settings.region_outside * k)),
        region_margin=round(settings.region_margin * k),
        uncertain_residual=settings.uncertain_residual * k,
        lost_residual=settings.lost_residual * k,
        reference_size=short_side,
    )


def reductions(settings: Settings, cameras) -> np.ndarray:
    """Each camera's :func:`reduction` under ``settings`` (integer (C,)): the factor its images are searched at."""
    return np.array([reduction(int(min(camera.size)), settings.work_side) for camera in cameras], np.int64)


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
    """:func:`smooth` at the blur that a :class:`Tracker` of ``settings`` uses for the images of ``cameras``
    (``blur_sigma`` scaled to their largest short side, :func:`scaled_to`)."""
    sigma = scaled_to(settings, max(min(camera.size) for camera in cameras)).blur_sigma
    return functools.partial(smooth, sigma=sigma, work_side=settings.work_side)


@dataclass(frozen=True)
class FrameResult:
    poses: np.ndarray
    status: int
    residual: float
    share: float
    samples: int


@dataclass(frozen=True)
class Inspection:
    """What the edge search saw at one set of poses (for viewers and the shape fit): per sample its camera,
    component, pixel and normal, the searched interval ``[lo, hi]`` along the normal, the edge offset (NaN if
    none) and the IRLS weight, its ``quadric``, its contour ``point`` (3,) in its component's frame and its
    Jacobian row L (6,) (:class:`tracker.tracking.outline.Samples`)."""

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


@njit(cache=True)
def add_prior(information, eta, prior, poses, anchor):
    """Gaussian prior on each component's pose about the frame's predicted pose ``anchor``.

    With delta_i = log(E_i^-1 E_anchor_i), the twist that would return E_i to
    the prediction, the cost (alpha_i - delta_i)^T P_i (alpha_i - delta_i) adds
    P_i to C_i and P_i delta_i to eta_i (section 3: it also keeps C_i invertible).
    ``prior`` (N,6,6) holds one P_i per component.
    """
    for i in range(poses.shape[0]):
        delta = log(between(poses[i], anchor[i]))
        information[i] += prior[i]
        eta[i] += prior[i] @ delta


@njit(cache=True, nogil=True)
def hold_kernel(information, eta, poses, trunk, parent, rest, turn, weight):
    """For each joint j of ``trunk`` turned from its ``rest`` by more than ``turn`` radians (the rotation vector
    ``bend`` of rest_j^T R_parent^T R_j), add ``weight`` I to its parent i's rotation block of C_i and ``weight``
    times the rotation vector from R_i to the rotation that would leave j turned ``turn`` the same way,
    R_j exp(bend turn / |bend|)^T rest_j^T, to eta_i (body frame, as :func:`add_prior`)."""
    for j in trunk:
        i = parent[j]
        parent_rotation = np.ascontiguousarray(poses[i, :3, :3])
        rotation = np.ascontiguousarray(poses[j, :3, :3])
        rest_j = np.ascontiguousarray(rest[j, :3, :3])
        bend = log_so3(np.ascontiguousarray(rest_j.T) @ np.ascontiguousarray(parent_rotation.T) @ rotation)
        angle = np.sqrt(bend[0] ** 2 + bend[1] ** 2 + bend[2] ** 2)
        if angle <= turn:
            continue
        back = np.ascontiguousarray(exp_so3(bend * (turn / angle)).T)
        within = rotation @ back @ np.ascontiguousarray(rest_j.T)
        pull = log_so3(np.ascontiguousarray(parent_rotation.T) @ within)
        for a in range(3):
            information[i, 3 + a, 3 + a] += weight
            eta[i, 3 + a] += weight * pull[a]


@njit(cache=True, nogil=True)
def update_kernel(
    information,
    eta,
    prior,
    poses,
    anchor,
    parent,
    D,
    projector,
    rows,
    rest,
    joint_type,
    axis,
    lower,
    upper,
    twist_limit,
    max_turn,
):
    """Prior, tree solve, E_i <- E_i exp(s alpha_i) and coercion in one call (sections 3-5).

    ``s = min(1, max_turn / max_i |w_i|)`` scales the whole body's step (all twists alike, so the
    linearised joint constraints still hold) when a component would turn by more than ``max_turn``
    radians (before the coercion, which may turn it a little more): the linearisation only holds
    for small motions."""
    add_prior(information, eta, prior, poses, anchor)
    alpha = solve_kernel(information, eta, parent, D, rows, poses)
    largest = 0.0
    for i in range(poses.shape[0]):
        largest = max(largest, np.sqrt(alpha[i, 3] ** 2 + alpha[i, 4] ** 2 + alpha[i, 5] ** 2))
    if largest > max_turn:
        alpha *= max_turn / largest
    moved = np.empty_like(poses)
    for i in range(poses.shape[0]):
        moved[i] = poses[i] @ exp(alpha[i])
    return coerce_kernel(moved, parent, rest, projector, rows, joint_type, axis, lower, upper, twist_limit)


def narrowing(first: int, last: int, *, step: int, steps: int) -> int:
    """Search range of step ``step`` of ``steps`` narrowing geometrically from ``first`` to ``last``:
    r_i = r_0 (r_last / r_0)^(i / (n - 1)), rounded, at least 1; ``last`` when there is a single step."""
    if steps < 2:
        return last
    return max(1, round(first * (last / first) ** (step / (steps - 1))))


@njit(cache=True, nogil=True)
def motion_since(sampled, current):
    """Each component's body twist log(E_sampled^-1 E_current) since its outline was sampled."""
    out = np.empty((current.shape[0], 6))
    for i in range(current.shape[0]):
        out[i] = log(between(sampled[i], current[i]))
    return out


@njit(cache=True, nogil=True)
def views_at(poses, velocity, lateness):
    """Each camera's poses (C, N, 4, 4): ``poses`` (N, 4, 4) moved on by ``lateness`` (C,) frames of the body
    ``velocity`` (N, 6), the twist of each component per frame, E_k = E exp(l_k v): the body at each view's capture
    time, to first order (docs/sync.md, "Each view at its own time")."""
    out = np.empty((lateness.shape[0], poses.shape[0], 4, 4))
    for k in range(lateness.shape[0]):
        for i in range(poses.shape[0]):
            out[k, i] = poses[i] @ exp(lateness[k] * velocity[i])
    return out


@njit(cache=True, nogil=True)
def constant_velocity(previous, current, damping):
    """Predict E_{t+1} = E_t exp(d log(E_{t-1}^-1 E_t)) for every component (d = damping): :func:`views_at` of a
    single view ``damping`` frames on."""
    return views_at(current, motion_since(previous, current), np.array([damping]))[0]


LATENESS = 0.5
"""Frames a view is moved on by at most (:meth:`Tracker.seen`): pairing leaves each view within half a frame of the
frame's time, where the motion is near enough first order; a view further off (a camera with no nearer frame, at
the ends of a recording) is moved half a frame, since a body carried on for frames at its velocity lands as far
off as the offset put it (docs/sync.md)."""

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
    limits (``ownership``'s buffers, and ``lo``/``hi`` of the samples, set by :meth:`Tracker.sample`); each
    sample's edge offset and IRLS weight (capacity,); the information C_i (N, 6, 6) and eta_i (N, 6) summed from
    them (and from the landmarks, whose misfits per camera the solve leaves in ``misfit`` (C, 33)); each camera's
    half-size colour image as colour bins, ``bins`` (C, H', W'), when the frame came with one in every camera and no
    camera's is of a single colour, as a black frame a camera dropped is (``coloured``; the region cue would read it
    as the background everywhere and shrink every outline there onto nothing, docs/region.md), and
    the region cue's mean and variance per sample (:func:`tracker.tracking.region_cue.region_kernel`).

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
    times: StageTimes
    bins: np.ndarray
    region_mean: np.ndarray
    region_variance: np.ndarray
    coloured: bool = False
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
            StageTimes(),
            np.zeros((len(half), int(half[:, 1].max()), int(half[:, 0].max())), np.int16),
            np.zeros(capacity),
            np.zeros(capacity),
        )

    def spare(self, images: np.ndarray) -> Workspace:
        """Buffers of the same sizes for a search in ``images`` beside this one's (:meth:`Ownership.spare
        <tracker.tracking.ownership.Ownership.spare>`)."""
        return Workspace.around(images, self.ownership.spare())


class Tracker:
    """Tracks one body in a fixed rig, frame after frame."""

    def __init__(self, model: Model, cameras, initial_poses: np.ndarray, settings: Settings = Settings()):
        if settings.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {DYNAMICS}")
        if settings.dynamics == "kalman" and not (
            settings.frame_rate > 0
            and settings.kalman_noise_scale > 0
            and settings.kalman_q_translation >= 0
            and settings.kalman_q_rotation >= 0
            and settings.kalman_decay >= 0
        ):
            raise ValueError(
                "dynamics 'kalman' needs frame_rate > 0, kalman_noise_scale > 0 and "
                "kalman_q_translation, kalman_q_rotation, kalman_decay >= 0"
            )
        self.model = model
        self.cameras = list(cameras)
        self.hidden = np.zeros(model.size, bool)  # the parts hidden from every view in this frame (step)
        self.rig = Rig.from_cameras(cameras)
        settings = scaled_to(settings, int(self.rig.size.min(axis=1).max()))
        self.settings = settings
        n = model.size
        self.prior = np.ascontiguousarray(
            np.broadcast_to(
                np.diag(np.array([settings.prior_translation] * 3 + [settings.prior_rotation] * 3, float)), (n, 6, 6)
            )
        )
        self.reduction = reductions(settings, cameras)
        self.search_size = self.rig.size // self.reduction[:, None]  # each camera's image as the edge search reads it
        height = int(self.search_size[:, 1].max())
        width = int(self.search_size[:, 0].max())
        self.work = Workspace.around(
            np.zeros((len(cameras), height, width), np.uint8),
            Ownership(model, self.rig, settings.capacity, max(settings.search_range, settings.final_search_range)),
        )
        self.retry = self.work.spare(self.work.images)  # a lead's try (:meth:`lead`): the same images, colours, clock
        self.retry.bins, self.retry.times = self.work.bins, self.work.times
        self.restart(initial_poses)
        self.sampled_poses = self.poses
        self.still = np.zeros((n, 6))
        self.lateness = np.zeros(len(cameras))  # frames each view of this frame was captured after it (step)
        self.landmarks = (*cue_points(model), left_right_pairs(LANDMARKS))
        self.placer = placers(model, *self.landmarks[:2])
        self.bone_lengths = bone_lengths(self.poses, *self.landmarks[:2])  # the legs' (tracker.tracking.guessed)
        self.limbs = limbs(model, self.landmarks[0])
        self.trunk = trunk(model, self.landmarks[0])
        top = np.where(self.limbs.any(axis=1), self.limbs.argmax(axis=1), -1)  # breadth-first: the limb's first part
        self.roots = (self.landmarks[0][None, :] == top[:, None]) & (top[:, None] >= 0)  # (K, K): each limb's root
        self.floor = (np.full(len(LANDMARKS), settings.keypoint_tolerance), np.full(len(LANDMARKS), np.inf))
        self.keypoints: tuple[np.ndarray, np.ndarray] | None = None
        self.noise = LandmarkNoise.start(len(LANDMARKS), n, settings.keypoint_tolerance)
        # each camera's colour image as the region cue reads it (region_cue's module docstring): width, height,
        # full-size pixels to one of its own, and its row of the likelihood terms' tables, one per pixel size
        grids = colour_grids(self.rig.size, settings.work_side)
        sizes, row = np.unique(grids[:, 2], return_inverse=True)
        self.grid = np.column_stack([grids, row])
        self.logs = np.stack([log_table(settings.region_amplitude, settings.region_slope / f) for f in sizes])
        factor = grids[:, 2]
        self.counts = Counts.empty(len(cameras), n)  # a frame's colour counts, before they are learnt
        self.margin = np.array([round(settings.region_margin * FACTOR / f) for f in factor], np.int64)
        self.inside = np.array([max(1, round(settings.region_inside / f)) for f in factor], np.int64)
        self.outside = np.array([max(2, round(settings.region_outside / f)) for f in factor], np.int64)
        height, width = int(self.grid[:, 1].max()), int(self.grid[:, 0].max())
        self.person = np.zeros((len(cameras), height, width), np.uint8)  # the person's mask per camera (see_person)
        self.person_trust = np.zeros(len(cameras))  # how far the region cue trusts it: 0 where there is none
        self.legs = hidden_parts(model, self.landmarks[0], leg_landmarks())  # the parts a guessed leg hides
        self.leads_leg = (self.limbs & self.legs[None]).any(axis=1)  # the landmarks that lead a leg (led_limbs)
        self.axis = axis_points(model)  # three points along each quadric (mask_shares)
        self.off_mask = np.zeros((len(cameras), n), bool)  # the legs off the person's mask in each view (see_person)
        self.square = np.full((len(cameras), 3), np.nan)  # where each view's last mask lies (see_person)

    def with_cameras(self, cameras) -> Tracker:
        """A tracker for the rig ``cameras`` that goes on from this one: the same model and (pixel-scaled)
        settings, from the current poses, with its motion (:class:`~tracker.tracking.motion_prior.Motion`) and the
        keypoints' learnt noise (:class:`~tracker.tracking.landmark_noise.LandmarkNoise`, in the old rig's pixels),
        each carried whole; buffers and timings start afresh."""
        other = Tracker(self.model, cameras, self.poses, self.settings)
        other.motion, other.noise = self.motion, self.noise
        return other

    def restart(self, poses: np.ndarray) -> None:
        """Go on from ``poses`` (coerced) as from a first pose: no motion carried over, the motion filter
        (kalman) started afresh about them, and no colours known (those learnt on the way that led astray are the
        room's as often as the body's; the region cue learns them again from the next frame)."""
        cameras, n = len(self.rig.names), self.model.size
        self.histograms = Histograms.empty(cameras, n)
        self.part_table = np.full((cameras, n, COLOURS), np.nan)  # p_f of every colour (region_cue.part_table)
        self.distinct = np.zeros((cameras, n))  # how distinct each part's colours are from its background's
        self.poses = self.model.coerce(poses)
        self.anchor = self.poses
        st = self.settings
        s = st.kalman_noise_scale
        kalman = None
        if st.dynamics == "kalman":
            kalman = motion_prior.initial_state(
                self.poses, position_variance=(s / st.prior_translation, s / st.prior_rotation)
            )
        self.motion = Motion(None, kalman, np.full(self.model.size, float(s)))
        self.start = self.poses  # the poses the frame in hand started from: the last frame's (step)

    def warm_up(self) -> None:
        """Run every kernel once on a blank frame (compiles them, or loads numba's cache) and restore the state."""
        poses, anchor = self.poses.copy(), self.anchor
        constant_velocity(poses, poses, self.settings.damping)
        self.iterate(0)
        self.iterate(1)
        if self.settings.region:  # the colours are learnt into spare histograms, then the tracker's are put back
            learnt = self.histograms, self.part_table.copy(), self.distinct.copy()
            self.histograms = Histograms.empty(*self.histograms.seen.shape)
            colour_bins(np.zeros((2, 2, 3), np.uint8), np.zeros((2, 2), np.int16))
            self.profile_lines(self.work)
            self.add_regions(self.work, self.still)
            self.learn_colours()
            self.histograms, self.part_table, self.distinct = learnt
        component_misfits(self.work.offset, self.work.samples.component, self.work.samples.count, self.model.size)
        self.poses, self.anchor = poses, anchor

    def smooth(self, image: np.ndarray) -> np.ndarray:
        """The edge search's input: a grey image reduced and smoothed by a Gaussian of ``blur_sigma`` pixels
        (:func:`smooth`).

        Thread-safe, so reader threads can run it beside the tracker (``step(..., smoothed=True)``).
        """
        return smooth(image, self.settings.blur_sigma, self.settings.work_side)

    def bin_colours(self, chroma: np.ndarray) -> np.ndarray:
        """The colour bins (H', W') int16 of a half-size colour image, reduced as the region cue reads it
        (:func:`tracker.tracking.region_cue.colour_reduction`, :func:`tracker.tracking.region_cue.colour_bins`).

        Thread-safe, so reader threads can run it beside the tracker (``chroma=tracker.bin_colours`` to
        :func:`tracker.io.recording.frames`)."""
        chroma = reduced(chroma, colour_reduction(min(chroma.shape[:2]), self.settings.work_side))
        bins = np.empty(chroma.shape[:2], np.int16)
        colour_bins(chroma, bins)
        return bins

    def see_person(self, masks: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Take each camera's person mask for the frame to track, ``masks``: (C, S, S) uint8 over squares (C, 3:
        centre x, y and side, full-size pixels; NaN for a camera without one) (:func:`tracker.tracking.person.
        person_grid`), or None: none in any camera.

        With ``hide_guessed``, a leg part (a thigh and every part below it) that lies off the mask of a view at the
        current poses (under half of its axis points on it, of those within the image and the mask's square), where
        some other part lies on it, while another view's mask has it on, is hidden in that view until the view's
        next mask: a table before that camera, whose edges would hold it (docs/keypoints.md, "Legs hidden from one
        view").  Off every view's mask, a leg has strayed rather than hidden, and its edges may bring it back."""
        self.person_trust[:] = 0.0
        if masks is None:
            return
        for k, (view, placed) in enumerate(zip(*masks)):
            if np.isfinite(placed).all() and placed[2] > 0:
                self.person_trust[k] = self.settings.region_person
                w, h, f, _ = self.grid[k]
                self.person[k, :h, :w] = person_grid(view, placed, self.grid[k, :2], factor=f)
                self.square[k] = placed
        masked = np.flatnonzero(self.person_trust > 0).tolist()
        if not self.settings.hide_guessed or not masked:
            return
        shares = np.array([self.mask_shares(camera, self.poses) for camera in masked])
        on = shares >= 0.5
        body = np.asarray(on[:, ~self.legs].any(axis=1))
        for row, camera in enumerate(masked):
            others = np.delete(on, row, axis=0)
            self.off_mask[camera] = self.legs & (shares[row] < 0.5) & body[row] & others.any(axis=0)

    def mask_shares(self, camera: int, poses: np.ndarray) -> np.ndarray:
        """Each component's share (N,) of its axis points (:func:`axis_points`) at ``poses`` that lie on the person's
        mask of view ``camera``, over those within the image and the mask's square; NaN where none is."""
        component, points = self.axis
        world = np.einsum("kij,kj->ki", poses[component, :3, :3], points) + poses[component, :3, 3]
        inside, on = self._on_mask(camera, world)
        pixels = self.cameras[camera].project(world)
        centre_x, centre_y, side = self.square[camera]
        with np.errstate(invalid="ignore"):
            inside &= (np.abs(pixels[:, 0] - centre_x) <= side / 2) & (np.abs(pixels[:, 1] - centre_y) <= side / 2)
        on &= inside
        count = np.bincount(component, weights=inside, minlength=self.model.size)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.bincount(component, weights=on, minlength=self.model.size) / count

    def load_images(self, images, smoothed: bool = False) -> None:
        """Copy one grey image per camera into the frame buffer, reduced and smoothed (:meth:`smooth`) unless
        ``smoothed`` says they already are."""
        self._load(self.work, images, smoothed)

    def _load(self, work: Workspace, images, smoothed: bool) -> None:
        """:meth:`load_images` into the images of ``work``."""
        started = time.perf_counter()
        coloured = True
        for k, image in enumerate(images):
            if isinstance(image, WithChroma):
                bins = image.chroma if image.chroma.ndim == 2 else self.bin_colours(image.chroma)  # 2-D: binned in a
                # reader thread already
                h, w = bins.shape
                work.bins[k, :h, :w] = bins
                image = image.image
                coloured &= bool(bins.min() != bins.max())  # a view of one colour shows nothing (a dropped frame)
            else:
                coloured = False
            searched = image if smoothed else self.smooth(image)
            h, w = searched.shape
            work.images[k, :h, :w] = searched
        work.coloured = coloured and len(images) > 0
        work.times.add("grey", started)

    def search_range(self, iteration: int) -> int:
        """Coarse to fine when final_search_range > 0 (:func:`narrowing` over the iterations)."""
        st = self.settings
        if st.final_search_range <= 0 or st.iterations < 2:
            return st.search_range
        return narrowing(
            st.search_range, st.final_search_range, step=min(iteration, st.iterations - 1), steps=st.iterations
        )

    def iterate(self, iteration: int = 0) -> Statistics:
        """One IRLS iteration at the current poses: sample, limit the searches, measure, solve, update, coerce.

        Every ``resample_every``-th iteration samples the outlines and their search limits afresh; the
        iterations between reuse them, each sample moved along its normal by its Jacobian row times its
        component's motion since (first order, section 3), which costs a few flops instead of a render.
        """
        st, work = self.settings, self.work
        search_range = self.search_range(iteration)
        resampled = iteration % max(st.resample_every, 1) == 0
        if resampled:
            self.sample(work, self.poses, search_range)
            self.sampled_poses = self.poses
            twist = self.still
        else:
            twist = motion_since(self.sampled_poses, self.poses)
        started = time.perf_counter()
        stats = self.measure(work, search_range, twist)
        if self.keypoints is not None:
            self.add_keypoints(*self.keypoints)
        started = work.times.add("measure", started)
        if self.regions:
            if resampled:
                self.profile_lines(work)
            self.add_regions(work, twist, afresh=iteration == st.iterations - 1 and not resampled)
            started = work.times.add("region", started)
        self.poses = self.update(self.poses)
        work.times.add("solve", started)
        return stats

    def update(self, poses: np.ndarray) -> np.ndarray:
        """Prior, tree solve, step and coercion (:func:`update_kernel`) with the information gathered."""
        return self._update(self.work.information, self.work.eta, self.prior, poses)

    def _update(self, information: np.ndarray, eta: np.ndarray, prior: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """:func:`update_kernel` with ``information``, ``eta`` and ``prior`` about the anchor."""
        m, st = self.model, self.settings
        if st.trunk_hold > 0:
            self.hold_trunk(information, eta, poses)
        return update_kernel(
            information,
            eta,
            prior,
            poses,
            self.anchor,
            m.parent,
            m.constraint,
            m.constraint_projector,
            m.constraint_rows,
            m.rest,
            m.joint_type,
            m.axis,
            m.lower,
            m.upper,
            m.twist,
            st.max_turn,
        )

    def hold_trunk(self, information: np.ndarray, eta: np.ndarray, poses: np.ndarray) -> None:
        """Where a trunk joint (:func:`tracker.tracking.keypoint_cue.trunk`: the torso's on the pelvis) is turned more
        than :data:`~tracker.tracking.keypoint_cue.TRUNK_TURN` from rest, pull its parent towards the turn that
        brings it back to that, ``trunk_hold`` per rad^2, into the parent's C_i and eta_i (:func:`hold_kernel`): the
        pelvis's pitch about the hips barely moves its outline (a round ellipsoid) or the landmarks (the hips lie on
        its axis), and left to drift it folds the trunk to its limit (docs/keypoints.md, "The trunk held near
        rest")."""
        m = self.model
        hold_kernel(information, eta, poses, self.trunk, m.parent, m.rest, TRUNK_TURN, self.settings.trunk_hold)

    def seen(self, poses: np.ndarray) -> np.ndarray:
        """Each camera's view of ``poses`` (C, N, 4, 4): the body at that view's capture time, ``poses`` moved on by
        its :attr:`lateness` in frames of their motion since the last frame's (:attr:`start`, :func:`views_at`);
        the same poses in every view when the views are on time."""
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
        """Sample the visible outlines at ``poses`` into ``work`` and limit each one's search (ownership)."""
        s, m, st = work.samples, self.model, self.settings
        started = time.perf_counter()
        sample_outlines(m, self.seen(poses), self.rig, spacing=st.spacing, samples=s, placed=work.placed)
        if self.lateness.any():
            s.jacobian[: s.count] *= self.gains[s.camera[: s.count], None]
        started = work.times.add("outline", started)
        if st.ownership:
            work.lo, work.hi = work.ownership.limits(work.placed, s, search_range, depths=st.region and work.coloured)
        else:
            work.lo = work.ownership.lo[: s.count]
            work.hi = work.ownership.hi[: s.count]
            work.lo[:] = -search_range
            work.hi[:] = search_range
            work.ownership.outside[: s.count] = -1
            work.ownership.depth[: s.count] = search_range + 1
        work.outside = work.ownership.outside[: s.count]
        work.depth = work.ownership.depth[: s.count]
        hidden = self.hidden[None, :] | self.off_mask
        if hidden.any():  # no edge or colour weight: an empty search, no region line
            hid = hidden[s.camera[: s.count], s.component[: s.count]]
            work.lo[hid] = 1
            work.hi[hid] = 0
            work.outside[hid] = -2
        work.times.add("ownership", started)

    @property
    def regions(self) -> bool:
        """Whether the region cue takes part in this frame: it is on, the frame came in colour, and colours have
        been learnt."""
        return self.settings.region and self.work.coloured and self.histograms.ready

    def profile_lines(self, work: Workspace) -> None:
        """Score the region cue's lines at the places just sampled, for this and the next iterations
        (:func:`tracker.tracking.region_cue.line_profiles`)."""
        s, st = work.samples, self.settings
        lo, hi, outside, depth = work.limits()
        work.profiles = line_profiles(
            work.bins,
            self.grid,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            outside,
            depth,
            lo,
            hi,
            max(st.region_every, 1),
            self.part_table,
            self.person,
            self.person_trust,
            self.logs,
            self.margin,
        )

    def add_regions(self, work: Workspace, twist: np.ndarray, afresh: bool = False) -> int:
        """Add the region cue's lines to C_i, eta_i (:func:`tracker.tracking.region_cue.region_kernel`), read from
        their profiles (:meth:`profile_lines`) where the parts moved little since, unless ``afresh`` (the frame's
        last iteration); returns the number of lines used."""
        s, st = work.samples, self.settings
        lo, hi, outside, depth = work.limits()
        assert work.profiles is not None  # set by profile_lines()
        likelihood, start, first, length = work.profiles
        return region_kernel(
            work.bins,
            self.grid,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            s.jacobian,
            outside,
            depth,
            twist,
            lo,
            hi,
            max(st.region_every, 1),
            self.part_table,
            self.person,
            self.person_trust,
            self.distinct,
            self.logs,
            st.region_weight,
            st.region_sigma**2,
            likelihood,
            start,
            first,
            length,
            afresh,
            work.region_mean,
            work.region_variance,
            work.information,
            work.eta,
        )

    def learn_colours(self, rate: float | None = None) -> None:
        """Count the colours along the lines at the current poses into the histograms
        (:func:`tracker.tracking.region_cue.learn_kernel`) and blend them in at ``rate`` (default
        ``region_learning_rate``)."""
        st, work = self.settings, self.work
        s = work.samples
        lo, hi, outside, depth = work.limits()
        started = time.perf_counter()
        learn_kernel(
            work.bins,
            self.grid,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            s.jacobian,
            outside,
            depth,
            motion_since(self.sampled_poses, self.poses),
            lo,
            hi,
            work.region_mean,
            self.histograms.seen,
            st.region_agree,
            self.inside,
            self.outside,
            self.person,
            self.person_trust,
            *self.counts.arrays(),
        )
        h = self.histograms
        h.learn(self.counts, rate=st.region_learning_rate if rate is None else rate)
        part_table(
            h.foreground,
            h.background,
            h.scale,
            h.seen,
            h.seen_background,
            h.own,
            h.own_size,
            h.backed,
            h.newly_backed,
            h.newly_backed_size,
            self.part_table,
            self.distinct,
        )
        work.times.add("region", started)

    def measure(self, work: Workspace, search_range: int, twist: np.ndarray) -> Statistics:
        """Search the edge of every sample in ``work`` (moved by ``twist`` since sampling) in its images and fill
        its C_i, eta_i (measure_kernel); the pass's counts and robust mean offset (NaN where nothing was found)."""
        s, st = work.samples, self.settings
        visible, found, sum_wm, sum_w = measure_kernel(
            work.images,
            self.search_size,
            self.reduction,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            s.jacobian,
            twist,
            search_range,
            st.threshold,
            st.robust_c,
            self.model.size,
            work.offset,
            work.weight,
            work.information,
            work.eta,
            work.lo,
            work.hi,
        )
        return Statistics(visible, found, sum_wm / sum_w if sum_w > 0 else float("nan"))

    def inspect(
        self,
        images=None,
        *,
        smoothed: bool = False,
        poses: np.ndarray | None = None,
        search_range: int | None = None,
    ) -> Inspection:
        """Sample and measure every outline as the last iteration would (or with ``search_range``): at ``poses`` if
        given (else the current ones), in ``images`` if given (one grey image per camera, rig order, already
        :meth:`smooth`-ed if ``smoothed``; else the frame just tracked).

        A query: it searches in buffers of its own (:meth:`Workspace.spare`) and leaves the tracker as it was (its
        poses, the frame's images, its motion and learnt noise), so a viewer may inspect with the tracker it shows,
        also from a thread of its own while the tracker steps (given ``images`` and ``poses``)."""
        work, _ = self._inspected(images, smoothed, poses, search_range)
        n = work.samples.count
        return self._inspection(work, work.offset[:n].copy(), work.weight[:n].copy())

    def judged(self, images, *, poses: np.ndarray, smoothed: bool = False) -> FrameResult:
        """The frame's result at ``poses`` as they stand, without moving them: one measurement of their outlines in
        ``images`` as the last iteration would search them (:meth:`inspect`), the share of their samples that found an
        edge, their robust mean offset and the status those give.  A query, like :meth:`inspect`."""
        _, stats = self._inspected(images, smoothed, poses, None)
        share, status = self.judge(stats)
        return FrameResult(np.array(poses, copy=True), status, stats.residual, share, stats.visible)

    def inspect_cues(
        self, images, *, poses: np.ndarray, search_range: int | None = None
    ) -> tuple[Inspection, Inspection]:
        """:meth:`inspect` of ``images`` (with their colour, :class:`tracker.io.readers.WithChroma`) at ``poses``, and
        from the same sampling the region cue's reading of each sample's line in place of its edge: the posterior
        mean of the outline's offset as the sample's ``offset`` and lambda / max(sigma^2, sigma_min^2) as its
        ``weight`` (:func:`tracker.tracking.region_cue.region_kernel`); NaN and 0 where no line was read (between
        every ``region_every``-th sample, where the line's outside is another part, in a view of one colour) and
        everywhere until colours are learnt (:meth:`teach`).  Returns (edges, region lines)."""
        work, _ = self._inspected(images, False, poses, search_range)
        s, n, st = work.samples, work.samples.count, self.settings
        offset, weight = np.full(n, np.nan), np.zeros(n)
        if st.region and work.coloured and self.histograms.ready:
            self.profile_lines(work)
            self.add_regions(work, self.still, afresh=True)
            offset = work.region_mean[:n].copy()
            read = np.isfinite(offset)
            variance = np.maximum(work.region_variance[:n][read], st.region_sigma**2)
            weight[read] = st.region_weight * self.distinct[s.camera[:n][read], s.component[:n][read]] / variance
        edges = self._inspection(work, work.offset[:n].copy(), work.weight[:n].copy())
        return edges, self._inspection(work, offset, weight)

    def teach(self, images, *, poses: np.ndarray, rate: float, search_range: int | None = None) -> None:
        """Learn the colours of one frame whose ``poses`` are known (a model fit's frames, docs/fit-model.md), mixed
        in at ``rate`` (:meth:`learn_colours`); the tracker is left at ``poses``.  ``images``: one grey image per
        camera with its colour (:class:`tracker.io.readers.WithChroma`); a frame without colour teaches nothing."""
        work = self.work
        self.load_images(images)
        self.poses = self.sampled_poses = self.model.coerce(poses)
        if not work.coloured:
            return
        self.sample(work, self.poses, self.search_range(0) if search_range is None else search_range)
        work.region_mean[: work.samples.count] = np.nan
        if self.regions:  # once colours are known, only the lines that agree with the outline teach
            self.profile_lines(work)
            self.add_regions(work, self.still, afresh=True)
        self.learn_colours(rate)

    def _inspected(
        self, images, smoothed: bool, poses: np.ndarray | None, search_range: int | None
    ) -> tuple[Workspace, Statistics]:
        """A spare workspace in which the outlines at ``poses`` (else the current ones) are sampled and their edges
        searched in ``images`` (else the frame just tracked) over ``search_range`` (else the last iteration's), and
        that search's statistics."""
        frame = self.work.images
        work = self.work.spare(frame if images is None else np.zeros_like(frame))
        if images is not None:
            self._load(work, images, smoothed)
        if search_range is None:
            search_range = self.search_range(self.settings.iterations - 1)
        self.sample(work, self.poses if poses is None else poses, search_range)
        return work, self.measure(work, search_range, self.still)

    @staticmethod
    def _inspection(work: Workspace, offset: np.ndarray, weight: np.ndarray) -> Inspection:
        """The :class:`Inspection` of the samples in ``work`` with each one's ``offset`` and ``weight``."""
        s, n = work.samples, work.samples.count
        assert work.lo is not None and work.hi is not None  # set by sample()
        return Inspection(
            s.camera[:n].copy(),
            s.component[:n].copy(),
            s.pixel[:n].copy(),
            s.normal[:n].copy(),
            work.lo.copy(),
            work.hi.copy(),
            offset,
            weight,
            s.quadric[:n].copy(),
            s.point[:n].copy(),
            s.jacobian[:n].copy(),
        )

    def add_keypoints(self, pixels: np.ndarray, confidence: np.ndarray) -> tuple[int, int]:
        """Add the landmarks' information to the edges' (:func:`tracker.tracking.keypoint_cue.keypoint_kernel`):
        ``pixels`` (C, 33, 2) and ``confidence`` (C, 33) float64, one row per camera of the rig.  A landmark
        whose placing component the edges did not hold in the last frame (:meth:`LandmarkNoise.held
        <tracker.tracking.landmark_noise.LandmarkNoise.held>`) pulls from the floor zone with no fade.  Returns
        (landmarks used, left/right pairs rejected)."""
        st = self.settings
        held = self.noise.held(self.placer, st.keypoint_edge_misfit)
        with np.errstate(divide="ignore"):
            reach = st.keypoint_reach / held
        zone = held * self.noise.tolerance + (1.0 - held) * st.keypoint_tolerance
        return self.pull(
            pixels,
            confidence,
            zone=(zone, reach),
            information=self.work.information,
            eta=self.work.eta,
            misfit=self.work.misfit,
        )

    def pull(
        self, pixels, confidence, *, zone, information, eta, misfit, poses=None, swaps: bool = True
    ) -> tuple[int, int]:
        """Add the pull of the landmarks ``pixels`` (C, K, 2) at ``confidence`` (C, K) at ``poses`` (default: the
        current ones) (:func:`tracker.tracking.keypoint_cue.keypoint_kernel`) to ``information`` and ``eta``, and
        their misfits to ``misfit``, each from its noise zone with its fade, ``zone`` = (zone (K,), reach (K,)); a
        left/right pair that fits better swapped is left out unless ``swaps`` is False."""
        st = self.settings
        component, point, pairs = self.landmarks
        if not swaps:
            pairs = pairs[:0]
        return keypoint_kernel(
            self.seen(self.poses if poses is None else poses),
            self.gains,
            self.rig.camera_from_world,
            self.rig.matrix,
            self.rig.lens,
            self.rig.distortion,
            component,
            point,
            pairs,
            pixels,
            confidence,
            st.keypoint_confidence,
            st.robust_c,
            st.keypoint_weight,
            zone[0],
            zone[1],
            information,
            eta,
            misfit,
        )

    def landmark_misfit(self, poses: np.ndarray, keypoints: tuple[np.ndarray, np.ndarray] | None = None) -> float:
        """How far the frame's landmarks (or ``keypoints``: pixels (C, 33, 2), confidence (C, 33)) lie off ``poses``
        (N, 4, 4): the mean over the usable landmarks of every view of their image distance as a share of the
        body's size there (:func:`tracker.tracking.keypoint_cue.keypoint_kernel`), each counted up to
        :data:`MISFIT_CAP` (a wrong detection weighs no more than a limb that far off); 0 without any."""
        if keypoints is None:
            assert self.keypoints is not None  # the frame's (step)
            keypoints = self.keypoints
        pixels, confidence = (np.ascontiguousarray(array, np.float64) for array in keypoints)
        work, misfit = self.work, np.empty_like(self.work.misfit)
        scratch = (np.zeros_like(work.information), np.zeros_like(work.eta))
        self.pull(
            pixels, confidence, zone=self.floor, information=scratch[0], eta=scratch[1], misfit=misfit, poses=poses
        )
        seen = np.isfinite(misfit)
        return float(np.minimum(misfit[seen], MISFIT_CAP).mean()) if seen.any() else 0.0

    def on_person(self, poses: np.ndarray) -> float:
        """How much of the body at ``poses`` (N, 4, 4) lies on the person's masks of the frame
        (:meth:`see_person`): the share of the points a quarter, a half and three quarters along every bone (a
        joint to its child's) that fall where the mask says the person, averaged over the cameras with a mask; 0
        where none has one.  Outlines find edges on clutter, while the mask is read from the person alone
        (docs/keypoints.md, "Re-seeds judged by the person's mask")."""
        child = np.flatnonzero(self.model.parent >= 0)
        joints = poses[:, :3, 3]
        ends = joints[self.model.parent[child]], joints[child]
        points = np.concatenate([(1.0 - s) * ends[0] + s * ends[1] for s in BONE_POINTS])
        shares = [
            self._on_mask(k, points)[1].sum() / len(points) for k in np.flatnonzero(self.person_trust > 0).tolist()
        ]
        return float(np.mean(shares)) if shares else 0.0

    def _on_mask(self, camera: int, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Which of the points ``world`` (P, 3) project within view ``camera``'s colour grid, and which lie on its
        person mask there (two (P,) bool)."""
        w, h, f, _ = self.grid[camera]
        grid = np.rint((self.cameras[camera].project(world) - (f - 1) / 2.0) / f)
        inside = np.isfinite(grid).all(axis=1) & (grid >= 0).all(axis=1) & (grid[:, 0] < w) & (grid[:, 1] < h)
        on = np.zeros(len(world), bool)
        u, v = grid[inside].astype(np.int64).T
        on[inside] = self.person[camera, v, u] >= 128
        return inside, on

    def carried(self, current: np.ndarray) -> np.ndarray:
        """The frame's prediction under ``constant-velocity`` dynamics: the last frame's poses ``current`` moved on
        by the motion between the two frames before (its ``damping`` share, :func:`constant_velocity`), unless
        (with ``check_prediction``) the frame's landmarks lie nearer ``current`` than the moved poses by more than
        the detector's noise (``keypoint_tolerance`` of the body's size, :meth:`landmark_misfit`); then
        ``current``.  That motion is partly the correction of the frame before's error (a lead, the landmarks'
        pull): at a low frame rate, carried on, it can throw the body a quarter of a metre off before any cue is
        read, and the edges then hold it there (docs/motion-models.md)."""
        st = self.settings
        moved = self.model.coerce(constant_velocity(self.motion.previous, current, st.damping))
        if self.keypoints is None or not st.check_prediction:
            return moved
        if self.landmark_misfit(moved) > self.landmark_misfit(current) + st.keypoint_tolerance:
            return current
        return moved

    def dragged(self) -> bool:
        """Whether the frame's edges and colours dragged the body off its landmarks: they lie off the tracked poses
        by more than ``keypoint_drag`` of the body's size beyond how far they lay off the poses the frame was
        tracked from (its prediction, or a kept lead's, :attr:`anchor`; :meth:`landmark_misfit`).  Behind a table,
        the table top's edges can tip a whole trunk over onto it within one frame's iterations, though every view's
        landmarks say it stands (docs/keypoints.md, "Dragged off the landmarks"); no trunk turns that far in a
        frame, and the frame then keeps the poses it started from."""
        st = self.settings
        if self.keypoints is None or st.keypoint_drag <= 0:
            return False
        return self.landmark_misfit(self.poses) > self.landmark_misfit(self.anchor) + st.keypoint_drag

    def led_limbs(self, pixels: np.ndarray, confidence: np.ndarray) -> tuple[np.ndarray, bool]:
        """The components (N,) bool that the landmarks ``pixels`` at ``confidence`` lead (:meth:`lead`) at the current
        poses: the limbs (:func:`tracker.tracking.keypoint_cue.limbs`) of the landmarks that lie more than
        ``keypoint_lead`` of the body's image size beyond their learnt noise zone
        (:class:`~tracker.tracking.landmark_noise.LandmarkNoise`) off their image, in the median over the views that see
        them (their detections already checked to agree, :mod:`tracker.keypoints.consistency`; one view may be all there
        is: the edges arbitrate, :meth:`lead`), where the landmarks at the limb's root (the shoulder of an arm, the hip
        of a leg) lie within that of theirs: a limb is led from a trunk in place; a trunk off its landmarks is the
        recovery's (:mod:`tracker.keypoints.recovery`), and leading its limbs would hide it from it.

        A left/right pair that fits better swapped in every view that sees it, :data:`CROSSED_VIEWS` or more, says the
        tracked limbs crossed over (a leg taken for the other as they pass): its landmarks, left out of the pull as a
        detector's swap, would then hold nothing (a detector's own swap is one view's, or two's alike from behind).
        Both limbs are led by their landmarks as detected, with the swap check off, however near; returns the led
        components and whether any was led so."""
        st = self.settings
        checked, free = np.empty_like(self.work.misfit), np.empty_like(self.work.misfit)
        scratch = np.zeros_like(self.work.information), np.zeros_like(self.work.eta)
        _, rejected = self.pull(
            pixels, confidence, zone=self.floor, information=scratch[0], eta=scratch[1], misfit=checked
        )
        crossed = np.zeros(checked.shape[1], bool)
        if rejected:  # some pair fits better swapped in some view: where in every view that sees it?
            self.pull(
                pixels, confidence, zone=self.floor, information=scratch[0], eta=scratch[1], misfit=free, swaps=False
            )
            crossed = (np.isfinite(free).sum(axis=0) >= CROSSED_VIEWS) & ~np.isfinite(checked).any(axis=0)
        misfit = np.where(crossed, free, checked)
        seen = np.isfinite(misfit)
        views = seen.sum(axis=0)
        far = np.array([np.median(misfit[seen[:, j], j]) if views[j] else 0.0 for j in range(misfit.shape[1])])
        judged = views >= 1
        off = judged & ((far > st.keypoint_lead + self.noise.tolerance) | crossed)
        placed = judged & ~off
        rooted = self.roots.any(axis=1) & ~(self.roots & ~placed).any(axis=1)
        led = off & rooted
        if st.lead_off_mask:
            somewhere, everywhere = self.limbs_off_mask()
            sure = (confidence >= st.keypoint_confidence).any(axis=0)
            astray = (self.limbs & somewhere[None]).any(axis=1)
            led |= sure & astray & (~self.leads_leg | (self.limbs & everywhere[None]).any(axis=1))
        return self.limbs[led].any(axis=0), bool((off & rooted & crossed).any())

    def limbs_off_mask(self) -> tuple[np.ndarray, np.ndarray]:
        """The parts (N,) bool that lie off the person's mask of some view at the current poses, and those off it in
        every view that judges them: off a view's mask is under half of a part's axis points on it, of those within
        the image and the mask's square (:meth:`mask_shares`), in a view whose mask has the trunk (the parts of no
        limb) on it (half of its points or more, over its parts on average).  A part hidden in that view
        (:meth:`see_person`), or hidden as guessed, is not off it.

        A segmenter's mask covers the limbs that the edges lose: in blur, at a low frame rate, or along one view's ray,
        where the other views' edges are weak and the landmarks within their learnt zones do not pull.  Such a limb is
        led by its landmarks (:meth:`led_limbs`), and the edges arbitrate as for any lead: an arm off the mask of any
        view, a leg only off every view's (a leg off one view's mask and on another's is hidden by a table in that
        view, :meth:`see_person`; docs/keypoints.md, "A limb beyond the edges' reach")."""
        masked = np.flatnonzero(self.person_trust > 0).tolist()
        if not masked:
            return np.zeros(self.model.size, bool), np.zeros(self.model.size, bool)
        shares = np.array([self.mask_shares(camera, self.poses) for camera in masked])
        trunk = shares[:, ~self.limbs.any(axis=0)]
        counted = np.isfinite(trunk)
        with np.errstate(invalid="ignore", divide="ignore"):
            on = np.where(counted, trunk, 0.0).sum(axis=1) / counted.sum(axis=1) >= 0.5
            away = shares < 0.5
        judged = np.isfinite(shares) & on[:, None]
        off = away & on[:, None] & ~self.hidden[None] & ~self.off_mask[masked]
        return off.any(axis=0), (away | ~judged).all(axis=0) & judged.any(axis=0)

    def move_limbs(self, led: np.ndarray, pixels: np.ndarray, confidence: np.ndarray, *, swaps: bool = True) -> None:
        """Move the components ``led`` (N,) bool to the landmarks ``pixels`` at ``confidence``, landmarks alone:
        :data:`LEAD_ITERATIONS` solves of the landmarks on them, from the floor zone with no fade, while the other
        components are held where they are (their prior times :data:`PIN`) and the prior about each step's start
        damps the led ones.  The moved pose becomes the frame's prediction (the anchor).  ``swaps``: as in
        :meth:`pull`."""
        work, component = self.work, self.landmarks[0]
        chosen = np.where((component >= 0) & led[np.maximum(component, 0)], confidence, 0.0)
        prior = np.where(led[:, None, None], self.prior, PIN * self.prior)
        information, eta, misfit = np.empty_like(work.information), np.empty_like(work.eta), np.empty_like(work.misfit)
        for _ in range(LEAD_ITERATIONS):
            self.anchor = self.poses
            information[:] = 0.0
            eta[:] = 0.0
            self.pull(pixels, chosen, zone=self.floor, information=information, eta=eta, misfit=misfit, swaps=swaps)
            self.poses = self._update(information, eta, prior, self.poses)
        self.anchor = self.poses

    def lead(self, stats: Statistics, pixels: np.ndarray, confidence: np.ndarray) -> Statistics:
        """Try again the limbs the edges could not reach, led by the landmarks ``pixels`` at ``confidence``; the
        frame's statistics (``stats`` as tracked, unless the try is kept).

        A limb's edges are searched a few pixels either side of its predicted outline: a limb that moved farther
        since the last frame (a fast swing, a low frame rate, a re-seed that left no velocity) lies beyond them, and
        its edges then hold it on whatever lies within reach, against the landmarks that say where it is (their pull
        is bounded, like an edge sample's).  So where the frame's landmarks still lie far off a limb once tracked
        (:meth:`led_limbs`), that limb is moved to them (:meth:`move_limbs`) and the frame tracked again from there.
        The edges arbitrate, as they do a re-seed (:mod:`tracker.keypoints.recovery`): the led pose is kept only
        when the led components' outlines find their edges closer (:func:`tracker.tracking.measure.support`) than
        the tracked ones did; a detector that is wrong where the edges are right (a faceless mannequin's wrists) is
        then outvoted."""
        st, work = self.settings, self.work
        led, crossed = self.led_limbs(pixels, confidence)
        if not led.any():
            return stats
        tracked, anchor = self.poses, self.anchor

        def fit(buffers: Workspace) -> float:
            """How closely the led components' outlines found their edges in ``buffers``' last measurement."""
            s = buffers.samples
            return support(buffers.offset, s.component, count=s.count, chosen=led, robust_c=st.robust_c)

        before = fit(work)
        self.work, self.retry = self.retry, work  # the try searches in the spare buffers, the frame's kept
        self.work.coloured = work.coloured
        self.move_limbs(led, pixels, confidence, swaps=not crossed)
        for iteration in range(st.iterations):
            again = self.iterate(iteration)
        tried = self.work
        if fit(tried) > before:
            return again
        self.work, self.retry = work, tried  # the edges side with the tracked pose
        self.poses, self.anchor = tracked, anchor
        return stats

    def step(
        self,
        images,
        *,
        smoothed: bool = False,
        dt: float | None = None,
        keypoints: tuple[np.ndarray, np.ndarray] | None = None,
        late: np.ndarray | None = None,
    ) -> FrameResult:
        """Track one frame given one grey image per camera (rig order), already :meth:`smooth`-ed or not.

        ``dt``: seconds since the previous frame (dynamics "kalman" only; default ``1 / frame_rate``).
        ``keypoints``: the frame's landmarks, (pixels (C, 33, 2), confidence (C, 33)), fused with the edges
        in every iteration (:meth:`add_keypoints`).  ``late``: seconds (C,) each camera's image was captured after
        the frame's time (a rig that is not frame-locked, :class:`tracker.io.pairing.Pairing`): each view's outlines
        and landmarks are then placed at the poses moved on by that many frames (of ``dt``, at most
        :data:`LATENESS`) of their motion since the last frame, and its Jacobians scaled to match (:meth:`seen`,
        :attr:`gains`, docs/sync.md).
        """
        st = self.settings
        self.keypoints = None
        if keypoints is not None:
            pixels, confidence = keypoints
            self.keypoints = (np.ascontiguousarray(pixels, np.float64), np.ascontiguousarray(confidence, np.float64))
        self.hidden = np.zeros(self.model.size, bool)
        if self.keypoints is not None and st.hide_guessed and len(self.cameras) >= 2:
            legs = guessed(self.cameras, *self.keypoints, lengths=self.bone_lengths)
            if legs.any():
                self.keypoints = (self.keypoints[0], np.where(legs[None], 0.0, self.keypoints[1]))
                self.hidden = hidden_parts(self.model, self.landmarks[0], legs)
        self.load_images(images, smoothed)
        current = self.poses
        interval = dt if dt is not None and dt > 0 else 1.0 / st.frame_rate  # seconds between the frames
        self.start = current
        late = np.zeros(len(self.rig.names)) if late is None else np.asarray(late, float) / interval
        self.lateness = np.clip(late, -LATENESS, LATENESS)
        if st.dynamics == "constant-velocity" and self.motion.previous is not None:
            self.poses = self.carried(current)
        elif st.dynamics == "kalman":
            inverse = self.predict_kalman(1.0 / st.frame_rate if dt is None else dt)
        self.anchor = self.poses
        for iteration in range(st.iterations):
            stats = self.iterate(iteration)
        if self.keypoints is not None and st.keypoint_lead > 0:
            stats = self.lead(stats, *self.keypoints)
        dragged = self.dragged()
        if dragged:
            self.poses = self.anchor.copy()
        if st.dynamics == "kalman":
            self.correct_kalman(inverse)
        self.motion = dataclasses.replace(self.motion, previous=current)
        work = self.work
        edge_misfit = component_misfits(work.offset, work.samples.component, work.samples.count, self.model.size)
        self.noise = dataclasses.replace(self.noise, edge_misfit=edge_misfit)
        share, status = self.judge(stats)
        if dragged and status == TRACKED:
            status = UNCERTAIN  # and nothing learnt from an image the pose was not tracked in
        if st.region and work.coloured and status != LOST and not dragged:
            self.learn_colours()
        if self.keypoints is not None and status == TRACKED:
            self.noise = self.noise.learnt(
                work.misfit,
                self.noise.held(self.placer, st.keypoint_edge_misfit),
                floor=st.keypoint_tolerance,
                multiple=st.keypoint_noise_multiple,
                ceiling=st.keypoint_tolerance_max,
            )
        return FrameResult(self.poses.copy(), status, stats.residual, share, stats.visible)

    def predict_kalman(self, dt: float) -> np.ndarray:
        """Predict every component ``dt`` ahead independently (:func:`tracker.tracking.motion_prior.predict`), coerce
        the predicted poses onto the joints (the filter's means follow), and set the prior about them to the
        predicted information ``s' P_xx^-1`` (floored at prior_translation/prior_rotation; ``s'`` of the
        previous frame).  Returns the predicted state's ``motion_prior.position_inverse``, which the
        correction reuses."""
        st, motion = self.settings, self.motion
        assert motion.kalman is not None  # dynamics "kalman"
        predicted = motion_prior.predict(
            motion.kalman, dt, q=(st.kalman_q_translation, st.kalman_q_rotation), decay=st.kalman_decay
        )
        self.poses = self.model.coerce(predicted.poses)
        kalman = motion_prior.rereference(predicted, self.poses)
        self.motion = dataclasses.replace(motion, kalman=kalman)
        inverse = motion_prior.position_inverse(kalman)
        self.prior = motion_prior.prior_information(
            kalman, scale=motion.noise_scale, floor=(st.prior_translation, st.prior_rotation), p_xx_inv=inverse
        )
        return inverse

    def correct_kalman(self, inverse: np.ndarray) -> None:
        """Update the filters with the tracked poses and the data information C_i of the last iteration
        (the workspace's ``information`` holds C_i plus the prior added by :func:`add_prior`) over the noise scale
        ``s' = s sigma0_i^2`` (:func:`tracker.tracking.motion_prior.variance_factor` of the same samples); ``inverse``
        is the predicted state's P_xx^-1 that :meth:`predict_kalman` returned."""
        st, motion, work = self.settings, self.motion, self.work
        s = float(st.kalman_noise_scale)
        noise_scale = motion.noise_scale
        if st.kalman_residual_variance:  # without any edge the last frame's values stay
            n = work.samples.count
            noise_scale = s * motion_prior.variance_factor(
                work.samples.component[:n],
                work.offset[:n],
                work.weight[:n],
                n_components=self.model.size,
                fallback=noise_scale / s,
            )
        data = work.information - self.prior
        assert motion.kalman is not None  # dynamics "kalman"
        information = motion_prior.block_information(data, self.poses) / noise_scale[:, None, None, None]
        kalman = motion_prior.correct(motion.kalman, self.poses, information, p_xx_inv=inverse)
        self.motion = dataclasses.replace(motion, kalman=kalman, noise_scale=noise_scale)

    def judge(self, stats: Statistics) -> tuple[float, int]:
        """The share of the samples that found an edge in the measurement ``stats`` and the frame status it and
        their residual give (:meth:`status`)."""
        share = stats.found / stats.visible if stats.visible else 0.0
        return share, self.status(share, stats.residual)

    def status(self, share: float, residual: float) -> int:
        st = self.settings
        if share < st.lost_share or not residual <= st.lost_residual:
            return LOST
        if share < st.uncertain_share or residual > st.uncertain_residual:
            return UNCERTAIN
        return TRACKED
