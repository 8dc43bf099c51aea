"""Joint constraints, the O(N) kinematic-tree solve and coercion (docs/method-tracking.md, sections 4-5).

Components form a tree numbered so that ``parent[i] < i`` (the root has
``parent = -1``).  Component i has pose ``E_i`` (world from component) and moves
by a body twist ``alpha_i = (v; w)`` in its own frame, ``E_i <- E_i exp(alpha_i)``.

**Joint constraint** (section 4).  The joint between child i and its parent p
is given in the child's frame by a k x 6 matrix ``D_i`` that annihilates the
allowed relative motion ``delta = alpha_i - Ad(E_i^-1 E_p) alpha_p``:

    D_i alpha_i + D_pi alpha_p = 0,        D_pi = -D_i Ad(E_i^-1 E_p)

    ball  at p        (3 rows)  [I3 | -[p]x]                          allowed (p x w, w)
    hinge at p, axis d (5 rows)  [[I3, -[p]x], [0, u1^T], [0, u2^T]]    allowed theta (p x d, d)
    slide along d     (5 rows)  [[0, I3], [u1^T, 0], [u2^T, 0]]        allowed (s d, 0)
    fixed             (6 rows)  I6                                     allowed 0
    free              (0 rows)  -                                      anything

with (u1, u2, d) orthonormal.  The ball rows use ``-[p]x`` (FIX of the printed
eq. 12, which pins -p with right-handed rotation generators).

**Tree solve** (section 4).  Minimise ``sum_i (alpha_i - mu_i)^T C_i (alpha_i - mu_i)``,
``mu_i = C_i^-1 eta_i``, subject to every joint.  Upward, children before
parents, each child's propagated statistics (its whole subtree folded in) are
marginalised into its parent in information form:

    S_i = D_i C_i^-1 D_i^T
    eta_p <- eta_p - D_pi^T S_i^-1 D_i mu_i,     C_p <- C_p + D_pi^T S_i^-1 D_pi

then ``alpha_root = mu_root`` and, downward, with the child's *propagated*
``mu_i, C_i`` (eq. 19; the raw ones give the wrong answer):

    alpha_i = mu_i - C_i^-1 D_i^T S_i^-1 (D_pi alpha_p + D_i mu_i)

Each edge costs O(6^3 + k^3), so the solve is O(N).

**Coercion** (section 5).  After the update the joints are broken at second
order.  Going down the tree, with the already-repaired parent held fixed and the
rest transform ``T0_i`` (parent from child):

    a  = log(T0_i^-1 E_p^-1 E_i)                     (eq. 23)
    a' = a - D_i^T (D_i D_i^T)^-1 D_i a               (eq. 24, projection onto null(D_i))
    E_i <- E_p T0_i exp(a')                           (eq. 25)

``D_i`` is a model constant, so the projector ``Pi_i = D_i^T (D_i D_i^T)^-1 D_i`` is made once
(:func:`row_projectors`, kept on the model) and eq. 24 is ``a' = a - Pi_i a``.

``exp(a')`` is an exact joint motion (a rotation about p, about the line (p, d),
a translation along d), so the repair holds to round-off.  The same map
projects arbitrary poses onto the model's joint set.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.geometry.se3 import between, exp, log, point_velocity

FREE = 0
BALL = 1
HINGE = 2
SLIDE = 3
FIXED = 4
JOINT_TYPES = {"free": FREE, "ball": BALL, "hinge": HINGE, "slide": SLIDE, "fixed": FIXED}


def _orthonormal_pair(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit d = axis/|axis| and u1, u2 such that (u1, u2, d) is a right-handed orthonormal basis."""
    norm = np.linalg.norm(axis)
    if not norm > 1e-12:
        raise ValueError(f"a hinge or slide axis must be non-zero, got {axis!r}")
    d = axis / norm
    u1 = np.cross(d, np.eye(3)[np.argmin(np.abs(d))])
    u1 /= np.linalg.norm(u1)
    return d, u1, np.cross(d, u1)


