"""Dynamic fitting of one deformable superquadric part to 3-D points
(docs/method-physics.md, sections 3 and 5).

Data forces (eq 16): point z_j attaches to its nearest model node k(j); with the residual
r_j = z_j - x_k(j) and V = sigma^2 I the generalized force is

    f_q = sum_j L_k(j)^T r_j / sigma^2,

whose blocks are f_c = sum r_j / sigma^2, f_phi = sum (R p_k) x r_j / sigma^2 (a torque),
f_s = sum J_k^T R^T r_j / sigma^2 and f_d,i = R^T sum_{k(j)=i} r_j / sigma^2.

First-order dynamics with D = I (section 3, "First order"; section 5, the "degenerate Kalman
filter" with P = I): qdot = f_q - K q, K = blockdiag(0, 0, 0, K_dd), K_dd = K_node (x) I3 the
loaded membrane of ``superquadric.membrane_stiffness``.  Explicit Euler with the rotation
retracted (R <- Exp([dt f_phi]x) R) and q_s clamped after every step.

Gauge (section 1, degeneracy 4): (a0, a1, a2, a3) -> (k a0, a1/k, a2/k, a3/k) leaves the shape
unchanged, so a0 is frozen: ``initial_part`` sets a0 = 1 and the a0 component of every step is
zero.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, eigsh
from scipy.spatial import cKDTree

from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

FROZEN = kin.SHAPE.start
"""Index of a0 in q: the gauge coordinate held fixed (section 1, degeneracy 4)."""

SPHERE_VARIANCE = 1.0 / 3.0
"""Variance of each coordinate of a point uniformly distributed on the unit sphere."""


def nearest_nodes(points: np.ndarray, node_positions: np.ndarray) -> np.ndarray:
    """k(j): the index of the node nearest to each point z_j (section 3, eq 16), shape (m,)."""
    return cKDTree(node_positions).query(points)[1]


def node_residuals(part: kin.Part, points: np.ndarray, assignment: np.ndarray) -> np.ndarray:
    """g_i = sum_{k(j)=i} r_j with r_j = z_j - x_k(j): the residuals summed per node, shape (n, 3)."""
    r = points - kin.positions(part)[assignment]
    out = np.zeros_like(part.d)
    np.add.at(out, assignment, r)
    return out


def data_force(part: kin.Part, points: np.ndarray, assignment: np.ndarray, *, sigma: float) -> np.ndarray:
    """f_q = sum_j L_k(j)^T r_j / sigma^2 (section 3, eq 16), shape (part.n_coordinates,).

    Evaluated by blocks from the per-node sums g_i (``node_residuals``) without forming L:
    f_c = sum g_i, f_phi = sum (R p_i) x g_i, f_s = sum J_i^T R^T g_i, f_d,i = R^T g_i,
    all over sigma^2, with p_i = s_i + d_i.
    """
    g = node_residuals(part, points, assignment)
    r = part.rotation
    local_g = g @ r  # rows R^T g_i
    p = kin.local_points(part)
    f_s = np.einsum("iak,ia->k", sq.jacobian(part.q_s, part.u, part.v), local_g)
    f = np.concatenate([g.sum(axis=0), np.cross(p @ r.T, g).sum(axis=0), f_s, local_g.ravel()])
    return f / sigma**2


def stiffness(part: kin.Part, triangles: np.ndarray, *, w0: float, w1: float) -> sp.csr_matrix:
    """K_node = w0 M_h + w1 K_h over the part's current reference shell s(q_s) (section 3)."""
    return sq.membrane_stiffness(sq.shape(part.q_s, part.u, part.v), triangles, w0=w0, w1=w1)


def stability_limit(
    part: kin.Part,
    assignment: np.ndarray,
    *,
    sigma: float,
    k_node: sp.spmatrix,
    coordinates: np.ndarray | None = None,
) -> float:
    """2 / lambda_max(H^T H / sigma^2 + K) over the coordinates that move (section 3, Euler).

    H^T H = sum_i n_i L_i^T L_i with n_i the number of points attached to node i, and
    K = blockdiag(0, 0, 0, K_node (x) I3).  ``coordinates`` (indices into q) are the ones that
    move, by default all but a0 (frozen); a subset has the limit of its principal submatrix,
    which is never smaller (e.g. a rigid part is not held to the step its shape and nodal
    displacements would need).  lambda_max is the largest eigenvalue of that symmetric matrix,
    found by Lanczos iteration on its products with vectors.  The bound is that of the dynamics
    linearised in the Gauss-Newton sense (the r . d^2x/dq^2 terms dropped).
    """
    if coordinates is None:
        coordinates = np.delete(np.arange(part.n_coordinates), [FROZEN])
    counts = np.bincount(assignment, minlength=len(part.u)).astype(np.float64)
    h = (np.sqrt(counts)[:, None, None] * kin.active_jacobians(part, coordinates)).reshape(-1, len(coordinates)) / sigma
    k = sp.block_diag([sp.csr_matrix((kin.SHAPE.stop,) * 2), sp.kron(k_node, sp.identity(3))]).tocsr()
    k = k[coordinates][:, coordinates]
    a = LinearOperator((len(coordinates),) * 2, matvec=lambda x: h.T @ (h @ x) + k @ x, dtype=np.float64)
    top = eigsh(a, k=1, which="LA", v0=np.ones(a.shape[0]), return_eigenvectors=False)[0]
    return 2.0 / top


