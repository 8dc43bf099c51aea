"""Kinematics of one deformable-superquadric part (docs/method-physics.md, section 2).

A part carries the generalized coordinates

    q = (c (3), phi (3), q_s (11), q_d (3 per node))

where c is the world position of the model frame, phi a world-frame rotation increment (the
minimal parameterisation recommended in docs/method-physics.md: the rotation itself is kept as a matrix R and a
step dphi acts as R <- Exp([dphi]x) R), q_s the global shape parameters of ``superquadric``
and q_d = d.ravel() the nodal displacements.  Node i sits at the material point (u_i, v_i) and
its world position is

    x_i = c + R p_i,   p_i = s(q_s; u_i, v_i) + d_i

so with linear nodal elements S evaluated at node i selects d_i.  Its Jacobian is

    L_i = dx_i/dq = [ I3 | -[R p_i]x | R J_i | R S_i ]   (3 x n, n = 17 + 3 nodes)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tracker.geometry.se3 import exp_so3
from tracker.physics import superquadric as sq

RIGID = 6
"""Number of rigid coordinates (c, phi) at the head of q."""

SHAPE = slice(RIGID, RIGID + sq.N_PARAMETERS)
"""Where q_s sits in q; q_d follows it."""


@dataclass(frozen=True)
class Part:
    """State of one part: position c (3,), rotation matrix (3, 3), global shape q_s (11,),
    nodal displacements d (n, 3) of the nodes at material points u, v (n,) each."""

    c: np.ndarray
    rotation: np.ndarray
    q_s: np.ndarray
    d: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def n_coordinates(self) -> int:
        """Length of q: 6 rigid + 11 global + 3 per node."""
        return RIGID + sq.N_PARAMETERS + self.d.size


def local_points(part: Part) -> np.ndarray:
    """p_i = s(q_s; u_i, v_i) + d_i, shape (n, 3)."""
    return sq.shape(part.q_s, part.u, part.v) + part.d


def positions(part: Part) -> np.ndarray:
    """World node positions x_i = c + R (s_i + d_i), shape (n, 3)."""
    return part.c + local_points(part) @ part.rotation.T


def rigid_global_jacobians(part: Part) -> np.ndarray:
    """The c, phi and q_s columns of L_i, [ I3 | -[R p_i]x | R J_i ], for every node, shape (n, 3, 17)."""
    y = local_points(part) @ part.rotation.T
    out = np.zeros((len(part.u), 3, SHAPE.stop))
    out[:, :, 0:3] = np.eye(3)
    out[:, 0, 4], out[:, 0, 5] = y[:, 2], -y[:, 1]
    out[:, 1, 3], out[:, 1, 5] = -y[:, 2], y[:, 0]
    out[:, 2, 3], out[:, 2, 4] = y[:, 1], -y[:, 0]
    out[:, :, SHAPE] = part.rotation @ sq.jacobian(part.q_s, part.u, part.v)
    return out


def active_jacobians(part: Part, coordinates: np.ndarray) -> np.ndarray:
    """The columns ``coordinates`` (indices into q) of every node's L_i, (n, 3, len(coordinates)):
    from :func:`rigid_global_jacobians` when none is a nodal displacement, without building the 3n d
    columns."""
    if max(coordinates, default=-1) < SHAPE.stop:
        return rigid_global_jacobians(part)[:, :, coordinates]
    return jacobians(part)[:, :, coordinates]


def jacobians(part: Part) -> np.ndarray:
    """L_i = [ I3 | -[R p_i]x | R J_i | R S_i ] for every node, shape (n, 3, part.n_coordinates).

    R S_i is R in the three columns of d_i and zero elsewhere.
    """
    n = len(part.u)
    r = part.rotation
    out = np.zeros((n, 3, part.n_coordinates))
    out[:, :, : SHAPE.stop] = rigid_global_jacobians(part)
    first = SHAPE.stop + 3 * np.arange(n)
    for k in range(3):
        out[np.arange(n), :, first + k] = r[:, k]
    return out


def retract(part: Part, dq: np.ndarray) -> Part:
    """q (+) dq: c + dc, Exp([dphi]x) R, q_s + dq_s, d + dq_d (section 2)."""
    dq = np.asarray(dq, dtype=np.float64)
    return replace(
        part,
        c=part.c + dq[0:3],
        rotation=exp_so3(np.ascontiguousarray(dq[3:6])) @ part.rotation,
        q_s=part.q_s + dq[SHAPE],
        d=part.d + dq[SHAPE.stop :].reshape(part.d.shape),
    )


def velocity_products(part: Part, qdot: np.ndarray, step: float = 1e-5) -> np.ndarray:
    """(Ldot qdot)_i for every node, shape (n, 3) (section 2):

        Ldot qdot = w x (w x R p) + 2 w x R pdot + R Jdot qdot_s,   pdot = J qdot_s + S qdot_d

    with w = phidot the world angular velocity.  Jdot qdot_s (which eq 43 leaves out) is the
    central difference (J(q_s + h qdot_s) - J(q_s - h qdot_s)) qdot_s / 2h, h = step / |qdot_s|.
    """
    qdot = np.asarray(qdot, dtype=np.float64)
    r = part.rotation
    w = qdot[3:6]
    qdot_s = qdot[SHAPE]
    pdot = qdot[SHAPE.stop :].reshape(part.d.shape)
    shape_term = np.zeros_like(pdot)
    speed = np.linalg.norm(qdot_s)
    if speed > 0.0:
        pdot = pdot + sq.jacobian(part.q_s, part.u, part.v) @ qdot_s
        h = step / speed
        j_plus = sq.jacobian(part.q_s + h * qdot_s, part.u, part.v)
        j_minus = sq.jacobian(part.q_s - h * qdot_s, part.u, part.v)
        shape_term = (j_plus - j_minus) @ qdot_s / (2.0 * h)
    rp = local_points(part) @ r.T
    return np.cross(w, np.cross(w, rp) + 2.0 * pdot @ r.T) + shape_term @ r.T


def lumped_mass(node_jacobians: np.ndarray, masses: np.ndarray, regularizer: float = 0.0) -> np.ndarray:
    """M = sum_i m_i L_i^T L_i + regularizer I (section 3) from L_i (n, 3, q) and masses m_i (n,).

    Not diagonal, unlike the paper's approximation.  Without the regulariser M is positive
    definite only if the nodes pin down every coordinate, e.g. three non-collinear nodes of a
    rigid part (L restricted to c, phi).  A full deformable part never is: its rank is at most
    3 n < 17 + 3 n, since the rigid and global coordinates move the nodes the way d can.  Such
    a part needs a small regulariser (or a prior) to be inverted.
    """
    m = np.einsum("i,iak,ial->kl", masses, node_jacobians, node_jacobians)
    return m + regularizer * np.eye(m.shape[0])
