"""Refine a rig's extrinsics to the outlines of a body tracked in its views (self-calibration).

A camera moved by a small twist xi, camera_from_world ``P_k <- exp(xi) P_k``, images component i
as the body moved by ``alpha_i = Ad((P_k E_i)^-1) xi`` would, since
``exp(xi) P_k E_i = P_k E_i exp(Ad((P_k E_i)^-1) xi)``.  So an outline sample's Jacobian row L_s
with respect to its component's motion (docs/method-tracking.md, section 3) gives the row
``J_s = L_s Ad((P_k E_i)^-1)`` with respect to its camera's, and holding the tracked body fixed,
the edge distances m_s of many frames with the IRLS weights w_s = 1/(c + |m_s|) give each camera's
motion as the tracker gives a component's, with a weak prior P = diag(lt I3, lr I3) (the tracker's)
holding the camera's accumulated move d_k = log(P_k P0_k^-1) from its calibration P0_k where the body
does not tell (a body in one place hardly separates a camera's sideways shift from its turn):

    (sum_s w_s J_s^T J_s + P) xi_k = sum_s w_s J_s^T m_s - P d_k,

repeated over rounds whose edge searches narrow from the settings' first search range to their
last.  After each round every frame's body is fitted again to all the (moved) cameras, as the
tracker fits a frame (``refit``): cameras and bodies then settle together, block by block, and a
camera whose calibration disagrees with the others is no longer met half way by a body that
compromised between them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from tracker.camera import Camera
from tracker.geometry import se3
from tracker.model import Model
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings
from tracker.tracking.solve import narrowing

ROUNDS = 8


@dataclass(frozen=True)
class Refined:
    """The refined cameras, and per camera how far each moved (degrees, metres of its centre) and its robust
    mean edge distance (pixels, at the last search range) before and after."""

    cameras: tuple[Camera, ...]
    rotation_deg: np.ndarray
    shift_m: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray


def camera_rows(
    jacobian: np.ndarray, camera: np.ndarray, component: np.ndarray, *, rig_pose: np.ndarray, poses: np.ndarray
) -> np.ndarray:
    """Rows J_s = L_s Ad((P_k E_i)^-1) (S, 6) of samples with rows L_s (S, 6) seen by cameras ``camera`` (S,)
    of components ``component`` (S,), with camera-from-world ``rig_pose`` (K, 4, 4) and world-from-component
    ``poses`` (N, 4, 4); one adjoint per (camera, component) pair."""
    adjoints = np.array([[se3.adjoint(se3.inverse(view @ pose)) for pose in poses] for view in rig_pose])
    return np.einsum("sa,sab->sb", jacobian, adjoints[camera, component])


def _measure(tracker: Tracker, poses: np.ndarray, images: Sequence[np.ndarray], search_range: int):
    """Sample the body at ``poses`` in every camera, search each sample's edge in ``images`` (smoothed, rig
    order); return per sample (camera, J row, offset m, weight w) for the samples that found an edge."""
    seen = tracker.inspect(images, smoothed=True, poses=poses, search_range=search_range)
    found = seen.weight > 0
    camera, component = seen.camera[found], seen.component[found]
    rows = camera_rows(seen.jacobian[found], camera, component, rig_pose=tracker.rig.camera_from_world, poses=poses)
    return camera, rows, seen.offset[found], seen.weight[found]


def _residuals(
    tracker: Tracker, poses: np.ndarray, frames: Sequence[Sequence[np.ndarray]], cameras: int, search_range: int
) -> np.ndarray:
    """Per camera the robust mean edge distance sum w|m| / sum w over all frames (NaN: no edge found)."""
    sum_wm, sum_w = np.zeros(cameras), np.zeros(cameras)
    for frame_poses, images in zip(poses, frames):
        seen = tracker.inspect(images, smoothed=True, poses=frame_poses, search_range=search_range)
        found = seen.weight > 0
        np.add.at(sum_wm, seen.camera[found], seen.weight[found] * np.abs(seen.offset[found]))
        np.add.at(sum_w, seen.camera[found], seen.weight[found])
    with np.errstate(invalid="ignore", divide="ignore"):
        return sum_wm / sum_w


def refine_rig(
    model: Model,
    cameras: Sequence[Camera],
    poses: np.ndarray,
    *,
    frames: Sequence[Sequence[np.ndarray]],
    settings: Settings = Settings(),
    rounds: int = ROUNDS,
    fixed: Iterable[int] = (),
    refit: bool = True,
    progress: Callable[[Iterable], Iterable] = iter,
) -> Refined:
    """Move each camera not in ``fixed`` to fit the outlines of the body at ``poses`` (F, N, 4, 4) in
    ``frames`` (F lists of one smoothed edge-search image per camera, as the tracker takes them), and
    with ``refit`` fit the bodies again after each round.  ``progress`` wraps the rounds (e.g. tqdm)."""
    start, cameras = tuple(cameras), list(cameras)
    fixed = set(fixed)
    poses = np.array(poses)
    settings = settings.but(motion=dict(dynamics="none"))  # each frame's fit starts from its own body, as tracked
    tracker = Tracker(model, cameras, poses[0], settings)
    prior = tracker.prior[0]  # the tracker's P = diag(lt I3, lr I3), the same for every component
    first, last = (
        tracker.settings.outline.search_range,
        tracker.settings.outline.final_search_range or tracker.settings.outline.search_range,
    )
    before = _residuals(tracker, poses, frames, len(cameras), last)
    for round_ in progress(range(rounds)):
        search_range = narrowing(first, last, step=round_, steps=rounds)
        information, eta = np.zeros((len(cameras), 6, 6)), np.zeros((len(cameras), 6))
        for frame_poses, images in zip(poses, frames):
            camera, rows, offset, weight = _measure(tracker, frame_poses, images, search_range)
            weighted = rows * weight[:, None]
            np.add.at(information, camera, weighted[:, :, None] * rows[:, None, :])
            np.add.at(eta, camera, weighted * offset[:, None])
        for k in set(range(len(cameras))) - fixed:
            moved = se3.log(cameras[k].camera_from_world @ se3.inverse(start[k].camera_from_world))
            xi = np.linalg.solve(information[k] + prior, eta[k] - prior @ moved)
            pose = se3.exp(xi) @ cameras[k].camera_from_world
            cameras[k] = cameras[k].with_camera_from_world(pose)
        tracker = tracker.with_cameras(cameras)
        if refit:
            for f, images in enumerate(frames):
                tracker.poses = model.coerce(poses[f])
                poses[f] = tracker.step(images, smoothed=True).poses
    after = _residuals(tracker, poses, frames, len(cameras), last)
    turn = [np.degrees(se3.rotation_angle(b.rotation @ a.rotation.T)) for a, b in zip(start, cameras)]
    shift = [np.linalg.norm(b.center - a.center) for a, b in zip(start, cameras)]
    return Refined(tuple(cameras), np.array(turn), np.array(shift), before, after)