def constraint_rows(joint_type: int, point, axis) -> np.ndarray:
    """The child-side constraint matrix D12 (k x 6) in the child's frame (section 4).

    ``point`` is the joint point p and ``axis`` the hinge or slide direction d
    (normalised here), both in child coordinates.  The rows annihilate the
    allowed relative motion: ball ``[I3 | -[p]x]``, hinge ``[[I3, -[p]x], [0, u1^T],
    [0, u2^T]]``, slide ``[[0, I3], [u1^T, 0], [u2^T, 0]]``, fixed ``I6``, free none.
    """
    p = np.asarray(point, dtype=np.float64)
    if joint_type == FREE:
        return np.zeros((0, 6))
    if joint_type == BALL:
        return point_velocity(p)
    if joint_type == FIXED:
        return np.eye(6)
    if joint_type not in (HINGE, SLIDE):
        raise ValueError(f"unknown joint type code {joint_type!r}; use one of {JOINT_TYPES}")
    _, u1, u2 = _orthonormal_pair(np.asarray(axis, dtype=np.float64))
    out = np.zeros((5, 6))
    if joint_type == HINGE:
        out[0:3] = point_velocity(p)
        out[3, 3:6] = u1
        out[4, 3:6] = u2
    else:
        out[0:3, 3:6] = np.eye(3)
        out[3, 0:3] = u1
        out[4, 0:3] = u2
    return out


def pack_constraints(blocks) -> tuple[np.ndarray, np.ndarray]:
    """Flat numba form of per-component constraint matrices.

    Returns ``D`` (N, 6, 6) with block i's k_i rows on top and zeros below, and
    ``rows`` (N,) int64 holding k_i.
    """
    n = len(blocks)
    packed = np.zeros((n, 6, 6))
    rows = np.zeros(n, dtype=np.int64)
    for i, block in enumerate(blocks):
        block = np.asarray(block, dtype=np.float64)
        if block.ndim != 2 or block.shape[1] != 6 or block.shape[0] > 6:
            raise ValueError(f"constraint block {i} must be (k, 6) with k <= 6, got shape {block.shape}")
        packed[i, : block.shape[0]] = block
        rows[i] = block.shape[0]
    return packed, rows


def row_projectors(D, rows) -> np.ndarray:
    """Per component the projector ``Pi_i = D_i^T (D_i D_i^T)^-1 D_i`` (N, 6, 6) onto the row space of its
    ``rows[i]`` constraint rows (zero for free components): coercion's eq. 24 is ``a' = a - Pi_i a``."""
    D = np.ascontiguousarray(D, dtype=np.float64)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    out = np.zeros((D.shape[0], 6, 6))
    for i in range(D.shape[0]):
        k = int(rows[i])
        if k > 0:
            d = D[i, :k]
            out[i] = d.T @ np.linalg.solve(d @ d.T, d)
    return out


@njit(cache=True)
def _invert(a, n, out, work):
    """out[:n, :n] = a[:n, :n]^-1 by Gauss-Jordan elimination with partial pivoting (work: n x 2n)."""
    for r in range(n):
        for c in range(n):
            work[r, c] = a[r, c]
            work[r, n + c] = 1.0 if r == c else 0.0
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(work[r, col]) > abs(work[pivot, col]):
                pivot = r
        if pivot != col:
            for c in range(2 * n):
                work[col, c], work[pivot, c] = work[pivot, c], work[col, c]
        scale = 1.0 / work[col, col]
        for c in range(2 * n):
            work[col, c] *= scale
        for r in range(n):
            factor = work[r, col]
            if r != col and factor != 0.0:
                for c in range(2 * n):
                    work[r, c] -= factor * work[col, c]
    for r in range(n):
        for c in range(n):
            out[r, c] = work[r, n + c]


