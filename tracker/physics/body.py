"""A multi-part body: deformable superquadric parts joined by point-to-point constraints
(docs/method-physics.md, sections 2-4).

Each part is a ``kinematics.Part`` on its own ``superquadric.Mesh``.  Its rotation is kept as a
unit quaternion theta = (s, v) (scalar first, section 2): a step dphi (a world-frame rotation
increment) updates

    theta <- normalise(exp(dphi / 2) (x) theta),   exp(w) = (cos|w|, sin|w| w / |w|)

and R = R(theta).  Since R(exp(dphi / 2)) = Exp([dphi]x) this is the minimal update of docs/method-physics.md
R <- Exp([dphi]x) R (section 7: 'quaternion vs minimal update: 0'); the quaternion is the state,
R is derived from it.

A joint holds a material point (u, v) of part A on a material point of part B.  The point's
displacement is interpolated from the nodes with the linear-element weights w of
``superquadric.interpolation_matrix`` (S = w (x) I3), so a pole (u = +-pi/2) or any node is the
node itself and any other (u, v) is a blend.  Its position and Jacobian are

    x = c + R (s(q_s; u, v) + sum_i w_i d_i),   L = [ I3 | -[R p]x | R J(u, v) | w (x) R ]

Each part moves a subset of its coordinates, set by its level: RIGID (c, phi), GLOBAL (c, phi
and q_s) or LOCAL (c, phi, q_s and d).  a0 never moves: the gauge (a0, a1, a2, a3) ->
(k a0, a1/k, a2/k, a3/k) leaves the shape unchanged (section 1, degeneracy 4).

Two kinds of dynamics act on the active coordinates q:

- second order (section 3, eq 11; section 4): M qddot + D qdot + K q = g_q + f_q + G^T f_c with
  the lumped mass M = sum_i m_i L_i^T L_i (+ an explicit regulariser for non-rigid parts,
  whose M is singular), D = alpha M + beta I, g_q = -sum_i m_i L_i^T (Ldot qdot)_i and f_c from
  the Baumgarte system Cddot + 2a Cdot + a^2 C = 0; semi-implicit Euler
  (qdot <- qdot + dt qddot, then q <- q (+) dt qdot);
- first order (fitting, section 4): D qdot = F + G^T f_c with D = I, F = f_q - K q and
  f_c from Cdot + a C = 0, so N = G G^T, r = a C + G qdot_free; explicit Euler.

Data forces are those of ``fitting.data_force`` (eq 16): each 3-D point attaches to the nearest
node of the part it is labelled with, or to the nearest node over all parts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import cast

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from tracker.physics import constraints as con
from tracker.physics import fitting as fit
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

RIGID, GLOBAL, LOCAL = 0, 1, 2
"""Levels: which coordinates of a part move (c, phi | + q_s | + d)."""

SOUTH = (-np.pi / 2, 0.0)
NORTH = (np.pi / 2, 0.0)
"""Material points (u, v) of the poles, the ends of a part's model z axis (node 0 and node n - 1)."""

_LOCAL_START = kin.SHAPE.stop


