"""A Rauch-Tung-Striebel smoother over a recording's track (``--smooth rts``, docs/motion-models.md, "Smoothing over
the whole recording").

The forward track uses nothing after the frame it solves.  Offline, every frame can also be judged by the frames
after it: each component's poses are smoothed under the motion model of :mod:`tracker.tracking.motion_prior` (per
block, translation and rotation, a position and a velocity driven by white-noise acceleration ``q`` with velocity
decay ``gamma``), each frame's tracked pose taken as a measurement of the position with the information its cues gave
it (:meth:`tracker.tracking.frame_loop.Tracker.measured`, ``W_k``, over the noise scale ``s``), and the smoothed poses
coerced onto the joints and their limits.

**The chain.**  One block of one component is the linear chain (Phi_k, Q_k of :func:`motion_prior.transition` and
:func:`motion_prior.noise_integral` over the frame interval dt_k)

    s_{k+1} = A_k s_k + a_k + e_k,   e_k ~ N(0, Q_k),      s_k = (x_k, u_k),
    z_k = x_k + d_k,                 d_k ~ N(0, W_k^-1),    s_0 ~ N(m_0, P_0),

whose smoothed means are the minimiser of ``sum_k |z_k - x_k|^2_{W_k} + sum_k |s_{k+1} - A_k s_k - a_k|^2_{Q_k^-1}
+ |s_0 - m_0|^2_{P_0^-1}`` (:func:`rts_kernel`, a Kalman filter forward and the RTS recursion back; ``W_k`` may be
singular, a part unseen in a frame has none).  ``m_0`` is the first frame's measurement and the motion from it to the
second, ``P_0`` broad (:data:`INITIAL_POSITION`, and the Kalman filter's first velocity's spread).

Translation: ``x`` the world position of the component's origin, ``A_k = Phi_k``, ``a_k = 0``.  Rotation, about a
reference ``R'_k`` (first the tracked rotations, then the smoothed ones; Gauss-Newton, :data:`PASSES` passes):
``x = phi`` with ``R_k = R'_k Exp(phi_k)``, ``u = w`` the body angular velocity.  ``R_{k+1} = R_k Exp(c w_k)`` gives,
to first order in ``phi`` and in ``w`` about the reference's own motion ``D_k = R'_k^T R'_{k+1}``,

    phi_{k+1} = D_k^T phi_k + c w_k - log(D_k),      w_{k+1} = b w_k,

and the measurement ``z_k = log(R'_k^T R_k)`` of the tracked rotation ``R_k``.

**Where it breaks.**  A re-seeded frame starts the track afresh (the poses before it had strayed), so the chains
restart there (:func:`segments`); the caller gives a lost frame no information.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.geometry.se3 import exp_so3_many, log_so3_many
from tracker.model import Model
from tracker.tracking.motion_prior import INITIAL_SPEED, INITIAL_SPIN, ROTATION, TRANSLATION, noise_integral, transition
from tracker.tracking.settings import MotionSettings

PASSES = 2
"""Gauss-Newton passes of the rotation chains: the first about the tracked rotations, the next about the smoothed."""

INITIAL_POSITION = (1.0, 1.0)
"""Prior variance of the first position (m^2, rad^2): broad, so that the first frame's measurement sets it."""


@njit(cache=True)
def _solve_psd(a, b):
    """a^-1 b for a symmetric positive definite ``a`` (Cholesky)."""
    low = np.linalg.cholesky(a)
    y = np.linalg.solve(low, b)
    return np.linalg.solve(low.T, y)


