"""The detector's landmarks against a render's truth: pixel errors as a share of the body's size, and swaps.

In camera k and frame f, the truth of a joint landmark j (shoulders, elbows, wrists, hips, knees,
ankles: the origins of the components of :data:`tracker.landmarks.body_landmarks.SIDES`) is the image u of its
true joint centre. It is scored where the camera sees that joint (inside the image, not behind a
prop; :func:`tracker.synthetic.synth.seen_joints`) and the detector gave it a confidence of at least
``min_confidence`` (the tracker's default, 0.5). The body's size s in that view is the diagonal of the
bounding box of every true joint centre's image. With d the detected pixel:

    error    |d - u| / s, its median over the render's scored landmarks, and the share above 0.1
    found    the share of views (camera, frame) in which a person was found
    on body  a view whose scored landmarks lie on the body: the median over them of the error, each
             left/right pair taken the way round it fits better, is below 0.2
    swapped  the share of views on the body whose pairs fit better swapped (summed distances over the
             pairs with both landmarks scored), as the keypoint cue judges a swap

:func:`suite_accuracy` scores every render of the hard suite (docs/suite.md) from KP/<name>/keypoints.npz (or the file
of another landmark model), and beside those scores the landmarks triangulated frame by frame
(:mod:`tracker.synthetic.detector_baseline`): their mean distance from the true joint centres in millimetres, and the
share of the joints the truth has that they give.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker.camera import Camera, load_calibration
from tracker.errors import TrackerInputError
from tracker.io.poses import load_poses
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.detect_recording import cache_name
from tracker.landmarks.landmark_models import RECORDED
from tracker.landmarks.store import Keypoints, load_keypoints
from tracker.model import Model, load_model
from tracker.synthetic.detector_baseline import Baseline, baseline
from tracker.synthetic.props import Box
from tracker.synthetic.suite import Render
from tracker.synthetic.synth import seen_joints, table_before

WRONG = 0.1
"""An error above this share of the body's size counts as a wrong landmark."""
ON_BODY = 0.2
"""A view whose median error (pairs either way round) is below this share of the body's size is on the body."""


@dataclass(frozen=True)
class Accuracy:
    """One render's scores (see the module): ``views`` (camera, frame) detected in, ``found`` among them,
    ``scored`` landmarks, their ``median`` error and the share ``wrong``, ``on_body`` views and the
    share of them ``swapped`` (NaN when there is nothing to share)."""

    views: int
    found: int
    scored: int
    median: float
    wrong: float
    on_body: int
    swapped: float


def accuracy(
    keypoints: Keypoints,
    cameras: list[Camera],
    poses: np.ndarray,
    *,
    model: Model,
    props: tuple[Box, ...] = (),
    min_confidence: float = 0.5,
) -> Accuracy:
    """The scores of ``keypoints`` against the true poses (F, N, 4, 4) of frames 0..F-1 of ``model``'s
    components, seen by ``cameras`` (matched to the keypoints' cameras by name) among ``props``."""
    by_name = {camera.name: camera for camera in cameras}
    missing = [name for name in keypoints.camera_names if name not in by_name]
    if missing:
        raise TrackerInputError(f"camera {missing[0]} of the keypoints is not in the calibration; give the rig's")
    if len(keypoints.frame) and keypoints.frame.max() >= len(poses):
        raise TrackerInputError(f"the keypoints reach frame {keypoints.frame.max()}, the truth only {len(poses) - 1}")
    component, _, pairs = landmark_points(model, LANDMARKS)
    joints = np.flatnonzero(component >= 0)  # the joint landmarks, in LANDMARKS order
    column = {int(j): i for i, j in enumerate(joints)}
    pairs = np.array([(column[a], column[b]) for a, b in pairs if a in column and b in column], np.int64)
    other = np.arange(len(joints))  # each joint landmark's other side
    other[pairs[:, 0]], other[pairs[:, 1]] = pairs[:, 1], pairs[:, 0]
    centres = poses[keypoints.frame][:, :, 0:3, 3]  # (F, N, 3) every joint centre
    errors, views, found, on_body, swapped = [], 0, 0, 0, 0
    for k, name in enumerate(keypoints.camera_names):
        camera = by_name[name]
        every = camera.project(centres.reshape(-1, 3)).reshape(*centres.shape[:2], 2)
        size = np.linalg.norm(every.max(axis=1) - every.min(axis=1), axis=1)[:, None]  # (F, 1) pixels
        truth = every[:, component[joints]]  # (F, J, 2)
        pixels, confidence = keypoints.pixels[:, k, joints], keypoints.confidence[:, k, joints]
        scored = seen_joints(centres[:, component[joints]], [camera], props) & (confidence >= min_confidence)
        scored &= np.isfinite(pixels).all(axis=2)
        share = np.linalg.norm(pixels - truth, axis=2) / size
        crossed = np.linalg.norm(pixels - truth[:, other], axis=2) / size
        views += len(centres)
        found += int((keypoints.confidence[:, k].max(axis=1) > 0.0).sum())
        errors.append(share[scored])
        for f in range(len(centres)):
            both = pairs[scored[f, pairs].all(axis=1)].ravel()
            best = share[f].copy()
            best[both] = np.minimum(share[f, both], crossed[f, both])
            if len(both) and np.median(best[scored[f]]) < ON_BODY:
                on_body += 1
                swapped += int(crossed[f, both].sum() < share[f, both].sum())
    error = np.concatenate(errors)
    return Accuracy(
        views=views,
        found=found,
        scored=len(error),
        median=float(np.median(error)) if len(error) else math.nan,
        wrong=float((error > WRONG).mean()) if len(error) else math.nan,
        on_body=on_body,
        swapped=swapped / on_body if on_body else math.nan,
    )


