"""A second-order motion prior per component: a continuous-discrete Kalman filter
(``Settings.motion.dynamics = "kalman"``).

docs/method-physics.md: section 3 (second-order dynamics
``M qddot + D qdot = f`` with ``D = gamma M``) and section 5 (the continuous EKF as code: the state
decoupled into blocks, Q and V scalar multiples of identity, the covariance by the Riccati equation).

State of one component ``i``, two independent blocks of 3 + 3 numbers each:

* translation: the world position ``t`` of the component's origin (its joint) and its world
  velocity ``v``;
* rotation: a rotation-vector increment ``phi`` about the reference rotation ``R`` (the last
  estimate, ``R_true = R Exp(phi)``, so ``phi = 0`` at the mean) and the body angular velocity ``w``
  (the rotational part of the body twist, ``Rdot = R [w]x``).

Both blocks follow the same linear model per axis (section 3 with unit mass, damping ``D = gamma M``
and a white-noise force; the mass only rescales the noise, ``q = q_force / m^2``, so the model is
parameterised by ``q`` alone):

    d/dt [x; u] = F [x; u] + G a,    F = [[0, I3], [0, -gamma I3]],   G = [0; I3],
    a = white-noise acceleration with spectral density q I3  (q_t m^2/s^3, q_r rad^2/s^3)

``gamma = 0`` is the constant-velocity model.  Between frames (interval ``dt``) the mean and the
covariance follow the continuous equations ``d m/dt = F m`` and the Riccati equation without data,
``dP/dt = F P + P F^T + G q G^T``, integrated exactly: with ``b = e^(-gamma dt)`` and
``c = (1 - b) / gamma`` (``c = dt`` for ``gamma = 0``)

    Phi = [[1, c], [0, b]] (x) I3,     P <- Phi P Phi^T + q Bq (x) I3,
    Bq = int_0^dt [c(s); b(s)] [c(s), b(s)] ds
       = [[dt^3/3, dt^2/2], [dt^2/2, dt]]                      (gamma = 0)

(:func:`transition`, :func:`noise_integral`; for ``gamma > 0`` the integrals are in
:func:`noise_integral`).  The rotation block's mean moves as ``R <- R Exp(c w)``, ``w <- b w``; the
block is then re-expressed about the new reference (``phi' = Exp(c w)^T (phi - c w)`` to first
order, so its covariance is rotated by ``blockdiag(Exp(c w)^T, Exp(c w)^T)``) -- the usual
multiplicative (error-state) EKF, exact for a constant body angular velocity.

**Measurement.**  The measurement of a frame is the component's pose; what the images say about it
is the tracker's per-component information ``C_i`` (``sum w L^T L`` over its edge samples, in body
twist coordinates).  We take the covariance of a weighted least-squares estimate, ``V = s' C_i^-1``
with ``s' = s sigma0_i^2`` and ``sigma0_i^2 = sum w m^2 / (n_i - 6)`` the a-posteriori variance of
unit weight of the component's fit (:func:`variance_factor`: small on clean renderings, large on
cluttered real footage, so one ``s`` trusts clean images and distrusts cluttered ones; values in
docs/motion-models.md), used in
information form ``V^-1 = C_i / s'`` so that a component without edges (``C_i = 0``, ``V`` infinite)
needs no inverse.  Why not the method's ``V = sigma^2 I`` on the pose?  In docs/method-physics.md ``V = sigma_v^2 I``
is the noise of the *data points*; their information about the parameters is ``H^T V^-1 H``
(section 3).  Our data are edge offsets with (IRLS-weighted) isotropic noise, so the same choice gives
exactly ``H^T V^-1 H = C_i / s'`` in pose space: a scalar ``V`` per sample (estimated from the
residuals), not per pose.  A scalar ``V`` on the 6-D pose itself would weigh a well-seen torso and a
half-hidden hand alike and mix metres with radians.  ``s`` absorbs what the residuals do not show:
the correlation of neighbouring samples, a consistently wrong edge.  The blocks are decoupled
(section 5), so each gets the *marginal* information of its 3 coordinates (the Schur complement
``C_tt - C_tr C_rr^-1 C_rt``, translation rotated into world coordinates), never more than the data
hold.

**Update = the IRLS solve.**  The tracker minimises ``sum rho(m) + 1/2 d^T (s' P_xx^-1) d`` about the
predicted pose (:func:`prior_information` gives ``s' P_xx^-1`` in body twist coordinates, ``s'`` of
the previous frame): with data information ``C / s'`` that is the MAP of the filter's measurement
update (the iterated EKF), and it also applies the joint constraints of the whole tree.  So the
tracked pose *is* the posterior mean of the position part, ``x+``, and :func:`correct` completes the
update of the other half of the state: the velocity ``u`` is not observed, so given ``x+`` (any data
that depend on ``x`` only)

    u+ = u + P_ux P_xx^-1 (x+ - x),    P+ = P - J (P_xx - P_xx+) J^T,    J = [I3; P_ux P_xx^-1],
    P_xx+ = (P_xx^-1 + C / s')^-1,

which equals the textbook update ``K = P H^T (H P H^T + V)^-1``, ``H = [I3 0]`` (``update`` in
tests/tracking/test_motion_prior.py does that from a measured pose and is tested against it).  A component's
``C_i`` counts its own edges only, not what its neighbours say through the joints, so its ``P_xx+``
errs on the large side (its prior on the next frame on the weak side).

**Prior about the prediction.**  The information ``s' P_xx^-1`` of the predicted position replaces the
fixed ``prior_translation``/``prior_rotation``, which remain as its floor (eigenvalues below them are
raised to them): that keeps every ``C_i`` invertible (docs/method-tracking.md, section 3) and bounds how
far the prior can fade while a component has no data; a component without data keeps moving with its
velocity while its covariance grows (``q dt^3 / 3`` per frame and more).

Relation to docs/method-physics.md, section 5 (``fitting_step`` in tests/tracking/test_motion_prior.py): its first-order
filter runs the Riccati equation over inner iterations of one frame; integrated over unit pseudo-time on a linear
measurement it gives exactly our discrete update, and with ``P = I`` held (no Riccati step) it is plain dynamic
fitting, ``qdot = H^T V^-1 r - K q`` (eqs. 16/18).  Its "same fixed point" holds for rigid
blocks (``K = 0``, ours); with stiffness the filter stops where ``P g = K q``, not ``g = K q``.

**Between frames.**  :class:`Motion` is all a tracker carries from frame to frame for its motion model: this filter's
state and noise scales, and for constant velocity the poses of the frame before.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from tracker.geometry.se3 import exp_so3_many, log_so3_many

TRANSLATION, ROTATION = 0, 1
INITIAL_SPEED = 1.0  # prior standard deviation of the unknown first velocity, m/s
INITIAL_SPIN = 3.0  # ... and angular velocity, rad/s


@dataclass(frozen=True)
class MotionState:
    """The filter of every component (N): means and covariances of both blocks.

    ``poses`` (N,4,4): the world position ``t`` of each component (mean of the translation block) and
    the reference rotation ``R`` of the rotation block (``phi = 0``).  ``velocity`` (N,2,3): world
    velocity ``v`` (m/s) and body angular velocity ``w`` (rad/s).  ``covariance`` (N,2,6,6): per block
    the covariance of ``(x, u)``, ``x`` the world position error (translation) or ``phi`` (rotation, body
    coordinates of ``R``), ``u`` the velocity error in the same coordinates.
    """

    poses: np.ndarray
    velocity: np.ndarray
    covariance: np.ndarray


@dataclass(frozen=True)
class Motion:
    """What a tracker carries from frame to frame for its motion model (``Settings.motion.dynamics``), whole to a
    tracker for other cameras: the poses it tracked in the frame before the last (constant velocity carries the motion
    between them on; None after a start), and with dynamics "kalman" the filter's state (None otherwise) and each
    component's measurement noise scale ``s'`` (N,) (module docstring, "Measurement")."""

    previous: np.ndarray | None
    kalman: MotionState | None
    noise_scale: np.ndarray


def initial_state(
    poses: np.ndarray, position_variance=(1e-3, 0.1), velocity_variance=(INITIAL_SPEED**2, INITIAL_SPIN**2)
) -> MotionState:
    """At rest at ``poses`` with isotropic covariances per block: position ``(m^2, rad^2)`` and velocity
    ``((m/s)^2, (rad/s)^2)``."""
    n = poses.shape[0]
    cov = np.zeros((n, 2, 6, 6))
    for b in (TRANSLATION, ROTATION):
        cov[:, b, :3, :3] = position_variance[b] * np.eye(3)
        cov[:, b, 3:, 3:] = velocity_variance[b] * np.eye(3)
    return MotionState(np.array(poses, dtype=np.float64), np.zeros((n, 2, 3)), cov)


def transition(dt: float, decay: float = 0.0) -> np.ndarray:
    """The 2x2 scalar transition ``[[1, c], [0, b]]`` (``Phi = it (x) I3``) of ``F`` over ``dt``:
    ``b = e^(-gamma dt)``, ``c = (1 - b) / gamma`` (``dt`` when ``gamma = 0``)."""
    b, c = _decay_terms(dt, decay)
    return np.array([[1.0, c], [0.0, b]])


def _decay_terms(dt: float, gamma: float) -> tuple[float, float]:
    x = gamma * dt
    if x < 1e-8:
        return 1.0 - x, dt * (1.0 - 0.5 * x)
    return float(np.exp(-x)), float(-np.expm1(-x) / gamma)


def noise_integral(dt: float, decay: float = 0.0) -> np.ndarray:
    """``Bq = int_0^dt [c(s); b(s)] [c(s), b(s)] ds`` so that the process noise is ``q Bq (x) I3``.

    With ``x = gamma dt``, ``E1 = 1 - e^-x`` and ``E2 = 1 - e^-2x``:
    ``int b^2 = E2 / (2 gamma)``, ``int c b = (E1 - E2 / 2) / gamma^2``,
    ``int c^2 = (dt - 2 E1 / gamma + E2 / (2 gamma)) / gamma^2``; their series in ``x`` (below 1e-3)
    start with ``dt``, ``dt^2 / 2``, ``dt^3 / 3`` -- the constant-velocity model's values.
    """
    g = decay
    x = g * dt
    if x < 1e-3:  # series, exact to O(x^3) relative
        bb = dt * (1.0 - x + 2.0 * x * x / 3.0)
        cb = dt * dt * (0.5 - x / 2.0 + 7.0 * x * x / 24.0)
        cc = dt**3 * (1.0 / 3.0 - x / 4.0 + 7.0 * x * x / 60.0)
    else:
        e1 = -np.expm1(-x)
        e2 = -np.expm1(-2.0 * x)
        bb = e2 / (2.0 * g)
        cb = (e1 - 0.5 * e2) / (g * g)
        cc = (dt - 2.0 * e1 / g + e2 / (2.0 * g)) / (g * g)
    return np.array([[cc, cb], [cb, bb]])


def propagate_covariance(covariance: np.ndarray, dt: float, *, q, decay: float = 0.0) -> np.ndarray:
    """``Phi P Phi^T + q Bq (x) I3``: the Riccati equation without data over ``dt``, solved exactly.

    ``covariance`` (..., 6, 6); ``q`` a scalar or an array broadcasting against its leading axes.
    """
    phi, noise = _block_matrices(float(dt), float(decay))
    q = np.asarray(q, dtype=np.float64)[..., None, None]
    out = phi @ covariance @ phi.T + q * noise
    return 0.5 * (out + np.swapaxes(out, -1, -2))


@lru_cache(maxsize=64)
def _block_matrices(dt: float, decay: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi and Bq (x) I3 (6x6 each), cached: a recording has one frame interval."""
    eye = np.eye(3)
    return np.kron(transition(dt, decay), eye), np.kron(noise_integral(dt, decay), eye)


