"""A body model fitted to the person in a recording (docs/fit-model.md).

1. The keypoint detector on frames spread over the recording (:data:`FRAMES` by default); a landmark off the
   detector's segmentation of the person in a view counts as unseen there (:mod:`tracker.landmarks.silhouette`:
   a desk before the legs); the landmarks triangulated frame by frame
   (:func:`tracker.landmarks.triangulation.frame_by_frame`).
2. The joints fitted to them, each frame's pose fitted first (:func:`tracker.shape.from_landmarks.fit_landmarks`).
3. Each frame's pose snapped to its edges with its landmarks (:func:`tracker.seeding.first_pose.snap_to_edges`);
   the frames the edges hold (status not lost) are kept.
4. One round per search range of :data:`RANGES`: the parts' and the room's colours learnt over the kept frames at
   their poses (:meth:`tracker.tracking.region_cue.RegionCue.teach`), every kept frame's outlines measured at its pose
   by their edges and by the region cue's lines (:meth:`tracker.tracking.frame_loop.Tracker.inspect_cues`: where the
   colours change from the part's to the room's, which a pattern inside the outline does not move), then one
   Gauss-Newton step of the shape and every frame's pose together (:func:`tracker.shape.edges.bundle_step`);
   a part is left out of a view where the detector does not see the joints at its ends (:func:`unseen_parts`)
   or where its outline falls off the person's segmentation (:func:`off_person`), and a joint the detector
   rarely sees is held at the given model's place, scaled (:func:`unseen_joints`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker.errors import TrackerInputError
from tracker.io.readers import WithChroma, half_size
from tracker.io.recording import Recording
from tracker.io.recording import frames as frames_of
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.consistency import consistent
from tracker.landmarks.detect_recording import detect_recording
from tracker.landmarks.detector import native_logs_muted
from tracker.landmarks.silhouette import PersonMask, Segmenter
from tracker.landmarks.store import Keypoints
from tracker.landmarks.triangulation import frame_by_frame
from tracker.model import Model, model_from_dict, save_model
from tracker.proportions import sizes
from tracker.seeding.first_pose import SNAP, snap_to_edges
from tracker.shape.edges import FrameRows, bundle_step, frame_rows, moved
from tracker.shape.from_landmarks import fit_landmarks
from tracker.shape.layout import Layout
from tracker.status import LOST
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.region_cue import RegionCue
from tracker.tracking.workspace import Inspection

FRAMES = 40
"""Frames the fit reads by default, spread evenly over the recording: many poses tell the lengths apart."""

RANGES = (16, 14, 12, 10, 10) + (8,) * 10 + (6,) * 15
"""Pixels each edge round searches either side of the outline (for 480-pixel images; scaled like the tracker's):
wide while the shape is far off, then narrower; one round each.  An edge nearer than the outline's true place
(clutter, texture) shortens each step, so the rounds are many and cheap."""

EDGE_PRIOR = 20.0
"""The prior's weight towards the given model scaled by the common scale, in pixels of outline offset per metre
of a joint's place (or per unit of a factor): weak, it only holds what no sample measures."""

SPAN_PRIOR = 1000.0
"""The prior's weight, in pixels per metre, that keeps each joint where its parent's stretch puts it (a part
spans its bone, :meth:`tracker.shape.layout.Layout.prior`): an outline does not show where a joint lies inside
overlapping parts (a shin's end inside the foot, the spine inside the trunk)."""

DAMPING = (1e-3, 1e3)
"""The Levenberg-Marquardt damping's least and largest value: a round whose step left the outlines fitting their
edges worse (robust mean |m|) is undone, and the step taken again ten times more damped; each good one lowers it
threefold."""

JOINT_STEP = 0.05
"""Metres a joint may move in one round: a direction the edges barely see cannot jump on noise."""

FACTOR_STEP = 0.15
"""The most a stretch factor may change in one round."""

FACTORS = (0.6, 1.6)
"""Every stretch factor stays within these multiples of the common scale: the shape stays human."""

STRAY = 3.0
"""A component whose outline fits its edges in a frame this many times worse (median |m|) than the median over
all components and frames is left out of that frame's step."""

SEEN = 0.5
"""A joint landmark's least confidence for the parts at its joint to be fitted in that view."""

RARELY = 0.5
"""A joint whose landmark is seen in fewer than this share of the views of the fitted frames is held."""

ON_PERSON = 0.5
"""A component whose outline samples lie on the person's segmentation in a view less than this share of the time
is left out of that view (:func:`off_person`)."""

MEASURED = 100
"""Samples with an edge, over the frames of the best round, that a component needs to count as measured; the
others keep the given model's proportions, scaled."""


@dataclass(frozen=True)
class ShapeFit:
    """A fitted model: its TOML ``document`` (parsed), the ``layout`` and ``x`` of its shape, the ``start`` x
    from the landmarks, the keypoint frames the landmarks used (``landmark_frames``) and the frames the edges
    held (``edge_frames``), the best robust mean offset in pixels after each edge round (``residuals``) and each
    component's ``samples`` (N,) with an edge at the best round."""

    document: dict
    layout: Layout
    x: np.ndarray
    start: np.ndarray
    landmark_frames: np.ndarray
    edge_frames: np.ndarray
    residuals: tuple[float, ...]
    samples: np.ndarray

    def measured(self) -> np.ndarray:
        """Whether the edges measured each component (N,) bool: :data:`MEASURED` samples or more."""
        return self.samples >= MEASURED


def spread(frame_count: int, count: int) -> np.ndarray:
    """``count`` frame numbers spread evenly over ``frame_count`` frames (all of them when fewer)."""
    return np.unique(np.linspace(0, frame_count - 1, min(count, frame_count)).round().astype(np.int64))


def fit_shape(
    recording: Recording,
    document: dict,
    *,
    frames: int = FRAMES,
    tie_sides: bool = True,
    cache: str | Path | None = None,
    landmark_model: str,
    progress: Callable[..., Iterable] = lambda iterable, total=None: iterable,
    say: Callable[[str], None] = lambda text: None,
) -> ShapeFit:
    """The model TOML ``document`` (parsed) fitted to the person in ``recording`` (module docstring), from
    ``frames`` frames spread over it; detections by ``landmark_model`` cached in ``cache``.
    ``progress(iterable, total=)`` wraps long loops (e.g. a tqdm bar) and ``say`` reports each stage.  One-line
    errors when too few frames show the body."""
    model = model_from_dict(document)
    layout = Layout.of(model, tie_sides=tie_sides)
    step = max(1, recording.frame_count // max(frames, 1))
    say(f"keypoints: detecting the body in one frame of every {step}" if step > 1 else "keypoints: detecting the body")
    keypoints, _ = detect_recording(
        recording, 0, recording.frame_count, step=step, cache=cache, progress=progress, landmark_model=landmark_model
    )
    say("silhouettes: which landmarks lie on the person")
    keypoints, coloured, masks = _on_person(recording, keypoints, step, progress)
    found = frame_by_frame(keypoints, recording.cameras, model)
    say(f"landmarks: {len(found.rows)} of {len(keypoints.frame)} frames show the body in two views or more")
    landmarks = fit_landmarks(layout, document, found.points, frames=keypoints.frame[found.rows], progress=progress)
    model = model_from_dict(layout.document(landmarks.x, document))
    images = [coloured[row] for row in np.searchsorted(keypoints.frame, landmarks.frames)]
    poses, held = [], []
    for k, row in enumerate(progress(np.searchsorted(keypoints.frame, landmarks.frames), total=len(images))):
        marks = consistent(keypoints.rows(slice(row, row + 1)), recording.cameras)[0]
        landmarks_now = (marks.pixels[0], marks.confidence[0])
        greys = [view.image for view in images[k]]
        result = snap_to_edges(model, recording.cameras, landmarks.poses[k], images=greys, keypoints=landmarks_now)
        poses.append(result.poses)
        held.append(result.status != LOST)
    kept = np.flatnonzero(held)
    if len(kept) < 3:
        raise TrackerInputError(
            f"{recording.path}: the edges hold the body in {len(kept)} of {len(images)} frames, the fit needs 3; "
            "give more frames (--frames) or a recording with the whole body in view"
        )
    say(f"edges: the body is held in {len(kept)} of {len(images)} frames")
    start = _State(np.inf, landmarks.x, model, [poses[k] for k in kept], [], np.zeros(model.size, np.int64))
    rows = np.searchsorted(keypoints.frame, landmarks.frames[kept])
    hidden = [unseen_parts(model, keypoints.confidence[row]) for row in rows]
    prior = layout.prior(
        EDGE_PRIOR, EDGE_PRIOR, span_weight=SPAN_PRIOR, held=unseen_joints(model, keypoints.confidence[rows])
    )
    views = [(images[k], masks[row], unseen) for k, row, unseen in zip(kept, rows, hidden)]
    best, residuals = _edge_rounds(layout, document, start, views, prior, recording.cameras, progress)
    return ShapeFit(
        layout.document(best.x, document),
        layout,
        best.x,
        landmarks.x,
        landmarks.frames,
        landmarks.frames[kept],
        residuals,
        best.samples,
    )


@dataclass(frozen=True)
class _State:
    """Where the edge rounds stand: the outlines' robust mean offset ``residual`` (pixels) at shape ``x`` (its
    ``model``) and the frames' ``poses``, the frames' ``rows`` measured there (less the strays, :func:`held_rows`)
    and each component's ``samples`` (N,) that found an edge."""

    residual: float
    x: np.ndarray
    model: Model
    poses: list[np.ndarray]
    rows: list[FrameRows]
    samples: np.ndarray


def _edge_rounds(
    layout: Layout,
    document: dict,
    start: _State,
    views: list[tuple[list[WithChroma], list[PersonMask | None], np.ndarray]],
    prior: np.ndarray,
    cameras: list,
    progress: Callable[..., Iterable],
) -> tuple[_State, tuple[float, ...]]:
    """The best state of the edge rounds from ``start`` (module docstring, step 4) under the ``prior`` rows, and
    each round's residual.  Each frame's ``views`` are its images, the person's masks and the parts (C, N) the
    detector does not see in each view: those are left out, and so are those off the masks (:func:`off_person`)."""
    damping, best, now, residuals = DAMPING[0], start, start, []
    for search in progress(RANGES, total=len(RANGES)):
        tracker = Tracker(now.model, cameras, now.poses[0], SNAP.but(outline=dict(search_range=search)))
        scaled = tracker.settings.outline.search_range  # for the image size
        colours = tracker.cue(RegionCue)
        for k, (pose, (images, _, _)) in enumerate(zip(now.poses, views)):
            colours.teach(
                tracker, images, poses=pose, rate=1.0 / (k + 1), search_range=scaled
            )  # the mean over the frames
        factors = layout.factors(now.x)
        measured, edged = [], []
        for pose, (images, masks, unseen) in zip(now.poses, views):
            read = tracker.inspect_cues(images, poses=pose, search_range=scaled)
            seen_here, lines = read["edges"], read["region"]
            hidden = unseen | off_person(seen_here, masks, now.model.size)
            edges = frame_rows(layout, now.model, factors=factors, poses=pose, inspection=seen_here).without(hidden)
            regions = frame_rows(layout, now.model, factors=factors, poses=pose, inspection=lines).without(hidden)
            measured.append(edges.joined(regions))
            edged.append(edges.component)
        seen = np.bincount(np.concatenate(edged), minlength=now.model.size)  # a part is measured by its edges
        rows = held_rows(measured, now.model.size)
        weight = np.concatenate([frame.weight for frame in rows])
        residual = float((weight * np.abs(np.concatenate([frame.offset for frame in rows]))).sum() / weight.sum())
        if residual > best.residual:  # the last step made it worse: back, and a shorter step
            damping = min(10.0 * damping, DAMPING[1])
        else:
            best = _State(residual, now.x, now.model, now.poses, rows, seen)
            damping = max(damping / 3.0, DAMPING[0])
        residuals.append(best.residual)
        target, motions = bundle_step(best.rows, prior, best.x, damping=damping)
        x, motions = trusted(layout, best.x, target, motions=motions)
        model = model_from_dict(layout.document(x, document))
        poses = [moved(model, pose, motion) for pose, motion in zip(best.poses, motions)]
        now = _State(np.nan, x, model, poses, [], np.zeros(model.size, np.int64))
    return best, tuple(residuals)


def trusted(
    layout: Layout, x: np.ndarray, step: np.ndarray, *, motions: list[np.ndarray]
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The step from x to ``step`` and the frames' ``motions``, shortened (all by one factor) so that no joint moves
    more than :data:`JOINT_STEP` and no factor changes by more than :data:`FACTOR_STEP`; then every factor kept
    within :data:`FACTORS` of the common scale."""
    change = step - x
    joints = np.abs(change[: layout.factor.min()]).max(initial=0.0) / JOINT_STEP
    factors = np.abs(change[layout.factor.min() : -1]).max(initial=0.0) / FACTOR_STEP
    shrink = 1.0 / max(1.0, joints, factors)
    out = x + shrink * change
    low, high = FACTORS[0] * out[-1], FACTORS[1] * out[-1]
    out[layout.factor.min() : -1] = np.clip(out[layout.factor.min() : -1], low, high)
    return out, [shrink * motion for motion in motions]


def unseen_parts(model: Model, confidence: np.ndarray) -> np.ndarray:
    """The limbs (C, N) bool that each view shows too little of to fit, from the detector's confidence (C, 33) in
    one frame: a component that a joint landmark marks (an upper arm, a shin, a foot) is unseen in a view where
    the landmark at its joint or at a child's (the shin's knee and ankle) is less than :data:`SEEN` sure.  A limb
    behind a table finds the table's edges, which no pose of it explains; the detector's visibility says it is
    not there.  The trunk and the head are always kept."""
    component, _, _ = landmark_points(model, LANDMARKS)
    marked = component >= 0
    unsure = confidence[:, marked] < SEEN  # (C, M)
    out = np.zeros((len(confidence), model.size), bool)
    for c in np.unique(component[marked]):
        ends = (component[marked] == c) | (model.parent[component[marked]] == c)
        out[:, c] = unsure[:, ends].any(axis=1)
    return out


def unseen_joints(model: Model, confidence: np.ndarray) -> np.ndarray:
    """The joints (N,) bool, by their component, whose landmark the detector is sure of (:data:`SEEN`) in fewer
    than :data:`RARELY` of the views of the frames' ``confidence`` (F, C, 33): their place is held at the given
    model's, scaled (:meth:`tracker.shape.layout.Layout.prior`).  Joints no landmark marks are not among them."""
    component, _, _ = landmark_points(model, LANDMARKS)
    out = np.zeros(model.size, bool)
    for j in np.flatnonzero(component >= 0):
        out[component[j]] = (confidence[:, :, j] >= SEEN).mean() < RARELY
    return out


def held_rows(frames: list[FrameRows], components: int) -> list[FrameRows]:
    """The frames' rows without the samples of a component whose outline fits its edges far worse in that frame
    than the components do in all: its median |m| above :data:`STRAY` times the median of those medians (a
    limb on clutter, or on another part, in that frame)."""
    misfit = np.full((len(frames), components), np.nan)
    for k, frame in enumerate(frames):
        for c in np.unique(frame.component):
            misfit[k, c] = np.median(np.abs(frame.offset[frame.component == c]))
    stray = misfit > STRAY * np.nanmedian(misfit)
    return [frame.without(stray[k]) for k, frame in enumerate(frames)]


def _on_person(
    recording: Recording, keypoints: Keypoints, step: int, progress: Callable[..., Iterable]
) -> tuple[Keypoints, list[list[WithChroma]], list[list[PersonMask | None]]]:
    """``keypoints`` with no confidence where a landmark lies off the person's segmentation in its view (kept as
    detected where the segmenter finds nobody), the grey images with their colour at half size (one per camera) of
    their frames (every one a multiple of ``step``) and the person's mask in each (None where not found).
    MediaPipe's native logs are muted the whole time, as while detecting."""
    wanted = {int(frame): row for row, frame in enumerate(keypoints.frame)}
    confidence = keypoints.confidence.copy()
    coloured: list[list[WithChroma]] = [[] for _ in wanted]
    masks: list[list[PersonMask | None]] = [[] for _ in wanted]
    with ExitStack() as stack:
        stack.enter_context(native_logs_muted())  # the graph's threads log while it runs
        segmenter = Segmenter()
        stack.callback(segmenter.close)
        every = frames_of(recording, 0, recording.frame_count, colour=True, step=step)
        for index, images in progress(every, total=len(range(0, recording.frame_count, step))):
            if index not in wanted:
                continue
            row = wanted[index]
            for view, image in enumerate(images):
                coloured[row].append(WithChroma(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), half_size(image, image.shape)))
                mask = segmenter.mask(image, keypoints.pixels[row, view])
                if mask is not None:
                    confidence[row, view] *= mask.covers(keypoints.pixels[row, view])
                masks[row].append(mask)
    return dataclasses.replace(keypoints, confidence=confidence), coloured, masks


def off_person(inspection: Inspection, masks: list[PersonMask | None], components: int) -> np.ndarray:
    """The components (C, N) bool whose outline samples in ``inspection`` lie on the person's mask in a view less
    than :data:`ON_PERSON` of the time (a part behind a desk, whose outline falls on the desk); none in a view
    without a mask."""
    out = np.zeros((len(masks), components), bool)
    for view, mask in enumerate(masks):
        if mask is None:
            continue
        here = inspection.camera == view
        total = np.bincount(inspection.component[here], minlength=components)
        on = np.bincount(inspection.component[here], weights=mask.covers(inspection.pixel[here]), minlength=components)
        out[view] = (total > 0) & (on < ON_PERSON * total)
    return out


GENERIC = Path(__file__).resolve().parents[2] / "models" / "human.toml"
"""The model a fit starts from when none is given: the generic human of ``models/``."""


def changes(base: dict, fit: ShapeFit) -> list[str]:
    """Lines for people: every size of the model ``base`` (parsed) and of the fitted one, in millimetres, and the
    components the edges did not measure (they keep ``base``'s proportions, scaled)."""
    lines = [f"{'component':12s} {'size':26s} {'given':>8s} {'fitted':>8s} {'change':>8s}"]
    for before, after in zip(sizes(base), sizes(fit.document)):
        change = 100.0 * (after.metres / before.metres - 1.0) if before.metres > 0 else 0.0
        lines.append(
            f"{before.component:12s} {before.what:26s} {1e3 * before.metres:6.1f}mm {1e3 * after.metres:6.1f}mm "
            f"{change:+7.1f}%"
        )
    unmeasured = [name for name, seen in zip(fit.layout.names, fit.measured()) if not seen]
    if unmeasured:
        lines.append(
            f"not measured (hidden, or too few edges seen): {', '.join(unmeasured)}; they keep the given proportions, "
            f"scaled by {fit.x[-1]:.3f}"
        )
    return lines


def fit_and_save(
    recording: Recording,
    document: dict,
    path: str | Path,
    *,
    source: str,
    say: Callable[[str], None] = lambda text: None,
    **options,
) -> ShapeFit:
    """:func:`fit_shape` (with its keyword ``options``), then the fitted model written to ``path`` (atomically)
    with a comment naming the recording and the ``source`` model, and its :func:`changes` said."""
    fit = fit_shape(recording, document, say=say, **options)
    sides = "tied" if options.get("tie_sides", True) else "apart"
    comment = (
        f"Fitted by `tracker fit-model` to {recording.path} ({len(fit.edge_frames)} frames held by the edges),\n"
        f"from {source}; left and right {sides}.  An ordinary model file (formats.md)."
    )
    name = f"{document.get('name', 'model')}-fitted"
    save_model(path, {**fit.document, "name": name}, comment)
    for line in changes(document, fit):
        say(line)
    return fit