def quaternion_product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p (x) q of scalar-first quaternions (..., 4):
    (p0 q0 - pv . qv, p0 qv + q0 pv + pv x qv)."""
    p, q = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    scalar = p[..., :1] * q[..., :1] - np.sum(p[..., 1:] * q[..., 1:], axis=-1, keepdims=True)
    vector = p[..., :1] * q[..., 1:] + q[..., :1] * p[..., 1:] + np.cross(p[..., 1:], q[..., 1:])
    return np.concatenate([scalar, vector], axis=-1)


def quaternion_exp(w: np.ndarray) -> np.ndarray:
    """exp of the pure quaternion (0, w): (cos|w|, sin|w| w / |w|), shape (..., 4)."""
    w = np.asarray(w, dtype=np.float64)
    angle = np.linalg.norm(w, axis=-1, keepdims=True)
    return np.concatenate([np.cos(angle), np.sinc(angle / np.pi) * w], axis=-1)


def rotation_matrix(theta: np.ndarray) -> np.ndarray:
    """R(theta) = (s^2 - v.v) I + 2 v v^T + 2 s [v]x of unit quaternions theta = (s, v), (..., 3, 3)."""
    theta = np.asarray(theta, dtype=np.float64)
    s, v = theta[..., 0], theta[..., 1:]
    out = 2.0 * v[..., :, None] * v[..., None, :]
    out += (s * s - np.sum(v * v, axis=-1))[..., None, None] * np.eye(3)
    sv = 2.0 * s[..., None] * v
    out[..., 0, 1] -= sv[..., 2]
    out[..., 0, 2] += sv[..., 1]
    out[..., 1, 0] += sv[..., 2]
    out[..., 1, 2] -= sv[..., 0]
    out[..., 2, 0] -= sv[..., 1]
    out[..., 2, 1] += sv[..., 0]
    return out


def rotate_quaternion(theta: np.ndarray, dphi: np.ndarray) -> np.ndarray:
    """theta <- normalise(exp(dphi / 2) (x) theta): R(theta) <- Exp([dphi]x) R(theta) (section 2)."""
    out = quaternion_product(quaternion_exp(0.5 * np.asarray(dphi, dtype=np.float64)), theta)
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Joint:
    """Constraint C = x_A(u_a, v_a) - x_B(u_b, v_b) = 0 between material points of parts a and b."""

    a: int
    point_a: tuple[float, float]
    b: int
    point_b: tuple[float, float]


def node_point(mesh: sq.Mesh, node: int) -> tuple[float, float]:
    """The material point (u, v) of a mesh node, for a joint at that node."""
    return float(mesh.u[node]), float(mesh.v[node])


@dataclass(frozen=True)
class Anchors:
    """The joints' material points on one part: u, v (k,) and interpolation weights w (k, n)."""

    u: np.ndarray
    v: np.ndarray
    weights: np.ndarray


@dataclass(frozen=True)
class Body:
    """Parts, their unit quaternions (P, 4) with part.rotation = R(theta), meshes, joints,
    levels (RIGID, GLOBAL or LOCAL per part), each part's ``Anchors`` and, per joint, the rows
    of its two points in the anchors of parts a and b (k, 2).  Build it with ``assemble``; move
    it with ``advance``."""

    parts: tuple[kin.Part, ...]
    quaternions: np.ndarray
    meshes: tuple[sq.Mesh, ...]
    joints: tuple[Joint, ...]
    levels: tuple[int, ...]
    anchors: tuple[Anchors, ...]
    rows: np.ndarray


def _anchors(mesh: sq.Mesh, points: list[tuple[float, float]]) -> Anchors:
    u = np.array([p[0] for p in points], dtype=np.float64)
    v = np.array([p[1] for p in points], dtype=np.float64)
    return Anchors(u, v, sq.interpolation_matrix(mesh, u, v).toarray().reshape(len(u), len(mesh.u)))


def assemble(
    parts: Sequence[kin.Part],
    meshes: Sequence[sq.Mesh],
    joints: Sequence[Joint],
    *,
    levels: int | Sequence[int] = LOCAL,
) -> Body:
    """A body from parts (whose u, v are their mesh's nodes), joints and levels (one or per part).
    The quaternions are taken from the parts' rotation matrices and R is re-derived from them."""
    theta = Rotation.from_matrix(np.stack([p.rotation for p in parts])).as_quat(scalar_first=True)
    parts = tuple(replace(p, rotation=r) for p, r in zip(parts, rotation_matrix(theta)))
    levels = (cast(int, levels),) * len(parts) if np.isscalar(levels) else tuple(cast(Sequence[int], levels))
    points: list[list[tuple[float, float]]] = [[] for _ in parts]
    rows = np.zeros((len(joints), 2), dtype=np.int64)
    for j, joint in enumerate(joints):
        for side, (p, point) in enumerate(((joint.a, joint.point_a), (joint.b, joint.point_b))):
            rows[j, side] = len(points[p])
            points[p].append(point)
    anchors = tuple(_anchors(m, pts) for m, pts in zip(meshes, points))
    return Body(parts, theta, tuple(meshes), tuple(joints), levels, anchors, rows)