def predict(state: MotionState, dt: float, *, q=(1.0, 10.0), decay: float = 0.0) -> MotionState:
    """Every component ``dt`` seconds ahead: ``t <- t + c v``, ``v <- b v``, ``R <- R Exp(c w)``,
    ``w <- b w``, covariances by :func:`propagate_covariance` (``q = (q_t, q_r)``), the rotation block
    re-expressed about the new reference."""
    b, c = _decay_terms(dt, decay)
    poses = state.poses.copy()
    velocity = state.velocity * b
    poses[:, :3, 3] += c * state.velocity[:, TRANSLATION]
    step = exp_so3_many(np.ascontiguousarray(c * state.velocity[:, ROTATION]))
    poses[:, :3, :3] = state.poses[:, :3, :3] @ step
    cov = propagate_covariance(state.covariance, dt, q=np.asarray(q, dtype=np.float64)[None, :], decay=decay)
    cov[:, ROTATION] = _rotate_block(cov[:, ROTATION], step)
    return MotionState(poses, velocity, cov)


def rereference(state: MotionState, poses: np.ndarray) -> MotionState:
    """The filter about other poses (the prediction after :meth:`Model.coerce`): the means move there
    (the projection of the predicted estimate onto the joint constraints), the covariances stay, the
    rotation block re-expressed in the new body frame (``D = R_old^T R_new``: ``w <- D^T w``)."""
    poses = np.array(poses, dtype=np.float64)
    turn = np.swapaxes(state.poses[:, :3, :3], -1, -2) @ poses[:, :3, :3]
    velocity = state.velocity.copy()
    velocity[:, ROTATION] = np.einsum("nba,nb->na", turn, state.velocity[:, ROTATION])
    cov = state.covariance.copy()
    cov[:, ROTATION] = _rotate_block(cov[:, ROTATION], turn)
    return MotionState(poses, velocity, cov)