def euler_step(
    part: kin.Part,
    points: np.ndarray,
    assignment: np.ndarray,
    *,
    sigma: float,
    k_node: sp.spmatrix,
    dt: float,
    local: bool = True,
) -> kin.Part:
    """q <- q (+) dt (f_q - K q) (section 3, first order, D = I), a0 frozen, q_s clamped.

    K q is zero except K_dd q_d = (K_node d).ravel(); (+) is ``kinematics.retract``.  With
    ``local=False`` d is frozen too (only c, phi and q_s move).
    """
    qdot = data_force(part, points, assignment, sigma=sigma)
    if local:
        qdot[kin.SHAPE.stop :] -= (k_node @ part.d).ravel()
    else:
        qdot[kin.SHAPE.stop :] = 0.0
    qdot[FROZEN] = 0.0
    moved = kin.retract(part, dt * qdot)
    return replace(moved, q_s=sq.clamp(moved.q_s))


def mean_residual(part: kin.Part, points: np.ndarray) -> float:
    """Mean distance from each point to its nearest model node."""
    return float(np.mean(cKDTree(kin.positions(part)).query(points)[0]))


def fit(
    part: kin.Part,
    points: np.ndarray,
    triangles: np.ndarray,
    *,
    sigma: float,
    n_steps: int,
    reassign_every: int = 10,
    w0: float = 0.1,
    w1: float = 0.5,
    step_fraction: float = 0.5,
    local: bool = True,
) -> tuple[kin.Part, np.ndarray]:
    """Dynamic fitting (section 3, first order; section 5 with P = I) by ``n_steps`` Euler steps.

    Every ``reassign_every`` steps the nearest nodes k(j), the membrane stiffness K_node (over
    the current shell) and the step dt = step_fraction * ``stability_limit`` are recomputed;
    step_fraction < 1 keeps dt below the limit.  ``local=False`` freezes d (see ``euler_step``):
    fitting c, phi, q_s first and then everything avoids the nearest-node assignment locking
    in while the global shape is still off (starting from ``initial_part`` with d free, about a
    quarter of the nodes end with no data and the rest share them).  Returns the fitted part and the mean
    point-to-nearest-node distance before each step and after the last, shape (n_steps + 1,).
    """
    history = []
    for step in range(n_steps):
        if step % reassign_every == 0:
            assignment = nearest_nodes(points, kin.positions(part))
            k_node = stiffness(part, triangles, w0=w0, w1=w1)
            dt = step_fraction * stability_limit(part, assignment, sigma=sigma, k_node=k_node)
        history.append(mean_residual(part, points))
        part = euler_step(part, points, assignment, sigma=sigma, k_node=k_node, dt=dt, local=local)
    history.append(mean_residual(part, points))
    return part, np.array(history)


def initial_part(points: np.ndarray, u: np.ndarray, v: np.ndarray) -> kin.Part:
    """A part initialised from the moments of its data (points (m, 3), nodes at u, v).

    c = the centroid; the model axes are the eigenvectors of the central second-moment matrix
    C = mean (z - c)(z - c)^T: z along the largest-variance axis (the axis taper and bend act
    along), x along the middle one, y along the smallest.  Eigenvector signs are not determined
    by C: each of x and z is flipped so that its largest-magnitude component is positive and
    y = z x x makes R = [x y z] right-handed.  Gauge a0 = 1; scales a_i = sqrt(lambda_i / (1/3)),
    exact for points uniformly distributed over an ellipsoid's surface in the sense
    z = c + R diag(a) n with n uniform on the unit sphere.  eps1 = eps2 = 1, no taper, no bend
    (b1 = b2 = 0, b3 = 0.5 inside its clamp range, irrelevant while b1 = 0), d = 0.
    """
    c = points.mean(axis=0)
    centred = points - c
    variances, axes = np.linalg.eigh(centred.T @ centred / len(points))  # ascending
    x, z = axes[:, 1], axes[:, 2]
    x = x * np.sign(x[np.argmax(np.abs(x))])
    z = z * np.sign(z[np.argmax(np.abs(z))])
    rotation = np.column_stack([x, np.cross(z, x), z])
    a1, a2, a3 = np.sqrt(np.maximum(variances[[1, 0, 2]], 0.0) / SPHERE_VARIANCE)
    q_s = sq.clamp(np.array([1.0, a1, a2, a3, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5]))
    return kin.Part(c, rotation, q_s, np.zeros((len(u), 3)), np.asarray(u), np.asarray(v))
