"""Continuous extended Kalman filter for one deformable-superquadric part
(docs/method-physics.md, section 5; the paper's eqs 37-38).

The model is the first-order one of section 3 with D = I: the state u is the part's q =
(c, phi, q_s, q_d), its dynamics qdot = g - K q, and the measurement of a point z_j attached
to its nearest node k(j) (or to a known node, ``filter_frame``'s ``nodes``) is
z_j = x_k(j)(q) + noise with Jacobian H_j = L_k(j) (section 2).
With V = v I (v = sigma_v^2) and Q = q I the filter integrates, in pseudo-time over the inner
iterations on one frame of data,

    qdot = P H^T V^-1 r - K q                   (the state equation, eq 37)
    Pdot = -K P - P K + Q - P H^T V^-1 H P      (the Riccati equation, eq 38)

with r_j = z_j - x_k(j).  The gain P H^T V^-1 scales the data forces f_q = H^T V^-1 r of
``fitting.data_force`` (eq 16) per direction, so P acts as a (learnt) preconditioner of
dynamic fitting; with P = I the filter *is* dynamic fitting (``fitting.euler_step``).

Blocks (section 5).  P keeps diagonal blocks, each integrated on its own: P_g over the
rigid + global vector (c, dphi, q_s without a0; 16 x 16, dphi the world-frame increment of
``kinematics.retract``) and P_d over q_d.  P_g is either the paper's decoupled c | phi | q_s
(3x3, 3x3, 10x10; ``Settings.coupling`` "decoupled") or one joint block ("joint", docs/method-physics.md's
"joint rigid+global block").  With isotropic V, Q and P_d(0) the local block stays exactly
P_d = P_node (x) I3 (n x n P_node), because K_dd = K_node (x) I3 and H_d^T V^-1 H_d =
diag(#points at node i / v) (x) I3: every term of the Riccati equation keeps the (x) I3
structure.  Only P_node is stored.

Two forms of the stiffness K (``Settings.prior_stiffness``):

* dynamics form (the paper's, F = -K):  qdot = P g - K q,     Pdot = -K P - P K + Q - P A P;
* prior form (F = 0, the membrane energy q^T K q / 2 a Gaussian prior on q, i.e. a
  pseudo-measurement 0 = K^(1/2) q of unit information):
                                        qdot = P (g - K q),   Pdot = Q - P (A + K) P.

One inner iteration (``iteration``) with information blocks A_b = H_b^T V^-1 H_b and forces
g_b = H_b^T V^-1 r:

    dt  = kappa / max_b rho(P_b A_b + K_b)  or  kappa / max_b rho(P_b (A_b + K_b))
    q_b <- q_b + dt qdot_b                     (phi by R <- Exp([dphi]x) R, q_s clamped)
    P_b <- P_b + dt Pdot_b,  P_b <- (P_b + P_b^T) / 2,  then capped (``cap_eigenvalues``)

K_b is zero for c and phi, K_node (the loaded membrane over the current shell) for d, and
for b1 ``Settings.bend_stiffness`` (zero by default).

Findings of docs/method-physics.md, section 5, handled here:

* Gauge (section 1, degeneracy 4): a0 is frozen; P_g leaves it out and its step is zero.
* Initial covariance: the paper's P(0) (1 on the diagonal, 0.4 on the stiffness pattern) is
  indefinite at node level on the 123-node mesh (its eigenvalues: docs/physics.md).  The
  default is P(0) = I; ``initial_state`` validates any given P_node(0) with a Cholesky
  factorisation, and ``mesh_covariance`` builds the paper's pattern for a chosen off-diagonal
  value (positive definite on that mesh only for small ones).
* The slow mode: with the blocks decoupled, c_x and b1 (with b3 small, cos r is nearly
  constant and b1 moves the shell along the model x axis like c does) form the weakest
  direction of H^T H, which the block-diagonal P cannot precondition: it takes a great many
  iterations (docs/physics.md).  The joint block's Riccati equation does (its steady state sqrt(q) A^-1/2 turns the rate
  matrix P A into sqrt(q) A^1/2, whose condition number is the square root of A's), but
  along nearly unobservable directions (information lambda < q) that steady state exceeds
  P(0); ``Settings.covariance_cap`` bounds the eigenvalues of each block of P_g, and the
  optional b1 stiffness damps the mode at the price of a bias in b1.
* Fixed point and the membrane: the fixed point of the dynamics form is P_b g_b = K_b q_b.
  For c, phi and q_s (K = 0) that is dynamic fitting's H^T V^-1 r = 0, but for d the
  membrane acts as P_node^-1 K_node: as P_node settles well below I the filter smooths the
  local deformation many times more than dynamic fitting does (the paper's remark that the
  filter "does not force the local deformations to interpolate"; measured: docs/physics.md).
  The prior form's fixed point is g = K q, dynamic fitting's, for any P; P then only sets the
  path and speed.
* Stopping rule: the paper's "change below 1e-4 per step" bounds a rate, not convergence.
  ``filter_frame`` stops when the Gauss-Newton estimate of the distance to the frame's fixed
  point (``newton_step``) is below ``Settings.tol``, or at ``Settings.max_iterations``.
* P is a gain: the Riccati equation runs over inner iterations of one frame, so P shrinks with
  pseudo-time, not with evidence; q and v are tuning parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from tracker.physics import fitting as fit
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

N_SHAPE = sq.N_PARAMETERS - 1
"""Length of q_s without the frozen a0."""

N_GLOBAL = kin.RIGID + N_SHAPE
"""Length of the rigid + global vector (c, phi, q_s without a0) that P_g covers."""

GLOBAL = np.r_[0 : kin.RIGID, kin.SHAPE.start + 1 : kin.SHAPE.stop]
"""Where the rigid + global vector sits in q (a0 left out)."""

B1 = kin.RIGID + 7
"""Index of b1 in the rigid + global vector (q_s = (a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3))."""

BLOCKS = {
    "decoupled": (slice(0, 3), slice(3, kin.RIGID), slice(kin.RIGID, N_GLOBAL)),
    "joint": (slice(0, N_GLOBAL),),
}
"""The diagonal blocks of P_g for each ``Settings.coupling``: the paper's c | phi | q_s, or
one block."""


@dataclass(frozen=True)
class Settings:
    """Filter parameters (section 5).

    measurement_variance v: V = v I, so sigma_v = sqrt(v) in ``fitting.data_force``.
    process_noise q: Q = q I.  kappa: the step as a fraction of 1 / rho (Euler on a linear
    mode of rate lambda is stable for dt lambda < 2).  max_iterations, tol: the stopping rule of
    ``filter_frame``.  w0, w1: the loaded membrane K_node.  reassign_every: the nearest nodes
    k(j) and K_node are recomputed (and the stopping rule checked) every that many iterations
    (the paper's footnote 5).  bend_stiffness: the optional K_g regulariser of b1.  local:
    False freezes d and P_node (a rigid + global part).  coupling: "decoupled" (the paper's
    c | phi | q_s blocks) or "joint" (one 16 x 16 block).  prior_stiffness: K enters as a
    prior instead of as the dynamics F = -K (see the module docstring).  covariance_cap: the
    largest eigenvalue allowed in each block of P_g.  absorb: ``filter_frame`` moves what the
    rigid + global model can express of d into it (``absorb_global`` with ``absorb_damping``,
    three rounds) at every reassignment and at the end of a frame that hits the iteration cap.
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
    coupling: str = "decoupled"
    prior_stiffness: bool = False
    covariance_cap: float = np.inf
    absorb: bool = False
    absorb_damping: float = 10.0

    def __post_init__(self):
        if self.coupling not in BLOCKS:
            raise ValueError(f"coupling must be one of {tuple(BLOCKS)}, got {self.coupling!r}")


@dataclass(frozen=True)
class State:
    """A part and its covariance: P_g (16, 16) over (c, phi, q_s without a0), block-diagonal
    in the decoupled filter, and P_node (n, n) with P_d = P_node (x) I3."""

    part: kin.Part
    p_global: np.ndarray
    p_node: np.ndarray

    @property
    def p_c(self) -> np.ndarray:
        return self.p_global[0:3, 0:3]

    @property
    def p_phi(self) -> np.ndarray:
        return self.p_global[3 : kin.RIGID, 3 : kin.RIGID]

    @property
    def p_s(self) -> np.ndarray:
        return self.p_global[kin.RIGID :, kin.RIGID :]


@dataclass(frozen=True)
class Information:
    """A_g = H_g^T V^-1 H_g over (c, phi, q_s without a0) with its cross blocks (16, 16), and
    the diagonal of A_node (n,), with A_d = diag(node) (x) I3."""

    global_: np.ndarray
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


def mesh_covariance(triangles: np.ndarray, n_nodes: int, *, off_diagonal: float, diagonal: float = 1.0) -> np.ndarray:
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
    """P_g = scale I16 and P_node = scale I (default) or the given P_node(0), which must be
    symmetric positive definite (``check_covariance``)."""
    n = len(part.u)
    if p_node is None:
        p_node = scale * np.eye(n)
    p_node = check_covariance(p_node, "P_node(0)")
    if p_node.shape != (n, n):
        raise ValueError(f"P_node(0) must be {n} x {n} for this part, got {p_node.shape}")
    return State(part, scale * np.eye(N_GLOBAL), p_node)


def global_jacobians(part: kin.Part) -> np.ndarray:
    """L_g,i = [ I3 | -[y_i]x | R J_i ] (y_i = R p_i, J_i without its a0 column): the rigid +
    global columns of L_i (section 2), shape (n, 3, 16): ``kinematics.active_jacobians`` at ``GLOBAL``."""
    return kin.active_jacobians(part, GLOBAL)


def absorb_global(part: kin.Part, damping: float = 0.0, rounds: int = 3) -> kin.Part:
    """The same node positions with what the rigid + global model can express of the shell
    displacement d moved into (c, phi, q_s without a0); d keeps the rest.

    Each round solves the damped least squares (stacked over nodes, L_g = ``global_jacobians``,
    minimum norm where L_g is rank-deficient, e.g. b2 and b3 at b1 = 0)

        delta = argmin |L_g delta - (R d)|^2 + damping |delta|^2

    and moves c, R, q_s by ``update_part`` (R <- Exp(delta_phi) R, q_s clamped), then sets
    d <- R^T (x - c) - s(q_s) with the old positions x, so x is kept exactly.  Repeated rounds
    are a Levenberg-Marquardt iteration and converge to L_g^T R d = 0 (local deformation is
    what the global model cannot fit) unless a clamp bound stops them.  The damping makes the
    move gradual along directions L_g barely sees: with eigenvalue lambda of L_g^T L_g a round
    moves the fraction lambda / (lambda + damping) of what is left.
    """
    x = kin.positions(part)
    for _ in range(rounds):
        jac = global_jacobians(part).reshape(-1, N_GLOBAL)
        system = np.vstack([jac, np.sqrt(damping) * np.eye(N_GLOBAL)])
        target = np.concatenate([(part.d @ part.rotation.T).ravel(), np.zeros(N_GLOBAL)])
        step = np.zeros(part.n_coordinates)
        step[GLOBAL] = np.linalg.lstsq(system, target, rcond=None)[0]
        moved = update_part(part, step, 1.0)
        part = replace(moved, d=(x - moved.c) @ moved.rotation - sq.shape(moved.q_s, moved.u, moved.v))
    return part


def information(part: kin.Part, assignment: np.ndarray, variance: float) -> Information:
    """The information H^T V^-1 H = sum_j L_k(j)^T L_k(j) / v by blocks (section 5).

    With n_i points attached to node i: A_g = sum n_i L_g,i^T L_g,i / v (``global_jacobians``;
    its diagonal blocks are A_c = (sum n_i) I3 / v, A_phi = sum n_i (|y_i|^2 I3 - y_i y_i^T) / v
    and A_s = sum n_i J_i^T J_i / v) and A_node = diag(n_i / v).
    """
    counts = np.bincount(assignment, minlength=len(part.u)).astype(np.float64)
    jac = global_jacobians(part)
    a_g = np.einsum("i,iak,ial->kl", counts, jac, jac)
    return Information(a_g / variance, counts / variance)


def global_stiffness(settings: Settings) -> np.ndarray:
    """K_g (16 x 16 over c, phi, q_s without a0): bend_stiffness at b1, zero elsewhere."""
    k = np.zeros((N_GLOBAL, N_GLOBAL))
    k[B1, B1] = settings.bend_stiffness
    return k


def global_vector(part: kin.Part) -> np.ndarray:
    """The vector K_g acts on: zeros for c and phi (K_g has no entries there; phi is an
    increment, not a coordinate), then q_s without a0."""
    return np.concatenate([np.zeros(kin.RIGID), part.q_s[1:]])


def coupled(a_g: np.ndarray, settings: Settings) -> np.ndarray:
    """A_g as the filter's Riccati equation and step see it: whole ("joint") or only its
    diagonal blocks ("decoupled", the paper's choice)."""
    out = np.zeros_like(a_g)
    for b in BLOCKS[settings.coupling]:
        out[b, b] = a_g[b, b]
    return out


def _spectral_radius(m: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def step_size(state: State, info: Information, k_node: sp.spmatrix, *, settings: Settings) -> float:
    """dt = kappa / max_b rho(rate matrix of block b) (section 5).

    The rate matrix is P_b A_b + K_b (dynamics form) or P_b (A_b + K_b) (prior form): the
    Jacobian of block b's state equation linearised in the Gauss-Newton sense; Euler with
    dt rho < 2 is stable on its real eigenvalues.  rho is exact for P_g (block-diagonal in the
    decoupled filter, so its rho is the largest of the blocks').  For the local block (whose
    n x n matrix has the spectrum of the 3n x 3n block) it is bounded by the infinity norm, the
    largest absolute row sum: any induced norm bounds rho, so dt can only come out smaller.
    """
    a_g, k_g = coupled(info.global_, settings), global_stiffness(settings)
    p = state.p_global
    rates = [_spectral_radius(p @ (a_g + k_g) if settings.prior_stiffness else p @ a_g + k_g)]
    if settings.local:
        k = k_node.toarray()
        m = state.p_node @ (np.diag(info.node) + k) if settings.prior_stiffness else state.p_node * info.node + k
        rates.append(np.max(np.sum(np.abs(m), axis=1)))
    return settings.kappa / max(rates)


def state_rate(state: State, force: np.ndarray, k_node: sp.spmatrix, *, settings: Settings) -> np.ndarray:
    """qdot by blocks, shape (part.n_coordinates,), from g = ``fitting.data_force`` (eq 37).

    Dynamics form: P_g g_g - K_g theta and (P_node G - K_node d).ravel(); prior form: P_g (g_g -
    K_g theta) and (P_node (G - K_node d)).ravel().  theta = ``global_vector``, G the (n, 3) rows
    of g_d (P_d g_d = (P_node G).ravel() for P_d = P_node (x) I3).  a0 is frozen, and d too if
    ``Settings.local`` is False.
    """
    part = state.part
    start = kin.SHAPE.stop
    rate = np.zeros(part.n_coordinates)
    kq = global_stiffness(settings) @ global_vector(part)
    p = state.p_global
    rate[GLOBAL] = p @ (force[GLOBAL] - kq) if settings.prior_stiffness else p @ force[GLOBAL] - kq
    if settings.local:
        g, kd = force[start:].reshape(part.d.shape), k_node @ part.d
        local = state.p_node @ (g - kd) if settings.prior_stiffness else state.p_node @ g - kd
        rate[start:] = local.ravel()
    return rate


def update_part(part: kin.Part, rate: np.ndarray, dt: float) -> kin.Part:
    """q <- q (+) dt qdot (``kinematics.retract``: R <- Exp([dt phidot]x) R), q_s clamped."""
    moved = kin.retract(part, dt * rate)
    return replace(moved, q_s=sq.clamp(moved.q_s))


def riccati_block(
    p: np.ndarray,
    a: np.ndarray,
    k: np.ndarray | sp.spmatrix | None,
    *,
    q: float,
    dt: float,
    prior: bool = False,
) -> np.ndarray:
    """One Euler step of the Riccati equation (eq 38) for one block, symmetrised.

    Dynamics form (F = -K): Pdot = -K P - P K + q I - P A P.  Prior form (F = 0, K a
    pseudo-measurement of information K): Pdot = q I - P (A + K) P.  A is a matrix, or a
    vector holding a diagonal A; K a (sparse) matrix or None for K = 0.
    """
    pap = (p * a) @ p if a.ndim == 1 else p @ a @ p
    rate = q * np.eye(len(p)) - pap
    if k is not None:
        kp = np.asarray(k @ p)
        rate -= p @ kp if prior else kp + kp.T
    out = p + dt * rate
    return 0.5 * (out + out.T)


def cap_eigenvalues(p: np.ndarray, cap: float) -> np.ndarray:
    """p with its eigenvalues above ``cap`` set to cap (V min(Lambda, cap) V^T); p itself if
    none is."""
    if cap == np.inf:
        return p
    values, vectors = np.linalg.eigh(p)
    if values[-1] <= cap:
        return p
    out = (vectors * np.minimum(values, cap)) @ vectors.T
    return 0.5 * (out + out.T)


def riccati(state: State, info: Information, k_node: sp.spmatrix, *, settings: Settings, dt: float) -> State:
    """The Riccati step of every block of P_g (``riccati_block``, then ``cap_eigenvalues``) and
    of P_node (kept if d is frozen)."""
    q, prior = settings.process_noise, settings.prior_stiffness
    k_g = global_stiffness(settings)
    p_g = np.zeros_like(state.p_global)
    for b in BLOCKS[settings.coupling]:
        block = riccati_block(state.p_global[b, b], info.global_[b, b], k_g[b, b], q=q, dt=dt, prior=prior)
        p_g[b, b] = cap_eigenvalues(block, settings.covariance_cap)
    p_node = riccati_block(state.p_node, info.node, k_node, q=q, dt=dt, prior=prior) if settings.local else state.p_node
    return replace(state, p_global=p_g, p_node=p_node)


def newton_step(
    state: State, points: np.ndarray, assignment: np.ndarray, *, k_node: sp.spmatrix, settings: Settings
) -> np.ndarray:
    """The Gauss-Newton estimate of the way from the current q to the filter's fixed point on
    this frame: delta (16 + 3n, or 16 with d frozen) over (c, phi, q_s without a0, q_d).

    Linearised in the Gauss-Newton sense, the data force is g(q + delta) = g - A delta with the
    full A = H^T V^-1 H (cross blocks included, whatever the filter's coupling: they are
    terms of the force, not of P).  The fixed point qdot = 0 is g = K' q with the effective
    stiffness K' = K (prior form) or P^-1 K (dynamics form, from P g = K q), so

        (A + K') delta = g - K' q.

    Solved through the Schur complement of the local block: N = diag(n_i / v) + K'_node
    (n x n) acts on d (n, 3) column by column, and A_dg has rows (n_i / v) R^T L_g,i.
    Directions A + K' does not see at all (b2, b3 at b1 = 0) get no step (least squares).
    """
    part, v = state.part, settings.measurement_variance
    force = fit.data_force(part, points, assignment, sigma=np.sqrt(v))
    counts = np.bincount(assignment, minlength=len(part.u)).astype(np.float64)
    jac = global_jacobians(part)
    weighted = counts[:, None, None] * jac / v
    k_g = global_stiffness(settings)
    if not settings.prior_stiffness:
        k_g = np.linalg.solve(state.p_global, k_g)
    schur = np.einsum("iak,ial->kl", weighted, jac) + k_g
    rhs = force[GLOBAL] - k_g @ global_vector(part)
    if not settings.local:
        return np.linalg.lstsq(schur, rhs, rcond=None)[0]
    k_node = k_node.toarray()
    if not settings.prior_stiffness:
        k_node = np.linalg.solve(state.p_node, k_node)
    n = len(part.u)
    coupling = np.einsum("ba,ibk->iak", part.rotation, weighted)  # rows of A_dg
    factor = sla.lu_factor(np.diag(counts / v) + k_node)
    z = sla.lu_solve(factor, force[kin.SHAPE.stop :].reshape(n, 3) - k_node @ part.d)
    zz = sla.lu_solve(factor, coupling.reshape(n, -1)).reshape(coupling.shape)
    schur -= np.einsum("iak,ial->kl", coupling, zz)
    rhs -= np.einsum("iak,ia->k", coupling, z)
    step = np.linalg.lstsq(schur, rhs, rcond=None)[0]
    return np.concatenate([step, (z - zz @ step).ravel()])


def iteration(
    state: State, points: np.ndarray, assignment: np.ndarray, *, k_node: sp.spmatrix, settings: Settings
) -> tuple[State, float]:
    """One inner iteration (section 5): forces and information at the current estimate, the
    step dt, the state update, the Riccati update.  Returns the new state and the largest
    coordinate change max |dt qdot|."""
    variance = settings.measurement_variance
    force = fit.data_force(state.part, points, assignment, sigma=np.sqrt(variance))
    info = information(state.part, assignment, variance)
    dt = step_size(state, info, k_node, settings=settings)
    rate = state_rate(state, force, k_node, settings=settings)
    moved = riccati(replace(state, part=update_part(state.part, rate, dt)), info, k_node, settings=settings, dt=dt)
    return moved, float(np.max(np.abs(dt * rate)))


def filter_frame(
    state: State,
    points: np.ndarray,
    triangles: np.ndarray,
    *,
    settings: Settings,
    nodes: np.ndarray | None = None,
) -> tuple[State, int]:
    """Inner iterations on one frame of points (m, 3) until converged or
    ``settings.max_iterations`` are done.  Every ``settings.reassign_every`` iterations
    (before the first included) the nearest nodes and K_node (over the current shell) are
    recomputed and the stopping rule is checked: stop when the largest entry of the
    ``newton_step`` to the fixed point is below ``settings.tol``.  ``nodes`` (m,), if given,
    is the known node of every point (one-to-one correspondence), used instead of the
    nearest nodes.  With ``settings.absorb`` (and d free) the global coordinates absorb what
    they can of d before every reassignment, so also before every check of the stopping rule,
    and once more at the end of a frame that hits the cap.  Returns the state to carry to the
    next frame (q and P) and the number of iterations run."""
    absorbing = settings.absorb and settings.local
    for done in range(settings.max_iterations):
        if done % settings.reassign_every == 0:
            if absorbing:
                state = replace(state, part=absorb_global(state.part, settings.absorb_damping))
            assignment = fit.nearest_nodes(points, kin.positions(state.part)) if nodes is None else nodes
            k_node = fit.stiffness(state.part, triangles, w0=settings.w0, w1=settings.w1)
            if np.max(np.abs(newton_step(state, points, assignment, k_node=k_node, settings=settings))) < settings.tol:
                return state, done
        state, _ = iteration(state, points, assignment, k_node=k_node, settings=settings)
    if absorbing:
        state = replace(state, part=absorb_global(state.part, settings.absorb_damping))
    return state, settings.max_iterations
