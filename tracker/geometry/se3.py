"""SE(3) for poses and body twists (docs/method-tracking.md, section 1).

A pose ``E`` is a 4x4 matrix ``[[R, t], [0, 1]]`` mapping a component's frame to
another frame (``X_a = E_a_from_b X_b``).  A motion is a twist
``alpha = (v; w)`` (translation first, then rotation) acting on the right:
``E <- E exp(hat(alpha))``.  The generators are

    G1..G3: translation along x, y, z        (G_i[0:3, 3] = e_i)
    G4..G6: right-handed rotation about x, y, z   (G_{3+j}[0:3, 0:3] = [e_j]x)

The kernels' functions are numba ``@njit`` so the per-frame kernels can call them; they
work unchanged from Python on float64 arrays.  ``generators``, ``cross``, ``from_rotvec``,
``from_rotation`` and ``rotation_angle`` are plain numpy, for Python callers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_SMALL = 1e-4


@njit(cache=True)
def skew(x):
    """[x]x, the cross-product matrix: ``skew(x) @ y == cross(x, y)``."""
    out = np.zeros((3, 3))
    out[0, 1] = -x[2]
    out[0, 2] = x[1]
    out[1, 0] = x[2]
    out[1, 2] = -x[0]
    out[2, 0] = -x[1]
    out[2, 1] = x[0]
    return out


@njit(cache=True)
def hat(alpha):
    """hat(alpha) = sum_i alpha_i G_i = [[ [w]x, v ], [0, 0]]."""
    out = np.zeros((4, 4))
    out[0:3, 0:3] = skew(alpha[3:6])
    out[0:3, 3] = alpha[0:3]
    return out


def generators() -> np.ndarray:
    """The six 4x4 generators G1..G6, translations then rotations (docs/method-tracking.md, section 1)."""
    return np.stack([hat(np.eye(6)[i]) for i in range(6)])


@njit(cache=True)
def _exp_coefficients(theta):
    """A = sin(th)/th, B = (1-cos th)/th^2, Cc = (th - sin th)/th^3, with series near 0."""
    if theta < _SMALL:
        t2 = theta * theta
        a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
        c = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
    else:
        half = np.sin(0.5 * theta)
        a = np.sin(theta) / theta
        b = 2.0 * half * half / (theta * theta)
        c = (theta - np.sin(theta)) / (theta * theta * theta)
    return a, b, c


@njit(cache=True)
def _cross(a, b):
    """a x b for 3-vectors, as three floats."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _rodrigues(w, a, b, out):
    """out[0:3, 0:3] = I + A W + B W^2 with W = [w]x (W^2 = w w^T - |w|^2 I), written in place."""
    t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    for i in range(3):
        for j in range(3):
            out[i, j] = b * w[i] * w[j]
        out[i, i] += 1.0 - b * t2
    out[0, 1] -= a * w[2]
    out[0, 2] += a * w[1]
    out[1, 0] += a * w[2]
    out[1, 2] -= a * w[0]
    out[2, 0] -= a * w[1]
    out[2, 1] += a * w[0]


@njit(cache=True)
def exp_so3(w):
    """Rodrigues: R = I + A W + B W^2 with W = [w]x."""
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    a, b, _ = _exp_coefficients(theta)
    out = np.empty((3, 3))
    _rodrigues(w, a, b, out)
    return out


@njit(cache=True)
def right_jacobian_so3(w):
    """J_r(w) = I - B W + Cc W^2 with W = [w]x: exp_so3(w + d) = exp_so3(w) exp_so3(J_r(w) d) to first order in d;
    the left Jacobian, exp_so3(w + d) = exp_so3(J_l(w) d) exp_so3(w), is J_r(w)^T."""
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    _, b, c = _exp_coefficients(theta)
    big_w = skew(w)
    return np.eye(3) - b * big_w + c * (big_w @ big_w)


@njit(cache=True)
def exp(alpha):
    """exp(hat(alpha)): R as in ``exp_so3``, t = V v with V = I + B W + Cc W^2,
    so t = v + B (w x v) + Cc (w x (w x v))."""
    w = alpha[3:6]
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    a, b, c = _exp_coefficients(theta)
    out = np.zeros((4, 4))
    _rodrigues(w, a, b, out)
    wv = _cross(w, alpha)
    wwv = _cross(w, wv)
    for i in range(3):
        out[i, 3] = alpha[i] + b * wv[i] + c * wwv[i]
    out[3, 3] = 1.0
    return out


@njit(cache=True)
def log_so3(r):
    """Rotation vector w with exp_so3(w) = R; stable near 0 and near pi."""
    s0 = 0.5 * (r[2, 1] - r[1, 2])
    s1 = 0.5 * (r[0, 2] - r[2, 0])
    s2 = 0.5 * (r[1, 0] - r[0, 1])
    sin_t = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    cos_t = 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0)
    theta = np.arctan2(sin_t, cos_t)
    if cos_t < -0.99 and theta >= _SMALL:
        big_b = 0.5 * (r + r.T) - cos_t * np.eye(3)
        j = 0
        for i in range(1, 3):
            if big_b[i, i] > big_b[j, j]:
                j = i
        k = big_b[:, j].copy()
        k *= theta / np.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
        if k[0] * s0 + k[1] * s1 + k[2] * s2 < 0.0:
            k = -k
        return k
    scale = 1.0 + theta * theta / 6.0 if theta < _SMALL else theta / sin_t
    out = np.empty(3)
    out[0] = scale * s0
    out[1] = scale * s1
    out[2] = scale * s2
    return out


