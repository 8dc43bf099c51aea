"""The body's joints fitted to the landmarks of many frames (docs/fit-model.md, "From the keypoints").

The detector's shoulders, elbows, wrists, hips, knees and ankles mark joint centres: the origins of
the components of :data:`tracker.landmarks.body_landmarks.SIDES`.  With every frame's rotations held, such a
landmark's world point is linear in the joints' places and the root's position:

    X_fk = t_f + sum over the joints i from the root down to c_k of R_f,p(i) at_i

where ``c_k`` is landmark k's component, ``p(i)`` joint i's parent, ``at_i`` its place in the parent's frame
(:class:`tracker.shape.layout.Layout`) and ``R_f,c`` component c's world rotation in frame f.  So the fit
alternates, :data:`ROUNDS` times:

1. each frame's pose fitted to its triangulated landmarks with the joints placed so far
   (:func:`tracker.seeding.pose_fit.fit_pose`, which also settles left and right);
2. the joints and the frames' root positions by iteratively reweighted least squares over every frame's
   landmarks (Cauchy weights of scale :data:`ROBUST`) with the layout's prior (:data:`PRIOR`): what no landmark
   measures (the parts' thickness, the hands, the head) follows the common scale.

A detector places its joints where people's usually are, so its lengths lean towards the average person's, and
its shoulders lie on the shoulder's outline rather than at the joint: these are a start that the edges refine
(:mod:`tracker.shape.edges`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from tracker.errors import TrackerInputError
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.model import Model, model_from_dict
from tracker.seeding.pose_fit import fit_pose
from tracker.shape.layout import Layout

ROBUST = 0.04
"""Metres of a landmark's misfit at which its weight has halved (Cauchy)."""

PRIOR = 0.02
"""The prior's weight, in metres of misfit per metre of a joint's place (or per unit of a factor) away from the
given model scaled by the common scale."""

ROUNDS = 1
"""Times the poses and the joints are fitted in turn."""

REWEIGHTS = 8
"""Iteratively reweighted solves of the joints per round."""

LEAST_FRAMES = 3
"""Frames with both hips and both shoulders that a fit needs."""

PLACING = tuple(LANDMARKS.index(f"{side}_{part}") for part in ("hip", "shoulder") for side in ("left", "right"))
"""The landmarks that place the body in a frame (:func:`tracker.seeding.pose_fit.root_from_landmarks`)."""


@dataclass(frozen=True)
class LandmarkFit:
    """The shape fitted to the landmarks: ``x`` (:class:`tracker.shape.layout.Layout`), the keypoint ``frames``
    (F,) used, each one's ``poses`` (F, N, 4, 4) of the fitted model, and the landmarks' median misfit in metres
    with the model as given (``misfit_before``) and as fitted (``misfit``)."""

    x: np.ndarray
    frames: np.ndarray
    poses: np.ndarray
    misfit_before: float
    misfit: float


def design(layout: Layout, model: Model, rotations: np.ndarray) -> np.ndarray:
    """The linear map (F, 33, 3, width) from x to the joint landmarks' world points less the root's position, at
    world-from-component ``rotations`` (F, N, 3, 3) (module docstring); zero for the other landmarks."""
    component, _, _ = landmark_points(model, LANDMARKS)
    out = np.zeros((len(rotations), len(LANDMARKS), 3, layout.width))
    for k in np.flatnonzero(component >= 0):
        i = int(component[k])
        while model.parent[i] >= 0:
            p = int(model.parent[i])
            out[:, k] += rotations[:, p] @ layout.joint_map(i)
            i = p
    return out


def solve(matrix: np.ndarray, points: np.ndarray, prior: np.ndarray, *, robust: float = ROBUST) -> np.ndarray:
    """x (width,) that best explains world ``points`` (F, 33, 3) (NaN: unknown) through ``matrix`` (F, 33, 3, width)
    (:func:`design`) and each frame's root position, under the ``prior`` rows (R, width), by :data:`REWEIGHTS`
    Cauchy-reweighted least squares (module docstring)."""
    frames, _, _, width = matrix.shape
    seen = np.isfinite(points).all(axis=2) & np.any(matrix != 0, axis=(2, 3))
    f_index, k_index = np.nonzero(seen)
    place = np.zeros((len(f_index), 3, 3 * frames))
    for axis in range(3):
        place[np.arange(len(f_index)), axis, 3 * f_index + axis] = 1.0
    data = np.concatenate([matrix[f_index, k_index], place], axis=2).reshape(-1, width + 3 * frames)
    target = points[f_index, k_index].ravel()
    pull = np.hstack([prior, np.zeros((len(prior), 3 * frames))])
    weight = np.ones(len(f_index))
    for _ in range(REWEIGHTS):
        root = np.sqrt(np.repeat(weight, 3))[:, None]
        system = np.vstack([root * data, pull])
        solution = np.linalg.lstsq(system, np.concatenate([root[:, 0] * target, np.zeros(len(pull))]), rcond=None)[0]
        misfit = np.linalg.norm((data @ solution - target).reshape(-1, 3), axis=1)
        weight = 1.0 / (1.0 + (misfit / robust) ** 2)
    return solution[:width]


def fit_landmarks(
    layout: Layout,
    document: dict,
    points: np.ndarray,
    *,
    frames: np.ndarray,
    progress: Callable[..., Iterable] = lambda iterable, total=None: iterable,
) -> LandmarkFit:
    """The shape of the model TOML ``document`` (parsed; ``layout`` made of it) that best fits the landmarks' world
    points ``points`` (F, 33, 3) of keypoint ``frames`` (F,) (NaN: unknown; module docstring).  ``progress``
    wraps each round's frames (e.g. a tqdm bar).  A one-line error when fewer than :data:`LEAST_FRAMES` frames
    show both hips and both shoulders."""
    usable = np.isfinite(points[:, PLACING]).all(axis=(1, 2))
    if usable.sum() < LEAST_FRAMES:
        raise TrackerInputError(
            f"only {int(usable.sum())} of {len(points)} frames show both hips and both shoulders in two views, the "
            f"fit needs {LEAST_FRAMES}; give more frames (--frames) or a recording with the whole body in view"
        )
    points, frames = points[usable], frames[usable]
    x = layout.start()
    prior = layout.prior(PRIOR, PRIOR)
    model = model_from_dict(document)
    before = np.nan
    for _ in range(ROUNDS):
        poses = np.stack([fit_pose(model, frame) for frame in progress(points, total=len(points))])
        matrix = design(layout, model, poses[:, :, :3, :3])
        if np.isnan(before):
            before = misfit(matrix, x, poses=poses, points=points)
        x = solve(matrix, points, prior)
        model = model_from_dict(layout.document(x, document))
    poses = np.stack([fit_pose(model, frame) for frame in points])
    after = misfit(design(layout, model, poses[:, :, :3, :3]), x, poses=poses, points=points)
    return LandmarkFit(x, frames, poses, before, after)


def misfit(matrix: np.ndarray, x: np.ndarray, *, poses: np.ndarray, points: np.ndarray) -> float:
    """Median distance (metres) between the known joint landmarks ``points`` (F, 33, 3) and the model's under x
    at ``poses`` (F, N, 4, 4), through ``matrix`` (:func:`design`)."""
    placed = matrix @ x + poses[:, :1, :3, 3]
    distance = np.linalg.norm(placed - points, axis=2)
    marked = np.any(matrix != 0, axis=(2, 3)) & np.isfinite(distance)
    return float(np.median(distance[marked]))
