"""Joint constraints, the O(N) kinematic-tree solve and coercion (design note, sections 4-5).

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

``exp(a')`` is an exact joint motion (a rotation about p, about the line (p, d),
a translation along d), so the repair holds to round-off.  The same map
projects arbitrary poses onto the model's joint set.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.geometry.se3 import adjoint, exp, inverse, log, point_velocity

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


@njit(cache=True)
def solve_kernel(information, eta, parent, D, rows, poses):
    """MAP twists of the whole tree (section 4): upward marginalisation, downward back-substitution.

    Upward, for i = N-1 ... 1 with p = parent(i) and the propagated (C_i, eta_i):
    mu_i = C_i^-1 eta_i, S_i = D_i C_i^-1 D_i^T, K_i = C_i^-1 D_i^T S_i^-1 and

        eta_p -= D_pi^T S_i^-1 D_i mu_i,    C_p += D_pi^T S_i^-1 D_pi.

    The back-substitution alpha_i = mu_i - K_i (D_pi alpha_p + D_i mu_i) is kept
    as alpha_i = b_i + G_i alpha_p with b_i = mu_i - K_i D_i mu_i and G_i = -K_i D_pi.
    Roots (parent < 0) and free children (k_i = 0) get alpha_i = mu_i.
    """
    n = information.shape[0]
    info = information.copy()
    eta_up = eta.copy()
    alpha = np.empty((n, 6))
    gain = np.zeros((n, 6, 6))
    for i in range(n - 1, -1, -1):
        c_inv = np.linalg.inv(info[i])
        mu = c_inv @ eta_up[i]
        p = parent[i]
        k = rows[i]
        if p < 0 or k == 0:
            alpha[i] = mu
            continue
        d_i = D[i, :k].copy()
        d_p = -(d_i @ adjoint(inverse(poses[i]) @ poses[p]))
        c_inv_dt = c_inv @ d_i.T.copy()
        s_inv = np.linalg.inv(d_i @ c_inv_dt)
        dpt_s_inv = d_p.T.copy() @ s_inv
        d_mu = d_i @ mu
        eta_up[p] -= dpt_s_inv @ d_mu
        info[p] += dpt_s_inv @ d_p
        k_gain = c_inv_dt @ s_inv
        alpha[i] = mu - k_gain @ d_mu
        gain[i] = -(k_gain @ d_p)
    for i in range(1, n):
        if parent[i] >= 0 and rows[i] > 0:
            alpha[i] += gain[i] @ alpha[parent[i]]
    return alpha


def solve(information, eta, parent, D, rows, poses) -> np.ndarray:
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
def coerce_kernel(poses, parent, rest, D, rows, joint_type, axis, lower, upper):
    """Repair the joints parents first (section 5, eqs. 23-25 with T0), within the joint limits.

    For each constrained child i with p = parent(i): a = log(T0_i^-1 E_p^-1 E_i),
    a' = a - D_i^T (D_i D_i^T)^-1 D_i a, E_i <- E_p T0_i exp(a').  Roots and free
    children keep their poses.  A hinge's a' = theta (p x d, d) and a slide's
    a' = (s d, 0) are then scaled so that theta (or s) lies in [lower_i, upper_i];
    a ball's a' = (p x w, w) so that its rotation from rest |w| <= upper_i.
    """
    out = poses.copy()
    for i in range(out.shape[0]):
        p = parent[i]
        k = rows[i]
        if p < 0 or k == 0:
            continue
        at_rest = out[p] @ rest[i]
        a = log(inverse(at_rest) @ out[i])
        d_i = D[i, :k].copy()
        a -= d_i.T.copy() @ (np.linalg.inv(d_i @ d_i.T.copy()) @ (d_i @ a))
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


def coerce(poses, parent, rest, D, rows, joint_type=None, axis=None, lower=None, upper=None) -> np.ndarray:
    """Poses (N,4,4) that satisfy every joint exactly (section 5); see :func:`coerce_kernel`.

    ``rest`` (N,4,4) holds T0_i (parent from child at rest).  Also projects arbitrary
    poses onto the joint set, e.g. a hinge keeps only the rotation about its axis.
    Without ``joint_type``/``axis``/``lower``/``upper`` no joint limits apply.
    """
    parent = _check_order(parent)
    n = parent.shape[0]
    return coerce_kernel(
        np.ascontiguousarray(poses, dtype=np.float64),
        parent,
        np.ascontiguousarray(rest, dtype=np.float64),
        np.ascontiguousarray(D, dtype=np.float64),
        np.ascontiguousarray(rows, dtype=np.int64),
        np.zeros(n, np.int64) if joint_type is None else np.ascontiguousarray(joint_type, dtype=np.int64),
        np.zeros((n, 3)) if axis is None else np.ascontiguousarray(axis, dtype=np.float64),
        np.full(n, -np.inf) if lower is None else np.ascontiguousarray(lower, dtype=np.float64),
        np.full(n, np.inf) if upper is None else np.ascontiguousarray(upper, dtype=np.float64),
    )


def _check_order(parent) -> np.ndarray:
    """parent as int64, checked to satisfy parent[i] < i (both passes rely on it)."""
    parent = np.ascontiguousarray(parent, dtype=np.int64)
    if np.any(parent >= np.arange(parent.shape[0])):
        raise ValueError("components must be ordered so that parent[i] < i (root: -1)")
    return parent