def coordinates(part: kin.Part, level: int) -> np.ndarray:
    """Indices into q of the coordinates a part at this level moves (a0 never)."""
    stop = {RIGID: kin.RIGID, GLOBAL: _LOCAL_START, LOCAL: part.n_coordinates}[level]
    return np.delete(np.arange(stop), [fit.FROZEN]) if level > RIGID else np.arange(stop)


def active(body: Body, cap: int = LOCAL) -> list[np.ndarray]:
    """Active coordinates of every part at min(its level, cap)."""
    return [coordinates(p, min(level, cap)) for p, level in zip(body.parts, body.levels)]


def _scatter(part: kin.Part, values: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """A vector over all of the part's coordinates, zero outside the active ones."""
    out = np.zeros(part.n_coordinates)
    out[idx] = values
    return out


def _split(values: np.ndarray, index: Sequence[np.ndarray]) -> list[np.ndarray]:
    return np.split(values, np.cumsum([len(i) for i in index])[:-1])


def advance(body: Body, steps: Sequence[np.ndarray], index: Sequence[np.ndarray]) -> Body:
    """q <- q (+) dq per part, dq given on the active coordinates ``index``: c + dc, the
    quaternion by ``rotate_quaternion`` (R derived from it), q_s + dq_s (clamped), d + dd."""
    dqs = [_scatter(part, step, idx) for part, step, idx in zip(body.parts, steps, index)]
    theta = rotate_quaternion(body.quaternions, np.stack([dq[3:6] for dq in dqs]))
    parts = []
    for part, dq, r in zip(body.parts, dqs, rotation_matrix(theta)):
        dq[3:6] = 0.0
        moved = kin.retract(part, dq)
        parts.append(replace(moved, rotation=r, q_s=sq.clamp(moved.q_s)))
    return replace(body, parts=tuple(parts), quaternions=theta)


def all_positions(body: Body) -> list[np.ndarray]:
    """World node positions of every part."""
    return [kin.positions(p) for p in body.parts]


def _anchor_part(part: kin.Part, anchors: Anchors) -> kin.Part:
    """The part's anchors as nodes of a part of their own, displaced by the interpolated w . d."""
    return replace(part, d=anchors.weights @ part.d, u=anchors.u, v=anchors.v)


def anchor_jacobians(part: kin.Part, anchors: Anchors) -> np.ndarray:
    """L at each anchor, (k, 3, part.n_coordinates): [ I3 | -[R p]x | R J | w (x) R ]."""
    k = len(anchors.u)
    out = np.empty((k, 3, part.n_coordinates))
    if k == 0:
        return out
    out[:, :, :_LOCAL_START] = kin.rigid_global_jacobians(_anchor_part(part, anchors))
    out[:, :, _LOCAL_START:] = np.einsum("rn,ab->ranb", anchors.weights, part.rotation).reshape(k, 3, -1)
    return out


def _anchor_velocity_products(part: kin.Part, anchors: Anchors, qdot: np.ndarray) -> np.ndarray:
    """Ldot qdot at each anchor (k, 3): that of the anchor part with d-rates w . ddot."""
    rates = np.concatenate([qdot[:_LOCAL_START], (anchors.weights @ qdot[_LOCAL_START:].reshape(-1, 3)).ravel()])
    return kin.velocity_products(_anchor_part(part, anchors), rates)


def _joint_values(body: Body, per_part: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The rows of per-part anchor values (k_p, ...) at each joint's A and B points."""
    a = np.array([per_part[j.a][row] for j, row in zip(body.joints, body.rows[:, 0])])
    b = np.array([per_part[j.b][row] for j, row in zip(body.joints, body.rows[:, 1])])
    return a, b


def joint_positions(body: Body) -> tuple[np.ndarray, np.ndarray]:
    """x_A and x_B of every joint, each (k, 3)."""
    return _joint_values(body, [kin.positions(_anchor_part(p, a)) for p, a in zip(body.parts, body.anchors)])


def violation(body: Body) -> np.ndarray:
    """C = (x_A - x_B) stacked, shape (3k,) (section 4)."""
    return con.stack_differences(*joint_positions(body))


def constraint_jacobian(body: Body, index: Sequence[np.ndarray]) -> np.ndarray:
    """G (3k x sum of active sizes): +L_A and -L_B restricted to the active coordinates."""
    jacobians = [anchor_jacobians(p, a)[:, :, idx] for p, a, idx in zip(body.parts, body.anchors, index)]
    jac_a = [jacobians[j.a][row] for j, row in zip(body.joints, body.rows[:, 0])]
    jac_b = [jacobians[j.b][row] for j, row in zip(body.joints, body.rows[:, 1])]
    return con.stack_jacobian(
        jac_a,
        jac_b,
        parts_a=[j.a for j in body.joints],
        parts_b=[j.b for j in body.joints],
        sizes=[len(i) for i in index],
    )


def constraint_velocity_products(body: Body, full_qdots: Sequence[np.ndarray]) -> np.ndarray:
    """Gdot qdot = (Ldot_A qdot_A - Ldot_B qdot_B) stacked, shape (3k,); full_qdots over all
    coordinates of each part."""
    products = [_anchor_velocity_products(p, a, q) for p, a, q in zip(body.parts, body.anchors, full_qdots)]
    return con.stack_differences(*_joint_values(body, products))


@dataclass(frozen=True)
class Attachment:
    """Data points (m, 3) of one part and the node k(j) each attaches to (m,)."""

    points: np.ndarray
    nodes: np.ndarray


def attach(body: Body, points: np.ndarray, labels: np.ndarray | None = None) -> list[Attachment]:
    """Split points among parts and attach each to a node (eq 16).

    With labels (m,) (the part of each point, e.g. a marker's segment; -1 for none) a point
    attaches to the nearest node of its part; without, to the nearest node over all parts.
    Points with a non-finite coordinate (e.g. occluded markers stored as NaN) are left out.
    """
    points = np.asarray(points, dtype=np.float64)
    seen = np.isfinite(points).all(axis=1)
    nodes = all_positions(body)
    if labels is None:
        points = points[seen]
        offsets = np.concatenate([[0], np.cumsum([len(x) for x in nodes])])
        flat = fit.nearest_nodes(points, np.concatenate(nodes))
        labels = np.searchsorted(offsets, flat, side="right") - 1
        local = flat - offsets[labels]
        return [Attachment(points[labels == p], local[labels == p]) for p in range(len(nodes))]
    labels = np.where(seen, labels, -1)
    out = []
    for p, x in enumerate(nodes):
        mine = points[labels == p]
        out.append(Attachment(mine, fit.nearest_nodes(mine, x) if len(mine) else np.zeros(0, int)))
    return out


def residuals(body: Body, points: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    """Per part, the RMS distance of its points to their nodes (``attach``), shape (P,);
    NaN for a part without points."""
    out = np.full(len(body.parts), np.nan)
    for p, (part, att) in enumerate(zip(body.parts, attach(body, points, labels))):
        if len(att.points):
            out[p] = np.sqrt(np.mean(np.sum((att.points - kin.positions(part)[att.nodes]) ** 2, axis=1)))
    return out


def stiffnesses(body: Body, w0: float, w1: float) -> list[sp.csr_matrix | None]:
    """K_node of every LOCAL part over its current shell (``fitting.stiffness``), None otherwise."""
    return [
        fit.stiffness(p, m.triangles, w0=w0, w1=w1) if level == LOCAL else None
        for p, m, level in zip(body.parts, body.meshes, body.levels)
    ]


def free_forces(
    body: Body,
    attachments: Sequence[Attachment | None],
    *,
    sigma: float,
    k_nodes: Sequence[sp.spmatrix | None],
    index: Sequence[np.ndarray],
) -> list[np.ndarray]:
    """f_q - K q per part on its active coordinates: the data force of ``fitting.data_force``
    (zero without points) and K_dd q_d = (K_node d).ravel() when d is active."""
    out = []
    for part, att, k_node, idx in zip(body.parts, attachments, k_nodes, index):
        f = np.zeros(part.n_coordinates)
        if att is not None and len(att.points):
            f = fit.data_force(part, att.points, att.nodes, sigma=sigma)
        if k_node is not None:
            f[_LOCAL_START:] -= (k_node @ part.d).ravel()
        out.append(f[idx])
    return out


def _constraint_forces(n: np.ndarray, r: np.ndarray) -> np.ndarray:
    """f_c of ``constraints.solve_forces``; none for a body without joints."""
    return con.solve_forces(n, r) if len(r) else np.zeros(0)


def first_order_step(
    body: Body,
    attachments: Sequence[Attachment | None],
    *,
    sigma: float,
    k_nodes: Sequence[sp.spmatrix | None],
    dt: float,
    a: float,
    cap: int = LOCAL,
) -> Body:
    """One explicit Euler step of D qdot = F + G^T f_c, D = I (section 4, first order):

        qdot_free = F = f_q - K q,   N = G G^T,   r = a C + G qdot_free,   N f_c + r = 0,
        q <- q (+) dt (qdot_free + G^T f_c)

    so Cdot = -a C and C(t) = C0 e^{-at}.  ``cap`` limits the levels (GLOBAL freezes d)."""
    index = active(body, cap)
    qdot_free = np.concatenate(free_forces(body, attachments, sigma=sigma, k_nodes=k_nodes, index=index))
    g = constraint_jacobian(body, index)
    n, r = con.first_order_system(g, None, qdot_free, violation=violation(body), a=a)
    qdot = qdot_free + g.T @ _constraint_forces(n, r)
    return advance(body, _split(dt * qdot, index), index)


def first_order_limit(
    body: Body,
    attachments: Sequence[Attachment | None],
    *,
    sigma: float,
    k_nodes: Sequence[sp.spmatrix | None],
    cap: int = LOCAL,
) -> float:
    """min over parts of ``fitting.stability_limit`` = 2 / lambda_max(H^T H / s^2 + K) on each
    part's active coordinates at min(level, cap) (section 3, Euler).  It bounds the constrained
    step too: with D = I, qdot = P F (plus the Baumgarte term) with P the orthogonal projector
    onto G qdot = 0, and P A P has no larger eigenvalue than A.  Parts with neither data nor
    stiffness do not limit dt (inf)."""
    limits = [np.inf]
    for part, att, k_node, idx in zip(body.parts, attachments, k_nodes, active(body, cap)):
        nodes = att.nodes if att is not None else np.zeros(0, dtype=np.int64)
        if len(nodes) or k_node is not None:
            k = k_node if k_node is not None else sp.csr_matrix((len(part.u),) * 2)
            limits.append(fit.stability_limit(part, nodes, sigma=sigma, k_node=k, coordinates=idx))
    return min(limits)


def fit_frame(
    body: Body,
    points: np.ndarray,
    *,
    sigma: float,
    n_global: int,
    n_local: int,
    labels: np.ndarray | None = None,
    reassign_every: int = 10,
    w0: float = 0.1,
    w1: float = 0.5,
    step_fraction: float = 0.5,
    decay: float = 0.2,
) -> tuple[Body, np.ndarray]:
    """Constrained dynamic fitting to one frame of points: ``n_global`` first-order steps with d
    frozen (levels capped at GLOBAL), then ``n_local`` with every part at its level (the
    two-stage schedule of ``fitting.fit``).

    Every ``reassign_every`` steps the attachments (``attach``, by labels or nearest node over
    all parts), the membrane stiffnesses and dt = step_fraction * ``first_order_limit`` are
    recomputed, and the Baumgarte rate is set to a = decay / dt, so that the violation shrinks
    by about (1 - decay) per step (C0 e^{-at} in pseudo-time).  Returns the body and per step
    (before each and after the last) the mean point-to-node distance and max |C|, shape
    (n_global + n_local + 1, 2).
    """
    history = []
    for step in range(n_global + n_local):
        cap = GLOBAL if step < n_global else LOCAL
        if step % reassign_every == 0 or step == n_global:
            attachments = attach(body, points, labels)
            k_nodes = stiffnesses(body, w0, w1) if cap == LOCAL else [None] * len(body.parts)
            dt = step_fraction * first_order_limit(body, attachments, sigma=sigma, k_nodes=k_nodes, cap=cap)
        history.append(_progress(body, attachments))
        body = first_order_step(body, attachments, sigma=sigma, k_nodes=k_nodes, dt=dt, a=decay / dt, cap=cap)
    history.append(_progress(body, attach(body, points, labels)))
    return body, np.array(history)


def _progress(body: Body, attachments: Sequence[Attachment]) -> tuple[float, float]:
    distances = np.concatenate(
        [
            np.linalg.norm(att.points - kin.positions(part)[att.nodes], axis=1)
            for part, att in zip(body.parts, attachments)
        ]
    )
    return float(np.mean(distances)), float(np.abs(violation(body)).max(initial=0.0))


def initial_body(
    points: np.ndarray,
    labels: np.ndarray,
    *,
    meshes: Sequence[sq.Mesh],
    joints: Sequence[Joint],
    levels: int | Sequence[int] = LOCAL,
) -> Body:
    """Each part from the centroid and central moments of its labelled points
    (``fitting.initial_part``; section 6 and the paper's arm experiment); points with a
    non-finite coordinate (hidden markers) are left out."""
    seen = np.isfinite(points).all(axis=1)
    labels = np.where(seen, labels, -1)
    parts = [fit.initial_part(points[labels == p], m.u, m.v) for p, m in enumerate(meshes)]
    return assemble(parts, meshes, joints, levels=levels)


def material_points(part: kin.Part, mesh: sq.Mesh, points: Sequence[tuple[float, float]]) -> np.ndarray:
    """World positions of material points (u, v) of a part, c + R (s(u, v) + w . d), (k, 3)."""
    return kin.positions(_anchor_part(part, _anchors(mesh, list(points))))


def node_jacobians(body: Body, index: Sequence[np.ndarray]) -> list[np.ndarray]:
    """L_i of every node of every part on its active coordinates, (n, 3, len(index[p]))."""
    return [kin.active_jacobians(p, idx) for p, idx in zip(body.parts, index)]


def lumped_masses(body: Body, jacobians: Sequence[np.ndarray], *, mass: float, regularizer: float) -> list[np.ndarray]:
    """M per part on its active coordinates: sum_i m_i L_i^T L_i with m_i = mass / n (each part
    weighs ``mass``), plus regularizer * mass * I for non-rigid parts (``kinematics.lumped_mass``;
    section 3).  Their M alone is singular: q_s and d can move the nodes alike (rank <= 3 n),
    and with b3 small b1 acts as a translation (section 1, weak modes).  A small regulariser
    (1e-3) leaves those directions so light that the membrane and data forces swing q_s into
    its clamps within a second of simulated time; 0.1 (the second-order functions' default)
    keeps them tame."""
    return [
        kin.lumped_mass(l, np.full(len(p.u), mass / len(p.u)), regularizer * mass if l.shape[2] > kin.RIGID else 0.0)
        for p, l in zip(body.parts, jacobians)
    ]


@dataclass(frozen=True)
class Damping:
    """D = alpha M + beta I (section 3); ``alpha`` one rate for every part or one per part."""

    alpha: float | Sequence[float] | np.ndarray = 0.0
    beta: float = 0.0

    def rate(self, part: int) -> float:
        """alpha of part ``part``."""
        return float(cast(float, self.alpha) if np.isscalar(self.alpha) else cast(np.ndarray, self.alpha)[part])


def second_order_step(
    body: Body,
    qdots: Sequence[np.ndarray],
    attachments: Sequence[Attachment | None],
    *,
    sigma: float,
    k_nodes: Sequence[sp.spmatrix | None],
    dt: float,
    a: float,
    damping: Damping = Damping(),
    mass: float = 1.0,
    regularizer: float = 0.1,
) -> tuple[Body, list[np.ndarray]]:
    """One semi-implicit Euler step of M qddot + D qdot + K q = g_q + f_q + G^T f_c
    (section 3, eq 11; section 4, second order), velocities qdots on the active coordinates:

        F = g_q + f_q - K q - D qdot,   g_q = -sum_i m_i L_i^T (Ldot qdot)_i
        N = G M^-1 G^T,   r = Gdot qdot + 2a Cdot + a^2 C + G M^-1 F,   N f_c + r = 0
        qdot <- qdot + dt M^-1 (F + G^T f_c),   q <- q (+) dt qdot

    so C(t) = (C0 + (Cdot0 + a C0) t) e^{-at}.  A part without data feels no data force and
    coasts.  Returns the moved body and the new velocities."""
    index = active(body)
    jacobians = node_jacobians(body, index)
    masses = lumped_masses(body, jacobians, mass=mass, regularizer=regularizer)
    full = [_scatter(p, q, idx) for p, q, idx in zip(body.parts, qdots, index)]
    forces = free_forces(body, attachments, sigma=sigma, k_nodes=k_nodes, index=index)
    for p, (part, l, m, qdot) in enumerate(zip(body.parts, jacobians, masses, qdots)):
        g_q = -np.einsum("iak,ia->k", l, kin.velocity_products(part, full[p])) * (mass / len(part.u))
        forces[p] = forces[p] + g_q - damping.rate(p) * (m @ qdot) - damping.beta * qdot
    force = np.concatenate(forces)
    qdot = np.concatenate(qdots)
    g = constraint_jacobian(body, index)
    n, r = con.second_order_system(
        g, masses, force, qdot=qdot, gdot_qdot=constraint_velocity_products(body, full), violation=violation(body), a=a
    )
    new = _split(qdot + dt * con.block_solve(masses, force + g.T @ _constraint_forces(n, r)), index)
    return advance(body, [dt * q for q in new], index), new


def second_order_limit(
    body: Body,
    attachments: Sequence[Attachment | None],
    *,
    sigma: float,
    k_nodes: Sequence[sp.spmatrix | None],
    damping: Damping = Damping(),
    mass: float = 1.0,
    regularizer: float = 0.1,
) -> float:
    """Largest stable semi-implicit Euler step: per mode of frequency w and damping rate c the
    step matrix [[1 - dt^2 w^2, dt (1 - c dt)], [-dt w^2, 1 - c dt]] has |eigenvalues| < 1 iff
    c dt < 2 and dt^2 w^2 + 2 c dt < 4.  w^2 ranges over the generalised eigenvalues of
    (H^T H / s^2 + K, M) (data stiffness plus membrane, Gauss-Newton sense) and c over those of
    (D, M) (alpha + beta / lambda(M)); the bound dt = (sqrt(c^2 + 4 w^2) - c) / w^2 with the
    largest w and c is returned (min over parts).  The constraints add the Baumgarte rates
    (2a, a^2), which need a dt < 1 as well."""
    index = active(body)
    jacobians = node_jacobians(body, index)
    limits = []
    for p, (part, att, k_node, idx, l, m) in enumerate(
        zip(
            body.parts,
            attachments,
            k_nodes,
            index,
            jacobians,
            lumped_masses(body, jacobians, mass=mass, regularizer=regularizer),
        )
    ):
        stiff = np.zeros((len(idx),) * 2)
        if att is not None and len(att.points):
            counts = np.bincount(att.nodes, minlength=len(part.u)).astype(np.float64)
            h = (np.sqrt(counts)[:, None, None] * l).reshape(-1, len(idx))
            stiff += h.T @ h / sigma**2
        if k_node is not None:
            k_full = np.zeros((part.n_coordinates,) * 2)
            k_full[_LOCAL_START:, _LOCAL_START:] = np.kron(k_node.toarray(), np.eye(3))
            stiff += k_full[np.ix_(idx, idx)]
        top = len(idx) - 1
        w2 = sla.eigh(stiff, m, eigvals_only=True, subset_by_index=[top, top])[0]
        c = damping.rate(p) + damping.beta / np.linalg.eigvalsh(m)[0]
        if w2 > 0.0:
            limits.append((np.sqrt(c * c + 4.0 * w2) - c) / w2)
        elif c > 0.0:
            limits.append(2.0 / c)
    return min(limits, default=np.inf)