@njit(cache=True)
def _relative_adjoint(child, parent, out):
    """out = Ad(E_child^-1 E_parent) = [[R, [t]x R], [0, R]] with R = R_c^T R_p, t = R_c^T (t_p - t_c)."""
    r = np.empty((3, 3))
    t = np.empty(3)
    for a in range(3):
        t[a] = 0.0
        for b in range(3):
            r[a, b] = 0.0
            for c in range(3):
                r[a, b] += child[c, a] * parent[c, b]
            t[a] += child[b, a] * (parent[b, 3] - child[b, 3])
    out[:] = 0.0
    for a in range(3):
        for b in range(3):
            out[a, b] = r[a, b]
            out[3 + a, 3 + b] = r[a, b]
    for b in range(3):  # [t]x R, column by column: t x R[:, b]
        out[0, 3 + b] = t[1] * r[2, b] - t[2] * r[1, b]
        out[1, 3 + b] = t[2] * r[0, b] - t[0] * r[2, b]
        out[2, 3 + b] = t[0] * r[1, b] - t[1] * r[0, b]


@njit(cache=True)
def solve_kernel(information, eta, parent, D, rows, poses):
    """MAP twists of the whole tree (section 4): upward marginalisation, downward back-substitution.

    Upward, for i = N-1 ... 1 with p = parent(i) and the propagated (C_i, eta_i):
    mu_i = C_i^-1 eta_i, S_i = D_i C_i^-1 D_i^T, K_i = C_i^-1 D_i^T S_i^-1 and

        eta_p -= D_pi^T S_i^-1 D_i mu_i,    C_p += D_pi^T S_i^-1 D_pi.

    The back-substitution alpha_i = mu_i - K_i (D_pi alpha_p + D_i mu_i) is kept
    as alpha_i = b_i + G_i alpha_p with b_i = mu_i - K_i D_i mu_i and G_i = -K_i D_pi.
    Roots (parent < 0) and free children (k_i = 0) get alpha_i = mu_i.  Small
    matrices are multiplied in loops over preallocated scratch (no allocation per
    component).
    """
    n = information.shape[0]
    info = information.copy()
    eta_up = eta.copy()
    alpha = np.empty((n, 6))
    gain = np.zeros((n, 6, 6))
    c_inv = np.empty((6, 6))
    work = np.empty((6, 12))
    adj = np.empty((6, 6))
    d_p = np.empty((6, 6))
    c_inv_dt = np.empty((6, 6))
    s_mat = np.empty((6, 6))
    s_inv = np.empty((6, 6))
    k_gain = np.empty((6, 6))
    dpt_s_inv = np.empty((6, 6))
    mu = np.empty(6)
    d_mu = np.empty(6)
    for i in range(n - 1, -1, -1):
        _invert(info[i], 6, c_inv, work)
        for a in range(6):
            mu[a] = 0.0
            for b in range(6):
                mu[a] += c_inv[a, b] * eta_up[i, b]
        p = parent[i]
        k = rows[i]
        if p < 0 or k == 0:
            alpha[i] = mu
            continue
        d_i = D[i]
        _relative_adjoint(poses[i], poses[p], adj)
        for r in range(k):
            d_mu[r] = 0.0
            for c in range(6):
                d_mu[r] += d_i[r, c] * mu[c]
                value = 0.0
                for m in range(6):
                    value += d_i[r, m] * adj[m, c]
                d_p[r, c] = -value
        for a in range(6):  # C^-1 D^T (6 x k)
            for r in range(k):
                value = 0.0
                for m in range(6):
                    value += c_inv[a, m] * d_i[r, m]
                c_inv_dt[a, r] = value
        for r in range(k):  # S = D C^-1 D^T (k x k)
            for q in range(k):
                value = 0.0
                for m in range(6):
                    value += d_i[r, m] * c_inv_dt[m, q]
                s_mat[r, q] = value
        _invert(s_mat, k, s_inv, work)
        for a in range(6):  # D_p^T S^-1 (6 x k) and K = C^-1 D^T S^-1 (6 x k)
            for q in range(k):
                v1 = 0.0
                v2 = 0.0
                for r in range(k):
                    v1 += d_p[r, a] * s_inv[r, q]
                    v2 += c_inv_dt[a, r] * s_inv[r, q]
                dpt_s_inv[a, q] = v1
                k_gain[a, q] = v2
        for a in range(6):
            correction = 0.0
            step = 0.0
            for q in range(k):
                correction += dpt_s_inv[a, q] * d_mu[q]
                step += k_gain[a, q] * d_mu[q]
            eta_up[p, a] -= correction
            alpha[i, a] = mu[a] - step
            for b in range(6):
                v1 = 0.0
                v2 = 0.0
                for q in range(k):
                    v1 += dpt_s_inv[a, q] * d_p[q, b]
                    v2 += k_gain[a, q] * d_p[q, b]
                info[p, a, b] += v1
                gain[i, a, b] = -v2
    for i in range(1, n):
        p = parent[i]
        if p >= 0 and rows[i] > 0:
            for a in range(6):
                for b in range(6):
                    alpha[i, a] += gain[i, a, b] * alpha[p, b]
    return alpha