Scores = tuple[Render, Accuracy, Baseline]
"""A render's scores: its landmarks' in the images, and triangulated frame by frame."""


def suite_accuracy(
    out: str | os.PathLike, keypoints: str | os.PathLike, renders: list[Render], *, landmark_model: str = RECORDED
) -> list[Scores]:
    """Each render's scores: the detections of ``landmark_model`` in ``keypoints``/<name>/ (keypoints.npz, or its
    own file: :func:`tracker.landmarks.detect_recording.cache_name`) against ``out``/<name>/ (its truth.npz,
    calibration.toml and model.toml, and the tables its staging stands before the cameras)."""
    scores = []
    for render in renders:
        folder, path = Path(out) / render.name, Path(keypoints) / render.name / cache_name(landmark_model)
        if not path.is_file():
            raise TrackerInputError(
                f"{path}: not found; detect it with tracker keypoints {folder} --out {path.parent} --landmark-model "
                f"{landmark_model}"
            )
        cameras = load_calibration(folder / "calibration.toml")
        props = tuple(table_before(camera) for camera in render.staging.table_cameras(cameras))
        truth = load_poses(folder / "truth.npz")
        found, model = load_keypoints(path), load_model(folder / "model.toml")
        scored = accuracy(found, cameras, truth["poses"], model=model, props=props)
        scores.append((render, scored, baseline(found, truth, cameras=cameras, model=model)))
    return scores


def accuracy_rows(scores: list[Scores]) -> list[dict]:
    """The scores as plain data, one dict per render (its name, the fields of :class:`Accuracy`, then the
    triangulated landmarks' ``triangulated_mm`` and ``coverage``); NaN becomes None."""
    rows = []
    for render, score, alone in scores:
        values = {**vars(score), "triangulated_mm": alone.landmarks_mm, "coverage": alone.coverage}
        rows.append({"name": render.name, **{key: None if _nan(value) else value for key, value in values.items()}})
    return rows


def _nan(value: float) -> bool:
    return isinstance(value, float) and math.isnan(value)


def format_accuracy(scores: list[Scores]) -> str:
    """The scores as a text table, one row per render, then the mean of the triangulated error over the renders."""
    width = max(len("render"), *(len(render.name) for render, _, _ in scores))
    lines = [
        f"{'render':<{width}}  {'found':>11}  {'median':>6}  {'> 10 %':>6}  {'on body':>7}  {'swapped':>7}  "
        f"{'3-D mm':>6}  {'coverage':>8}"
    ]
    for render, score, alone in scores:
        lines.append(
            f"{render.name:<{width}}  {score.found:>5}/{score.views:<5}  {_percent(score.median):>6}  "
            f"{_percent(score.wrong):>6}  {score.on_body:>7}  {_percent(score.swapped):>7}  "
            f"{_millimetres(alone.landmarks_mm):>6}  {_percent(alone.coverage):>8}"
        )
    numbers = [alone.landmarks_mm for _, _, alone in scores if not math.isnan(alone.landmarks_mm)]
    mean = sum(numbers) / len(numbers) if numbers else math.nan
    lines += [
        "",
        f"3-D: the landmarks triangulated frame by frame, mean error {_millimetres(mean)} mm over the renders "
        "scored; coverage: the share of the truth's joints they give",
    ]
    return "\n".join(lines)


def _millimetres(value: float) -> str:
    """Millimetres with one decimal, or - for NaN."""
    return "-" if math.isnan(value) else f"{value:.1f}"


def _percent(value: float) -> str:
    """A share as a percentage with one decimal, or - for NaN."""
    return "-" if math.isnan(value) else f"{100.0 * value:.1f} %"