@njit(cache=True)
def rts_kernel(transition, offset, noise, measured, information, mean0, covariance0):
    """Smoothed means (M, F, 6) of M independent linear chains of F states s = (x, u), x and u in R^3 (module
    docstring, "The chain"): ``transition`` A_k (M, F-1, 6, 6), ``offset`` a_k (M, F-1, 6), ``noise`` Q_k (M, F-1, 6,
    6) positive definite, ``measured`` z_k (M, F, 3), ``information`` W_k (M, F, 3, 3) positive semi-definite,
    ``mean0`` m_0 (M, 6) and ``covariance0`` P_0 (M, 6, 6).  The update in information form,
    K = P H^T (I + W P_xx)^-1 W, needs no inverse of W; the backward gain G_k = P_k|k A_k^T P_k+1|k^-1."""
    m_count, f_count = measured.shape[0], measured.shape[1]
    out = np.empty((m_count, f_count, 6))
    filtered = np.empty((f_count, 6))
    filtered_cov = np.empty((f_count, 6, 6))
    predicted = np.empty((f_count, 6))
    predicted_cov = np.empty((f_count, 6, 6))
    eye3 = np.eye(3)
    for m in range(m_count):
        mean = mean0[m].copy()
        cov = covariance0[m].copy()
        for k in range(f_count):
            if k > 0:
                a = transition[m, k - 1]
                mean = a @ mean + offset[m, k - 1]
                cov = a @ cov @ a.T + noise[m, k - 1]
                cov = 0.5 * (cov + cov.T)
            predicted[k] = mean
            predicted_cov[k] = cov
            w = np.ascontiguousarray(information[m, k])
            p_x = np.ascontiguousarray(cov[:, :3])  # P H^T
            gain = p_x @ np.linalg.solve(eye3 + w @ np.ascontiguousarray(cov[:3, :3]), w)
            mean = mean + gain @ (measured[m, k] - mean[:3])
            cov = cov - gain @ np.ascontiguousarray(p_x.T)
            cov = 0.5 * (cov + cov.T)
            filtered[k] = mean
            filtered_cov[k] = cov
        out[m, f_count - 1] = mean
        smoothed_cov = cov
        for k in range(f_count - 2, -1, -1):
            a = transition[m, k]
            back = _solve_psd(predicted_cov[k + 1], a @ filtered_cov[k]).T  # G_k = P_k|k A^T P_k+1|k^-1
            out[m, k] = filtered[k] + back @ (out[m, k + 1] - predicted[k + 1])
            smoothed_cov = filtered_cov[k] + back @ (smoothed_cov - predicted_cov[k + 1]) @ back.T
    return out


def segments(starts: np.ndarray) -> list[slice]:
    """The rows of a track that one chain each smooths: from row 0 and from every row ``starts`` (F,) bool marks (a
    re-seed, a frame missing before it) to the next."""
    bounds = [0, *(int(row) for row in np.flatnonzero(starts) if row > 0), len(starts)]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