def _rotate_block(cov: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """``T P T^T`` with ``T = blockdiag(D^T, D^T)``: a (phi, w) covariance (N,6,6) seen from frames
    turned by D (N,3,3)."""
    t = np.zeros(cov.shape)
    dt_ = np.swapaxes(turn, -1, -2)
    t[:, :3, :3] = dt_
    t[:, 3:, 3:] = dt_
    out = t @ cov @ np.swapaxes(t, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def position_inverse(state: MotionState) -> np.ndarray:
    """``P_xx^-1`` (N,2,3,3): the inverse position covariance of each block, for :func:`prior_information`
    and :func:`correct` of the same state to share."""
    return np.linalg.inv(state.covariance[:, :, :3, :3])


def prior_information(state: MotionState, *, scale=1.0, floor=(0.0, 0.0), p_xx_inv=None) -> np.ndarray:
    """The tracker's prior (N,6,6) about ``state.poses`` in body twist coordinates (translation first):
    ``s blockdiag(R^T Pt_xx^-1 R, Pr_xx^-1)``, each 3x3 block's eigenvalues raised to at least
    ``floor = (per m^2, per rad^2)``; ``scale`` s a scalar or one per component.  (A body twist ``(v, w)``
    moves the origin by ``R v``.)  ``p_xx_inv``: :func:`position_inverse` of ``state`` if at hand."""
    n = state.poses.shape[0]
    rot = state.poses[:, :3, :3]
    scale = np.broadcast_to(np.asarray(scale, dtype=np.float64), (n,))[:, None, None, None]
    info = scale * (position_inverse(state) if p_xx_inv is None else p_xx_inv)  # (N,2,3,3)
    info[:, TRANSLATION] = np.swapaxes(rot, -1, -2) @ info[:, TRANSLATION] @ rot
    info = _floored(info, np.array([max(floor[0], 0.0), max(floor[1], 0.0)]))
    out = np.zeros((n, 6, 6))
    out[:, :3, :3] = info[:, TRANSLATION]
    out[:, 3:, 3:] = info[:, ROTATION]
    return out


def _floored(info: np.ndarray, floor) -> np.ndarray:
    """Symmetric (..., 2, 3, 3) matrices with the eigenvalues of block b raised to at least ``floor[b]``."""
    values, vectors = np.linalg.eigh(0.5 * (info + np.swapaxes(info, -1, -2)))
    values = np.maximum(values, np.asarray(floor, dtype=np.float64)[:, None])
    return (vectors * values[..., None, :]) @ np.swapaxes(vectors, -1, -2)


def block_information(information: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Per component (N,2,3,3) the marginal information of each block from a 6x6 body-twist information
    ``C`` (translation first): translation ``R (C_tt - C_tr C_rr^-1 C_rt) R^T`` (world coordinates),
    rotation ``C_rr - C_rt C_tt^-1 C_tr`` (body); regularised (symmetrised, a relative 1e-9 ridge in the
    inverse, eigenvalues clipped at 0)."""
    c = 0.5 * (information + np.swapaxes(information, -1, -2))
    tr = c[:, :3, 3:]
    rt = np.swapaxes(tr, -1, -2)
    diagonal = np.stack([c[:, :3, :3], c[:, 3:, 3:]], axis=1)  # (N,2,3,3)
    ridge = 1e-9 * np.trace(diagonal, axis1=-2, axis2=-1) + 1e-300
    inverse = np.linalg.inv(diagonal + ridge[..., None, None] * np.eye(3))
    out = np.empty_like(diagonal)
    out[:, TRANSLATION] = diagonal[:, TRANSLATION] - tr @ inverse[:, ROTATION] @ rt
    out[:, ROTATION] = diagonal[:, ROTATION] - rt @ inverse[:, TRANSLATION] @ tr
    rot = poses[:, :3, :3]
    out[:, TRANSLATION] = rot @ out[:, TRANSLATION] @ np.swapaxes(rot, -1, -2)
    return _floored(out, (0.0, 0.0))


def variance_factor(
    component: np.ndarray,
    offset: np.ndarray,
    weight: np.ndarray,
    *,
    n_components: int,
    pooled_weight: float = 12.0,
    fallback=1.0,
) -> np.ndarray:
    """Per component the a-posteriori variance of unit weight of its IRLS fit (weighted least squares:
    ``Cov = sigma0^2 C^-1``), ``sigma0_i^2 = sum w m^2 / (n_i - 6)`` over its samples that found an edge,
    shrunk towards the value pooled over all components with the weight of ``pooled_weight`` samples (so
    that a component with a handful of samples gets about the pooled value); ``fallback`` (a scalar or one
    per component, e.g. the last frame's) when no sample found an edge.  Offsets ``m`` in pixels, weights
    ``w`` from the IRLS."""
    found = weight > 0.0
    comp = component[found]
    wm2 = weight[found] * offset[found] ** 2
    sums = np.bincount(comp, weights=wm2, minlength=n_components)
    counts = np.bincount(comp, minlength=n_components).astype(np.float64)
    dof = counts.sum() - 6.0 * np.count_nonzero(counts)
    if dof <= 0:
        return np.broadcast_to(np.asarray(fallback, dtype=np.float64), (n_components,)).copy()
    pooled = sums.sum() / dof
    return (sums + pooled_weight * pooled) / (np.maximum(counts - 6.0, 0.0) + pooled_weight)


def _difference(poses: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per component, the blocks (N, 2, 3) from ``poses`` to ``target``: ``t' - t`` and ``log(R^T R')`` (body)."""
    diff = np.empty((poses.shape[0], 2, 3))
    diff[:, TRANSLATION] = target[:, :3, 3] - poses[:, :3, 3]
    diff[:, ROTATION] = log_so3_many(np.ascontiguousarray(np.swapaxes(poses[:, :3, :3], -1, -2) @ target[:, :3, :3]))
    return diff


def correct(state: MotionState, poses: np.ndarray, information: np.ndarray, *, p_xx_inv=None) -> MotionState:
    """The measurement update given the posterior poses ``x+`` (the tracked poses) and the data's
    information per block ``W = C / s'`` (N,2,3,3, from :func:`block_information` divided by ``s'``;
    ``p_xx_inv``: :func:`position_inverse` of ``state`` if at hand):

        P_xx+ = (P_xx^-1 + W)^-1,  G = P_ux P_xx^-1,  u+ = u + G (x+ - x),  P+ = P - J (P_xx - P_xx+) J^T,
        J = [I3; G]

    with ``x+ - x = t+ - t`` (translation) and ``log(R^T R+)`` (rotation, body); the rotation block is
    then re-expressed about ``R+`` (:func:`rereference`)."""
    poses = np.asarray(poses, dtype=np.float64)
    diff = _difference(state.poses, poses)
    cov = state.covariance
    p_xx = cov[..., :3, :3]
    p_ux = cov[..., 3:, :3]
    if p_xx_inv is None:
        p_xx_inv = position_inverse(state)
    # W's symmetric part: block_information's V diag(l) V^T is symmetric only to round-off relative to its
    # largest eigenvalue, and with a nearly unobservable direction that asymmetry moves P_xx+ visibly
    posterior = np.linalg.inv(p_xx_inv + 0.5 * (information + np.swapaxes(information, -1, -2)))
    gain = p_ux @ p_xx_inv
    velocity = state.velocity + np.einsum("nbij,nbj->nbi", gain, diff)
    j = np.concatenate([np.broadcast_to(np.eye(3), gain.shape), gain], axis=-2)  # (N,2,6,3)
    cov = cov - j @ (p_xx - posterior) @ np.swapaxes(j, -1, -2)
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    return rereference(MotionState(state.poses, velocity, cov), poses)  # takes x+ (a copy of poses) as the means