def solve(information, eta, *, parent, D, rows, poses) -> np.ndarray:
    """MAP motions alpha (N, 6) of a kinematic tree (section 4); see :func:`solve_kernel`.

    ``information`` (N,6,6) C_i and ``eta`` (N,6) eta_i = C_i mu_i per component,
    ``parent`` (N,) with parent[i] < i, ``D``/``rows`` from :func:`pack_constraints`,
    ``poses`` (N,4,4) world from component.  Apply as E_i <- E_i exp(alpha_i).
    """
    parent = _check_order(parent)
    return solve_kernel(
        np.ascontiguousarray(information, dtype=np.float64),
        np.ascontiguousarray(eta, dtype=np.float64),
        parent,
        np.ascontiguousarray(D, dtype=np.float64),
        np.ascontiguousarray(rows, dtype=np.int64),
        np.ascontiguousarray(poses, dtype=np.float64),
    )


@njit(cache=True)
def coerce_kernel(poses, parent, rest, projector, rows, joint_type, axis, lower, upper, twist):
    """Repair the joints parents first (section 5, eqs. 23-25 with T0), within the joint limits.

    For each constrained child i with p = parent(i): a = log(T0_i^-1 E_p^-1 E_i),
    a' = a - Pi_i a with Pi_i = D_i^T (D_i D_i^T)^-1 D_i (``projector``, :func:`row_projectors`),
    E_i <- E_p T0_i exp(a').  Roots and free
    children keep their poses.  A hinge's a' = theta (p x d, d) and a slide's
    a' = (s d, 0) are then scaled so that theta (or s) lies in [lower_i, upper_i];
    a ball's turn about its child's z axis (along a limb's bone) is first brought within +-``twist_i``
    (:func:`within_twist`; the joint lies at the child's origin, so a' = (0, w)), then its rotation from
    rest so that |w| <= upper_i.
    """
    out = poses.copy()
    pi_a = np.empty(6)
    for i in range(out.shape[0]):
        p = parent[i]
        if p < 0 or rows[i] == 0:
            continue
        at_rest = out[p] @ rest[i]
        a = log(between(at_rest, out[i]))
        pi_i = projector[i]
        for r in range(6):
            value = 0.0
            for c in range(6):
                value += pi_i[r, c] * a[c]
            pi_a[r] = value
        for r in range(6):
            a[r] -= pi_a[r]
        if joint_type[i] == BALL and twist[i] < np.inf:
            a[3:6] = within_twist(a[3:6], twist[i])
        if joint_type[i] == BALL and upper[i] < np.inf:
            angle = np.sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5])
            if angle > upper[i]:
                a *= upper[i] / angle
        elif joint_type[i] == HINGE or joint_type[i] == SLIDE:
            part = a[3:6] if joint_type[i] == HINGE else a[0:3]
            amount = part[0] * axis[i, 0] + part[1] * axis[i, 1] + part[2] * axis[i, 2]
            clamped = min(max(amount, lower[i]), upper[i])
            if clamped != amount:
                if amount != 0.0:
                    a *= clamped / amount
                elif joint_type[i] == HINGE:
                    a[3:6] = clamped * axis[i]
                else:
                    a[0:3] = clamped * axis[i]
        out[i] = at_rest @ exp(a)
    return out


