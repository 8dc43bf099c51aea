"""Continuous extended Kalman filter for one deformable-superquadric part (design note
metaxas-terzopoulos-math.md, section 5; the paper's eqs 37-38).

The model is the first-order one of section 3 with D = I: the state u is the part's q =
(c, phi, q_s, q_d), its dynamics qdot = g - K q, and the measurement of a point z_j attached
to its nearest node k(j) is z_j = x_k(j)(q) + noise with Jacobian H_j = L_k(j) (section 2).
With V = v I (v = sigma_v^2) and Q = q I the filter integrates, in pseudo-time over the inner
iterations on one frame of data,

    qdot = P H^T V^-1 r - K q                   (the state equation, eq 37)
    Pdot = -K P - P K + Q - P H^T V^-1 H P      (the Riccati equation, eq 38)

with r_j = z_j - x_k(j).  The gain P H^T V^-1 scales the data forces f_q = H^T V^-1 r of
``fitting.data_force`` (eq 16) per direction, so P acts as a (learnt) preconditioner of
dynamic fitting; with P = I the filter *is* dynamic fitting (``fitting.euler_step``).

Decoupling (section 5).  P keeps only the diagonal blocks of the four coordinate sets, each
integrated on its own: P_c (3x3), P_phi (3x3 over the world-frame increment dphi of
``kinematics.retract``), P_s (10x10 over q_s without a0) and P_d.  With isotropic V, Q and
P_d(0) the local block stays exactly P_d = P_node (x) I3 (n x n P_node), because K_dd =
K_node (x) I3 and H_d^T V^-1 H_d = diag(#points at node i / v) (x) I3: every term of the
Riccati equation keeps the (x) I3 structure.  Only P_node is stored.

One inner iteration (``iteration``) with information blocks A_b = H_b^T V^-1 H_b and forces
g_b = H_b^T V^-1 r:

    dt  = kappa / max_b rho(P_b A_b + K_b)         (rho: spectral radius)
    q_b <- q_b + dt (P_b g_b - K_b q_b)           (phi by R <- Exp([dphi]x) R, q_s clamped)
    P_b <- P_b + dt (-K_b P_b - P_b K_b + q I - P_b A_b P_b),  P_b <- (P_b + P_b^T) / 2

K_b is zero for c and phi, K_node (the loaded membrane over the current shell) for d, and for
q_s zero unless ``Settings.bend_stiffness`` is set (see below).

Findings of the note handled here:

* Gauge (section 1, degeneracy 4): a0 is frozen; P_s leaves it out and its step is zero.
* Initial covariance: the paper's P(0) (1 on the diagonal, 0.4 on the stiffness pattern) is
  indefinite at node level on the 123-node mesh (minimum eigenvalue -0.17).  The default is
  P(0) = I; ``initial_state`` validates any given P_node(0) with a Cholesky factorisation, and
  ``mesh_covariance`` builds the paper's pattern for a chosen off-diagonal value (positive
  definite on that mesh up to about 0.2).
* Stopping rule: the paper's "change below 1e-4 per step" bounds a rate, not convergence;
  ``filter_frame`` stops at ``Settings.max_iterations`` or when the largest coordinate change
  of one iteration falls below ``Settings.tol``, whichever comes first.
* The slow mode: with the blocks decoupled, c_x and b1 (with b3 small, cos r is nearly
  constant and b1 moves the shell along the model x axis like c does) form the weakest
  direction of H^T H, and the decoupled filter needs 1e4-1e5 iterations to settle it.  A
  small ``bend_stiffness`` k adds K_ss = k e_b1 e_b1^T, pulling b1 towards 0, which damps
  that mode at the price of a bias in b1.
* P is a gain: the Riccati equation runs over inner iterations of one frame, so P shrinks with
  pseudo-time, not with evidence; q and v are tuning parameters.
* Fixed point: P_b g_b = K_b q_b.  For c, phi and q_s (K = 0) that is dynamic fitting's
  H^T V^-1 r = 0, but for d the membrane acts as P_node^-1 K_node: as P_node settles (about
  0.03 I with Q = V = 0.1 I on the 123-node mesh) the filter smooths the local deformation
  some 30 times more than dynamic fitting does and no longer interpolates the data (the
  paper's remark that the filter "does not force the local deformations to interpolate").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from tracker.physics import fitting as fit
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

N_SHAPE = sq.N_PARAMETERS - 1
"""Size of P_s: q_s without the frozen a0."""

B1 = 8 - 1
"""Index of b1 in q_s without a0 (q_s = (a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3))."""


@dataclass(frozen=True)
class Settings:
    """Filter parameters (section 5).

    measurement_variance v: V = v I, so sigma_v = sqrt(v) in ``fitting.data_force``.
    process_noise q: Q = q I.  kappa: the step as a fraction of 1 / rho (Euler on a linear
    mode of rate lambda is stable for dt lambda < 2).  max_iterations, tol: the stopping rule of
    ``filter_frame``.  w0, w1: the loaded membrane K_node.  reassign_every: the nearest nodes
    k(j) and K_node are recomputed every that many iterations (the paper's footnote 5).
    bend_stiffness: the optional K_ss regulariser of b1.  local: False freezes d and P_node
    (a rigid + global part).
    """

    measurement_variance: float = 0.1
    process_noise: float = 0.1
    kappa: float = 0.5
    max_iterations: int = 200
    tol: float = 1e-6
    w0: float = 0.1
    w1: float = 0.5
    reassign_every: int = 10
    bend_stiffness: float = 0.0
    local: bool = True


@dataclass(frozen=True)
class State:
    """A part and its covariance blocks: P_c, P_phi (3, 3), P_s (10, 10, q_s without a0),
    P_node (n, n) with P_d = P_node (x) I3."""

    part: kin.Part
    p_c: np.ndarray
    p_phi: np.ndarray
    p_s: np.ndarray
    p_node: np.ndarray


@dataclass(frozen=True)
class Information:
    """A_b = H_b^T V^-1 H_b of each block: c, phi (3, 3), s (10, 10), and the diagonal of
    A_node (n,), with A_d = diag(node) (x) I3."""

    c: np.ndarray
    phi: np.ndarray
    s: np.ndarray
    node: np.ndarray


def check_covariance(p: np.ndarray, name: str = "covariance") -> np.ndarray:
    """p as a float array if it is symmetric positive definite, else ValueError.

    Positive definiteness is tested by a Cholesky factorisation; symmetry to 1e-12 of the
    largest entry.
    """
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != p.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {p.shape}")
    if not np.allclose(p, p.T, rtol=0.0, atol=1e-12 * np.max(np.abs(p))):
        raise ValueError(f"{name} is not symmetric")
    try:
        np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        smallest = np.linalg.eigvalsh(p)[0]
        raise ValueError(f"{name} is not positive definite (smallest eigenvalue {smallest:.3g})") from None
    return p


def mesh_covariance(triangles: np.ndarray, n_nodes: int, off_diagonal: float, diagonal: float = 1.0) -> np.ndarray:
    """The paper's P_node(0): ``diagonal`` on the diagonal, ``off_diagonal`` between the nodes
    of a common triangle (the sparsity pattern of K_node), zero elsewhere (section 5).

    With the paper's 0.4 it is positive definite per element (minimum eigenvalue 0.6) but
    not at node level on the 123-node mesh; ``check_covariance`` says so.
    """
    rows, cols = np.repeat(triangles, 3, axis=1).ravel(), np.tile(triangles, 3).ravel()
    adjacency = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_nodes, n_nodes)).toarray() > 0
    p = np.where(adjacency, off_diagonal, 0.0)
    np.fill_diagonal(p, diagonal)
    return p


def initial_state(part: kin.Part, scale: float = 1.0, p_node: np.ndarray | None = None) -> State:
    """P_c = P_phi = scale I3, P_s = scale I10 and P_node = scale I (default) or the given
    P_node(0), which must be symmetric positive definite (``check_covariance``)."""
    n = len(part.u)
    if p_node is None:
        p_node = scale * np.eye(n)
    p_node = check_covariance(p_node, "P_node(0)")
    if p_node.shape != (n, n):
        raise ValueError(f"P_node(0) must be {n} x {n} for this part, got {p_node.shape}")
    return State(part, scale * np.eye(3), scale * np.eye(3), scale * np.eye(N_SHAPE), p_node)


def information(part: kin.Part, assignment: np.ndarray, variance: float) -> Information:
    """The diagonal blocks of H^T V^-1 H = sum_j L_k(j)^T L_k(j) / v (section 5).

    With n_i points attached to node i, y_i = R p_i and J_i without its a0 column:

        A_c = (sum n_i) I3 / v,   A_phi = sum n_i [y_i]x^T [y_i]x / v = sum n_i (|y_i|^2 I3 - y_i y_i^T) / v
        A_s = sum n_i J_i^T J_i / v   (R^T R = I),   A_node = diag(n_i / v)
    """
    counts = np.bincount(assignment, minlength=len(part.u)).astype(np.float64)
    y = (sq.shape(part.q_s, part.u, part.v) + part.d) @ part.rotation.T
    jac = sq.jacobian(part.q_s, part.u, part.v)[:, :, 1:]
    squared = np.einsum("i,ia,ia->", counts, y, y)
    a_phi = squared * np.eye(3) - np.einsum("i,ia,ib->ab", counts, y, y)
    a_s = np.einsum("i,iak,ial->kl", counts, jac, jac)
    return Information(counts.sum() * np.eye(3) / variance, a_phi / variance, a_s / variance, counts / variance)


def shape_stiffness(settings: Settings) -> np.ndarray:
    """K_ss (10 x 10 over q_s without a0): bend_stiffness at b1, zero elsewhere."""
    k = np.zeros((N_SHAPE, N_SHAPE))
    k[B1, B1] = settings.bend_stiffness
    return k


def _spectral_radius(m: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def step_size(state: State, info: Information, k_node: sp.spmatrix, settings: Settings) -> float:
    """dt = kappa / max_b rho(P_b A_b + K_b) over the blocks (section 5).

    P_b A_b + K_b is the rate matrix of block b's state equation linearised in the
    Gauss-Newton sense; Euler with dt rho < 2 is stable on its real eigenvalues.  rho is
    exact for c, phi and q_s.  For the local block (whose n x n P_node A_node + K_node has the
    spectrum of the 3n x 3n block) it is bounded by the infinity norm, the largest absolute
    row sum: an O(n^2) upper bound (any induced norm bounds rho) instead of a dense
    eigensolve per iteration, so dt can only come out smaller.
    """
    rates = [
        _spectral_radius(state.p_c @ info.c),
        _spectral_radius(state.p_phi @ info.phi),
        _spectral_radius(state.p_s @ info.s + shape_stiffness(settings)),
    ]
    if settings.local:
        rates.append(np.max(np.sum(np.abs(state.p_node * info.node + k_node.toarray()), axis=1)))
    return settings.kappa / max(rates)


def state_rate(state: State, force: np.ndarray, k_node: sp.spmatrix, settings: Settings) -> np.ndarray:
    """qdot = P g - K q by blocks, shape (part.n_coordinates,), from g = ``fitting.data_force``
    (section 5, eq 37).

    c: P_c g_c.  phi: P_phi g_phi.  q_s: (0, P_s g_s - K_ss q_s) with a0 frozen.  d:
    (P_node G - K_node d).ravel() with G the (n, 3) rows of g_d, which is P_d g_d - K_dd q_d for
    P_d = P_node (x) I3; zero if d is frozen (``Settings.local`` False).
    """
    part = state.part
    start = kin.SHAPE.stop
    rate = np.zeros(part.n_coordinates)
    rate[0:3] = state.p_c @ force[0:3]
    rate[3:6] = state.p_phi @ force[3:6]
    rate[kin.SHAPE.start + 1:start] = state.p_s @ force[kin.SHAPE.start + 1:start] - shape_stiffness(settings) @ part.q_s[1:]
    if settings.local:
        rate[start:] = (state.p_node @ force[start:].reshape(part.d.shape) - k_node @ part.d).ravel()
    return rate


def update_part(part: kin.Part, rate: np.ndarray, dt: float) -> kin.Part:
    """q <- q (+) dt qdot (``kinematics.retract``: R <- Exp([dt phidot]x) R), q_s clamped."""
    moved = kin.retract(part, dt * rate)
    return replace(moved, q_s=sq.clamp(moved.q_s))


def riccati_block(p: np.ndarray, a: np.ndarray, k: np.ndarray | sp.spmatrix | None, q: float, dt: float) -> np.ndarray:
    """One Euler step of Pdot = -K P - P K + q I - P A P for one block, symmetrised (eq 38).

    A is a matrix, or a vector holding a diagonal A; K a (sparse) matrix or None for K = 0.
    """
    pap = (p * a) @ p if a.ndim == 1 else p @ a @ p
    rate = q * np.eye(len(p)) - pap
    if k is not None:
        kp = np.asarray(k @ p)
        rate -= kp + kp.T
    out = p + dt * rate
    return 0.5 * (out + out.T)


def riccati(state: State, info: Information, k_node: sp.spmatrix, settings: Settings, dt: float) -> State:
    """The Riccati step of every block (``riccati_block``); P_node is kept if d is frozen."""
    q = settings.process_noise
    p_node = riccati_block(state.p_node, info.node, k_node, q, dt) if settings.local else state.p_node
    return replace(
        state,
        p_c=riccati_block(state.p_c, info.c, None, q, dt),
        p_phi=riccati_block(state.p_phi, info.phi, None, q, dt),
        p_s=riccati_block(state.p_s, info.s, shape_stiffness(settings), q, dt),
        p_node=p_node,
    )


def iteration(
    state: State, points: np.ndarray, assignment: np.ndarray, k_node: sp.spmatrix, settings: Settings
) -> tuple[State, float]:
    """One inner iteration (section 5): forces and information at the current estimate, the
    step dt, the state update, the Riccati update.  Returns the new state and the largest
    coordinate change max |dt qdot|."""
    variance = settings.measurement_variance
    force = fit.data_force(state.part, points, assignment, np.sqrt(variance))
    info = information(state.part, assignment, variance)
    dt = step_size(state, info, k_node, settings)
    rate = state_rate(state, force, k_node, settings)
    moved = riccati(replace(state, part=update_part(state.part, rate, dt)), info, k_node, settings, dt)
    return moved, float(np.max(np.abs(dt * rate)))


def filter_frame(
    state: State, points: np.ndarray, triangles: np.ndarray, settings: Settings
) -> tuple[State, int]:
    """Inner iterations on one frame of points (m, 3) until the largest coordinate change of an
    iteration is below ``settings.tol`` or ``settings.max_iterations`` are done.  Every
    ``settings.reassign_every`` iterations the nearest nodes and K_node (over the current
    shell) are recomputed.  Returns the state to carry to the next frame (q and P) and the
    number of iterations run."""
    for done in range(settings.max_iterations):
        if done % settings.reassign_every == 0:
            assignment = fit.nearest_nodes(points, kin.positions(state.part))
            k_node = fit.stiffness(state.part, triangles, settings.w0, settings.w1)
        state, change = iteration(state, points, assignment, k_node, settings)
        if change < settings.tol:
            return state, done + 1
    return state, settings.max_iterations
