"""The motion model that predicts each frame's poses (``Settings.motion.dynamics``, docs/motion-models.md): none
(the last poses), constant velocity (the last motion carried on) or the Kalman filter of
:mod:`tracker.tracking.motion_prior`, each behind one small interface (:class:`MotionModel`); and the body moved on
along its motion, which also places each view at its own capture time (docs/sync.md).

A model keeps nothing of its own: what it carries from frame to frame is the tracker's
:class:`~tracker.tracking.motion_prior.Motion`, copied whole (so a tracker for other cameras goes on with it), and
the prior about the prediction it sets is the tracker's ``prior``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numba import njit

from tracker.geometry.se3 import between, exp, log
from tracker.tracking import motion_prior
from tracker.tracking.motion_prior import Motion

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker


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


class MotionModel(Protocol):
    """Predicts a frame's poses from the ones tracked before, and learns from the frame once tracked."""

    def start(self, tracker: Tracker) -> Motion:
        """What the model carries from a start at the tracker's poses (no motion yet)."""
        ...

    def predict(self, tracker: Tracker, current: np.ndarray, dt: float | None) -> Any:
        """Set the tracker's poses (and its prior) to the prediction for a frame ``dt`` seconds (None: one frame of
        ``frame_rate``) after the one tracked at ``current``; returns what :meth:`correct` needs of it."""
        ...

    def correct(self, tracker: Tracker, predicted: Any) -> None:
        """Learn from the frame as tracked, given what :meth:`predict` returned."""
        ...


class Still:
    """dynamics "none": each frame starts from the last frame's poses."""

    def start(self, tracker: Tracker) -> Motion:
        return Motion(None, None, np.full(tracker.model.size, float(tracker.settings.motion.noise_scale)))

    def predict(self, tracker: Tracker, current: np.ndarray, dt: float | None) -> None:
        return None

    def correct(self, tracker: Tracker, predicted: Any) -> None:
        return None


class ConstantVelocity(Still):
    """dynamics "constant-velocity": the last frame's poses moved on by the motion between the two frames before (its
    ``damping`` share, :func:`constant_velocity`), unless (with ``check_prediction``) the frame's landmarks lie nearer
    the last poses than the moved ones by more than the detector's noise (``keypoints.tolerance`` of the body's size,
    :meth:`tracker.tracking.keypoint_cue.KeypointCue.misfit`); then the last poses.  That motion is partly the
    correction of the frame before's error (a lead, the landmarks' pull): at a low frame rate, carried on, it can throw
    the body a quarter of a metre off before any cue is read, and the edges then hold it there."""

    def predict(self, tracker: Tracker, current: np.ndarray, dt: float | None) -> None:
        if tracker.motion.previous is not None:
            tracker.poses = self.carried(tracker, current)

    @staticmethod
    def carried(tracker: Tracker, current: np.ndarray) -> np.ndarray:
        """The prediction from the last frame's poses ``current`` (the class docstring)."""
        st = tracker.settings
        moved = tracker.model.coerce(constant_velocity(tracker.motion.previous, current, st.motion.damping))
        landmarks = tracker.landmarks
        if landmarks.frame is None or not st.motion.check_prediction:
            return moved
        if landmarks.misfit(tracker, moved) > landmarks.misfit(tracker, current) + st.keypoints.tolerance:
            return current
        return moved


class Kalman:
    """dynamics "kalman": a second-order Kalman filter per component (:mod:`tracker.tracking.motion_prior`), whose
    predicted covariance also sets how firmly the prediction holds."""

    def start(self, tracker: Tracker) -> Motion:
        st = tracker.settings
        m = st.motion
        if not (m.frame_rate > 0 and m.noise_scale > 0 and min(m.q_translation, m.q_rotation, m.decay) >= 0):
            raise ValueError(
                "dynamics 'kalman' needs frame_rate > 0, noise_scale > 0 and q_translation, q_rotation, decay >= 0"
            )
        s = st.motion.noise_scale
        kalman = motion_prior.initial_state(
            tracker.poses, position_variance=(s / st.solve.prior_translation, s / st.solve.prior_rotation)
        )
        return Motion(None, kalman, np.full(tracker.model.size, float(s)))

    def predict(self, tracker: Tracker, current: np.ndarray, dt: float | None) -> np.ndarray:
        """Predict every component ``dt`` ahead independently (:func:`tracker.tracking.motion_prior.predict`), coerce
        the predicted poses onto the joints (the filter's means follow), and set the prior about them to the
        predicted information ``s' P_xx^-1`` (floored at the solve's prior_translation/prior_rotation; ``s'`` of the
        previous frame).  Returns the predicted state's ``motion_prior.position_inverse``, which the correction
        reuses."""
        st, motion = tracker.settings, tracker.motion
        assert motion.kalman is not None  # started by this model
        predicted = motion_prior.predict(
            motion.kalman,
            1.0 / st.motion.frame_rate if dt is None else dt,
            q=(st.motion.q_translation, st.motion.q_rotation),
            decay=st.motion.decay,
        )
        tracker.poses = tracker.model.coerce(predicted.poses)
        kalman = motion_prior.rereference(predicted, tracker.poses)
        tracker.motion = dataclasses.replace(motion, kalman=kalman)
        inverse = motion_prior.position_inverse(kalman)
        tracker.prior = motion_prior.prior_information(
            kalman,
            scale=motion.noise_scale,
            floor=(st.solve.prior_translation, st.solve.prior_rotation),
            p_xx_inv=inverse,
        )
        return inverse

    def correct(self, tracker: Tracker, predicted: Any) -> None:
        """Update the filters with the tracked poses and the data information C_i of the last iteration (the
        workspace's ``information`` holds C_i plus the prior added by :func:`tracker.tracking.solve.add_prior`) over
        the noise scale ``s' = s sigma0_i^2`` (:func:`tracker.tracking.motion_prior.variance_factor` of the same
        samples); ``predicted`` is the predicted state's P_xx^-1 that :meth:`predict` returned."""
        st, motion, work = tracker.settings, tracker.motion, tracker.work
        s = float(st.motion.noise_scale)
        noise_scale = motion.noise_scale
        if st.motion.residual_variance:  # without any edge the last frame's values stay
            n = work.samples.count
            noise_scale = s * motion_prior.variance_factor(
                work.samples.component[:n],
                work.offset[:n],
                work.weight[:n],
                n_components=tracker.model.size,
                fallback=noise_scale / s,
            )
        data = work.information - tracker.prior
        assert motion.kalman is not None  # started by this model
        information = motion_prior.block_information(data, tracker.poses) / noise_scale[:, None, None, None]
        kalman = motion_prior.correct(motion.kalman, tracker.poses, information, p_xx_inv=predicted)
        tracker.motion = dataclasses.replace(motion, kalman=kalman, noise_scale=noise_scale)


MODELS: dict[str, type[Still] | type[Kalman]] = {"none": Still, "constant-velocity": ConstantVelocity, "kalman": Kalman}
"""The motion model of each ``Settings.motion.dynamics``."""