@njit(cache=True, nogil=True)
def _quaternion(w):
    """The unit quaternion (x, y, z, w) of the rotation vector ``w``."""
    angle = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    s = 0.5 if angle < 1e-12 else np.sin(angle / 2.0) / angle
    return w[0] * s, w[1] * s, w[2] * s, np.cos(angle / 2.0)


@njit(cache=True, nogil=True)
def twist_angle(w):
    """The turn tau in (-pi, pi] about z of the rotation vector ``w`` in the swing-twist split R = S T: T the turn
    about z, applied first, S a swing with no turn about z.  0 where the swing is a half turn (tau undefined)."""
    _, _, qz, qw = _quaternion(w)
    if np.sqrt(qz * qz + qw * qw) < 1e-9:
        return 0.0
    tau = 2.0 * np.arctan2(qz, qw)
    if tau > np.pi:
        tau -= 2.0 * np.pi
    elif tau < -np.pi:
        tau += 2.0 * np.pi
    return tau


def twist_gradient(w: np.ndarray) -> np.ndarray:
    """d :func:`twist_angle` / d ``w`` (3,): with q = (sin(theta/2) w/theta, cos(theta/2)), theta = |w|,
    tau = 2 atan2(q_z, q_w) and d tau = 2 (q_w dq_z - q_z dq_w) / (q_z^2 + q_w^2)."""
    w = np.asarray(w, dtype=np.float64)
    angle = float(np.linalg.norm(w))
    if angle < 1e-8:
        return np.array([0.0, 0.0, 1.0])
    qz, qw = _quaternion(w)[2:]
    unit = w / angle
    f = np.sin(angle / 2) / angle
    slope = (angle / 2 * np.cos(angle / 2) - np.sin(angle / 2)) / angle**2  # df / d theta
    d_qz = f * np.array([0.0, 0.0, 1.0]) + w[2] * slope * unit
    d_qw = -0.5 * np.sin(angle / 2) * unit
    return 2 * (qw * d_qz - qz * d_qw) / (qz * qz + qw * qw)


@njit(cache=True, nogil=True)
def within_twist(w, limit):
    """The rotation vector ``w`` with its :func:`twist_angle` brought within +-``limit`` radians and its swing
    kept; unchanged within it."""
    tau = twist_angle(w)
    if abs(tau) <= limit:
        return w.copy()
    qx, qy, qz, qw = _quaternion(w)
    norm = np.sqrt(qz * qz + qw * qw)
    tz, tw = qz / norm, qw / norm  # T, whose inverse (0, 0, -tz, tw) takes it out: S = q T^-1
    sx = qx * tw - qy * tz
    sy = qy * tw + qx * tz
    sw = qw * tw + qz * tz
    half = np.copysign(limit, tau) / 2.0
    cz, cw = np.sin(half), np.cos(half)
    nx = sx * cw + sy * cz  # S C with C = (0, 0, cz, cw), the turn at the limit
    ny = sy * cw - sx * cz
    nz = sw * cz
    nw = sw * cw
    if nw < 0.0:
        nx, ny, nz, nw = -nx, -ny, -nz, -nw
    vector = np.sqrt(nx * nx + ny * ny + nz * nz)
    out = np.zeros(3)
    if vector < 1e-15:
        return out
    turn = 2.0 * np.arctan2(vector, nw)
    out[0], out[1], out[2] = nx * turn / vector, ny * turn / vector, nz * turn / vector
    return out