@njit(cache=True)
def exp_so3_many(w):
    """:func:`exp_so3` of every row of ``w`` (N, 3) -> (N, 3, 3)."""
    out = np.empty((w.shape[0], 3, 3))
    for i in range(w.shape[0]):
        out[i] = exp_so3(w[i])
    return out


@njit(cache=True)
def log_so3_many(r):
    """:func:`log_so3` of every rotation of ``r`` (N, 3, 3) -> (N, 3)."""
    out = np.empty((r.shape[0], 3))
    for i in range(r.shape[0]):
        out[i] = log_so3(r[i])
    return out


@njit(cache=True)
def log(e):
    """Twist alpha = (v; w) with exp(alpha) = E: w = log_so3(R), v = V^-1 t,
    V^-1 = I - W/2 + g W^2, g = (1 - (th/2) cot(th/2)) / th^2, so v = t - (w x t)/2 + g (w x (w x t))."""
    w = log_so3(e[0:3, 0:3])
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if theta < 1e-2:
        t2 = theta * theta
        g = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        half = 0.5 * theta
        g = (1.0 - half * np.cos(half) / np.sin(half)) / (theta * theta)
    t = (e[0, 3], e[1, 3], e[2, 3])
    wt = _cross(w, t)
    wwt = _cross(w, wt)
    out = np.empty(6)
    for i in range(3):
        out[i] = t[i] - 0.5 * wt[i] + g * wwt[i]
        out[3 + i] = w[i]
    return out


@njit(cache=True)
def inverse(e):
    """E^-1 = [[R^T, -R^T t], [0, 1]]."""
    out = np.zeros((4, 4))
    for i in range(3):
        for j in range(3):
            out[i, j] = e[j, i]
        out[i, 3] = -(e[0, i] * e[0, 3] + e[1, i] * e[1, 3] + e[2, i] * e[2, 3])
    out[3, 3] = 1.0
    return out


@njit(cache=True)
def between(a, b):
    """A^-1 B = [[Ra^T Rb, Ra^T (tb - ta)], [0, 1]]: B seen from A's frame."""
    out = np.zeros((4, 4))
    for i in range(3):
        for j in range(4):
            out[i, j] = a[0, i] * b[0, j] + a[1, i] * b[1, j] + a[2, i] * b[2, j]
        out[i, 3] -= a[0, i] * a[0, 3] + a[1, i] * a[1, 3] + a[2, i] * a[2, 3]
    out[3, 3] = 1.0
    return out


@njit(cache=True)
def adjoint(e):
    """Ad(E) = [[R, [t]x R], [0, R]], so that E exp(hat a) E^-1 = exp(hat(Ad(E) a))."""
    r = np.ascontiguousarray(e[0:3, 0:3])
    out = np.zeros((6, 6))
    out[0:3, 0:3] = r
    out[0:3, 3:6] = skew(np.ascontiguousarray(e[0:3, 3])) @ r
    out[3:6, 3:6] = r
    return out


@njit(cache=True)
def point_velocity(x):
    """D(x) = [I3 | -[x]x] (3x6): d/de exp(e alpha) x at e=0 equals D(x) alpha = v + w x x."""
    out = np.zeros((3, 6))
    out[0:3, 0:3] = np.eye(3)
    out[0:3, 3:6] = -skew(x)
    return out


def cross(a, b) -> np.ndarray:
    """a x b (..., 3) of 3-vectors along the last axis of ``a`` and ``b``, their leading axes broadcast: the
    products and differences of ``np.cross`` in its order (the same numbers), without its axis handling, which
    costs more than the arithmetic for the few vectors of a Jacobian's rows."""
    a, b = np.asarray(a), np.asarray(b)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def from_rotvec(rotvec, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 pose from a Rodrigues rotation vector and a translation."""
    out = np.eye(4)
    out[0:3, 0:3] = exp_so3(np.asarray(rotvec, dtype=np.float64))
    out[0:3, 3] = np.asarray(translation, dtype=np.float64)
    return out


def from_rotation(rotation, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 pose ``[[R, t], [0, 1]]`` from a rotation matrix R (3, 3) and a translation t (3,), or a
    stack of them (..., 4, 4) from (..., 3, 3) and (..., 3)."""
    rotation = np.asarray(rotation, dtype=np.float64)
    out = np.zeros((*rotation.shape[:-2], 4, 4))
    out[..., 0:3, 0:3] = rotation
    out[..., 0:3, 3] = np.asarray(translation, dtype=np.float64)
    out[..., 3, 3] = 1.0
    return out


def rotation_angle(rotation):
    """Geodesic angle (radians, in [0, pi]) of a rotation R (..., 3, 3): |log_so3(R)|, the angle
    between frames a and b for ``R = a_from_b``; ``rotation_angle(Ra.T @ Rb)`` is the angle between
    two rotations.  atan2(|s|, (trace R - 1) / 2) with s = vee(R - R^T) / 2 (|s| = sin th), as in
    ``log_so3``: exact near 0 and pi, where arccos of the trace alone loses half the digits.  A
    float for one rotation, an array over the leading axes for many."""
    r = np.asarray(rotation, dtype=np.float64)
    s0 = r[..., 2, 1] - r[..., 1, 2]
    s1 = r[..., 0, 2] - r[..., 2, 0]
    s2 = r[..., 1, 0] - r[..., 0, 1]
    sin_t = 0.5 * np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    cos_t = 0.5 * (r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2] - 1.0)
    angle = np.arctan2(sin_t, cos_t)
    return float(angle) if angle.ndim == 0 else angle