def _block_model(dt: np.ndarray, motion: MotionSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per interval (F-1,) of ``dt``: c, b and the noise Bq (2, 2) of both blocks' per-axis motion
    (:func:`motion_prior.transition`, :func:`motion_prior.noise_integral`), each interval's length computed once."""
    steps, which = np.unique(dt, return_inverse=True)
    phi = np.array([transition(float(step), motion.decay) for step in steps]).reshape(-1, 2, 2)[which]
    integral = np.array([noise_integral(float(step), motion.decay) for step in steps]).reshape(-1, 2, 2)[which]
    return phi[:, 0, 1], phi[:, 1, 1], integral


def _transitions(c: np.ndarray, b: np.ndarray, turn: np.ndarray | None = None) -> np.ndarray:
    """The transitions A_k (1, F-1, 6, 6) of one chain with the per-interval c and b, the position block ``turn``
    (F-1, 3, 3; identity when None)."""
    a = np.zeros((1, len(c), 6, 6))
    a[0, :, :3, :3] = np.eye(3) if turn is None else turn
    a[0, :, :3, 3:] = c[:, None, None] * np.eye(3)
    a[0, :, 3:, 3:] = b[:, None, None] * np.eye(3)
    return a


def _prior(position: float, velocity: float) -> np.ndarray:
    """P_0 (1, 6, 6): the first position's and velocity's variances."""
    return np.diag([position] * 3 + [velocity] * 3)[None].astype(np.float64)


def smooth_segment(
    poses: np.ndarray, information: np.ndarray, times: np.ndarray, *, motion: MotionSettings, scale: float = 1.0
) -> np.ndarray:
    """The component poses (F, N, 4, 4) of one segment smoothed (module docstring), before any coercion:
    ``information`` (F, N, 2, 3, 3) of each frame's poses (:meth:`Tracker.measured`), divided by the noise scale
    ``scale``; ``times`` (F,) seconds.  One component at a time, so that a long recording's chains stay small."""
    f_count, n = poses.shape[:2]
    if f_count < 2:
        return poses.copy()
    c, b, integral = _block_model(np.diff(times), motion)
    eye = np.eye(3)
    noise = {
        block: (q * np.kron(integral, eye))[None]
        for block, q in ((TRANSLATION, motion.q_translation), (ROTATION, motion.q_rotation))
    }
    still = np.zeros((1, f_count - 1, 6))
    translation = _transitions(c, b)
    out = poses.copy()
    for i in range(n):
        weight = np.asarray(information[:, i], np.float64) / scale  # (F, 2, 3, 3)
        # translation: the world position of the component's origin, its velocity from the first two frames
        position = np.ascontiguousarray(poses[None, :, i, :3, 3])  # (1, F, 3)
        mean0 = np.concatenate([position[:, 0], (position[:, 1] - position[:, 0]) / c[0]], axis=1)
        means = rts_kernel(
            translation,
            still,
            noise[TRANSLATION],
            position,
            np.ascontiguousarray(weight[None, :, TRANSLATION]),
            mean0,
            _prior(INITIAL_POSITION[TRANSLATION], INITIAL_SPEED**2),
        )
        out[:, i, :3, 3] = means[0, :, :3]
        # rotation: increments about a reference, the tracked rotations and then the smoothed ones
        tracked = np.ascontiguousarray(poses[:, i, :3, :3])
        reference = tracked.copy()
        for _ in range(PASSES):
            step = np.swapaxes(reference[:-1], -1, -2) @ reference[1:]  # D_k (F-1, 3, 3)
            turned = log_so3_many(np.ascontiguousarray(step))  # log(D_k)
            offset = np.zeros((1, f_count - 1, 6))
            offset[0, :, :3] = -turned
            measured = log_so3_many(np.ascontiguousarray(np.swapaxes(reference, -1, -2) @ tracked))[None]
            mean0 = np.concatenate([measured[:, 0], turned[None, 0] / c[0]], axis=1)
            means = rts_kernel(
                _transitions(c, b, np.swapaxes(step, -1, -2)),
                offset,
                noise[ROTATION],
                measured,
                np.ascontiguousarray(weight[None, :, ROTATION]),
                mean0,
                _prior(INITIAL_POSITION[ROTATION], INITIAL_SPIN**2),
            )
            reference = reference @ exp_so3_many(np.ascontiguousarray(means[0, :, :3]))
        out[:, i, :3, :3] = reference
    return out


def smoothed_track(
    model: Model,
    poses: np.ndarray,
    information: np.ndarray,
    *,
    times: np.ndarray,
    starts: np.ndarray,
    motion: MotionSettings,
    scale: float = 1.0,
) -> np.ndarray:
    """A track's poses (F, N, 4, 4), at ``times`` (F,) seconds, smoothed segment by segment (:func:`segments` of
    ``starts``, :func:`smooth_segment` with ``information`` (F, N, 2, 3, 3) over ``scale``) and coerced onto the
    ``model``'s joints and limits (:meth:`tracker.model.Model.coerce`)."""
    out = np.empty_like(poses)
    for rows in segments(starts):
        out[rows] = smooth_segment(poses[rows], information[rows], times[rows], motion=motion, scale=scale)
    return np.stack([model.coerce(row) for row in out])