def coerce(
    poses, *, parent, rest, D, rows, joint_type=None, axis=None, lower=None, upper=None, twist=None
) -> np.ndarray:
    """Poses (N,4,4) that satisfy every joint exactly (section 5); see :func:`coerce_kernel`.

    ``rest`` (N,4,4) holds T0_i (parent from child at rest).  Also projects arbitrary
    poses onto the joint set, e.g. a hinge keeps only the rotation about its axis.
    Without ``joint_type``/``axis``/``lower``/``upper`` no joint limits apply.
    """
    parent = _check_order(parent)
    n = parent.shape[0]
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    return coerce_kernel(
        np.ascontiguousarray(poses, dtype=np.float64),
        parent,
        np.ascontiguousarray(rest, dtype=np.float64),
        row_projectors(D, rows),
        rows,
        np.zeros(n, np.int64) if joint_type is None else np.ascontiguousarray(joint_type, dtype=np.int64),
        np.zeros((n, 3)) if axis is None else np.ascontiguousarray(axis, dtype=np.float64),
        np.full(n, -np.inf) if lower is None else np.ascontiguousarray(lower, dtype=np.float64),
        np.full(n, np.inf) if upper is None else np.ascontiguousarray(upper, dtype=np.float64),
        np.full(n, np.inf) if twist is None else np.ascontiguousarray(twist, dtype=np.float64),
    )


def motion_basis(projector, rows) -> list[np.ndarray]:
    """Per component a basis B_i (6 x (6 - k_i)) of the motions its joint allows relative to its parent, the null
    space of its constraint rows (``projector``, :func:`row_projectors`): I6 for roots and free components."""
    out = []
    for pi_i, k in zip(projector, rows):
        if k == 0:
            out.append(np.eye(6))
            continue
        values, vectors = np.linalg.eigh(np.eye(6) - pi_i)
        out.append(vectors[:, values > 0.5])
    return out


def marginal_information(information, *, parent, poses, basis) -> np.ndarray:
    """Per component the information (N, 6, 6) the whole body's cues give its twist alpha_i, through the joints: with
    the joints' coordinates theta (the roots' twists and each joint's allowed motion, ``basis``: :func:`motion_basis`),
    alpha = J theta, J's rows for i being Ad(E_i^-1 E_p) J_p + B_i for its own coordinates (section 4), the cost
    sum_i alpha_i^T C_i alpha_i gives theta the information H = J^T C J, and alpha_i the covariance
    J_i H^-1 J_i^T, whose inverse this is.  ``information`` C_i (N, 6, 6) must leave H invertible (a prior added)."""
    parent = _check_order(parent)
    n = parent.shape[0]
    widths = [b.shape[1] for b in basis]
    columns = np.concatenate([[0], np.cumsum(widths)])
    jac = np.zeros((n, 6, int(columns[-1])))
    for i in range(n):
        p = parent[i]
        if p >= 0 and widths[i] < 6:
            adj = np.empty((6, 6))
            _relative_adjoint(np.ascontiguousarray(poses[i]), np.ascontiguousarray(poses[p]), adj)
            jac[i] = adj @ jac[p]
        jac[i, :, columns[i] : columns[i + 1]] += basis[i]
    flat = jac.reshape(6 * n, -1)
    hessian = flat.T @ (information @ jac).reshape(6 * n, -1)
    blocks = jac @ np.linalg.inv(hessian) @ np.swapaxes(jac, 1, 2)
    return np.linalg.inv(0.5 * (blocks + np.swapaxes(blocks, 1, 2)))


def _check_order(parent) -> np.ndarray:
    """parent as int64, checked to satisfy parent[i] < i (both passes rely on it)."""
    parent = np.ascontiguousarray(parent, dtype=np.int64)
    if np.any(parent >= np.arange(parent.shape[0])):
        raise ValueError("components must be ordered so that parent[i] < i (root: -1)")
    return parent
