"""Clipped quadrics in a component's frame (docs/method-tracking.md, section 2).

A surface is ``X~^T Q X~ = 0`` with ``X~ = (X; 1)``, negative inside.  Each
rendered quadric has a clipping quadric ``Q2``: a surface point is kept when
``X~^T Q2 X~ <= 0``.  Moving a quadric by ``T`` (``X_new = T X_old``) gives
``Q_new = T^-T Q T^-1``.
"""

from __future__ import annotations

import numpy as np

KEEP_ALL = -np.diag([0.0, 0.0, 0.0, 1.0])
"""Clipping quadric that keeps every point (the form is -1 everywhere)."""


def place(q: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Q' = T^-T Q T^-1: the quadric Q moved by the 4x4 transform T."""
    t_inv = np.linalg.inv(transform)
    out = t_inv.T @ q @ t_inv
    return 0.5 * (out + out.T)


def ellipsoid(center, radii) -> np.ndarray:
    """diag(1/a^2, 1/b^2, 1/c^2, -1), centred at ``center``, axes along x, y, z."""
    a, b, c = (float(r) for r in radii)
    q = np.diag([1.0 / a**2, 1.0 / b**2, 1.0 / c**2, -1.0])
    shift = np.eye(4)
    shift[0:3, 3] = center
    return place(q, shift)


def axis_frame(start, end) -> np.ndarray:
    """A 4x4 transform whose origin is ``start`` and whose z axis points to ``end``."""
    start = np.asarray(start, dtype=np.float64)
    d = np.asarray(end, dtype=np.float64) - start
    length = np.linalg.norm(d)
    z = d / length
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    out = np.eye(4)
    out[0:3, 0:3] = np.column_stack([x, np.cross(z, x), z])
    out[0:3, 3] = start
    return out


def cone(start, end, *, radius_start, radius_end) -> np.ndarray:
    """Truncated cone (a cylinder when the radii are equal) along start -> end.

    With s the distance along the axis from ``start`` and k = (r1 - r0)/L, the
    surface is x^2 + y^2 - (r0 + k s)^2 = 0, i.e. in the axis frame
    Q0 = [[1,0,0,0],[0,1,0,0],[0,0,-k^2,-r0 k],[0,0,-r0 k,-r0^2]], scaled by 1/r0^2.
    """
    frame = axis_frame(start, end)
    length = np.linalg.norm(np.asarray(end, dtype=np.float64) - np.asarray(start, dtype=np.float64))
    r0, r1 = float(radius_start), float(radius_end)
    k = (r1 - r0) / length
    q0 = np.diag([1.0, 1.0, -k * k, -r0 * r0])
    q0[2, 3] = q0[3, 2] = -r0 * k
    return place(q0 / (r0 * r0), frame)


def slab(normal, d1: float, d2: float) -> np.ndarray:
    """Clip to d1 <= n.X <= d2: Q2 = (pi1 pi2^T + pi2 pi1^T)/2, pi_i = (n, -d_i)."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    pi1 = np.append(n, -float(d1))
    pi2 = np.append(n, -float(d2))
    return 0.5 * (np.outer(pi1, pi2) + np.outer(pi2, pi1))


def evaluate(q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """X~^T Q X~ for each row of ``points`` (M, 3)."""
    h = np.hstack([points, np.ones((len(points), 1))])
    return np.einsum("mi,ij,mj->m", h, q, h)
