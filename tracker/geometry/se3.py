"""SE(3) for poses and body twists (design note, section 1).

A pose ``E`` is a 4x4 matrix ``[[R, t], [0, 1]]`` mapping a component's frame to
another frame (``X_a = E_a_from_b X_b``).  A motion is a twist
``alpha = (v; w)`` (translation first, then rotation) acting on the right:
``E <- E exp(hat(alpha))``.  The generators are

    G1..G3: translation along x, y, z        (G_i[0:3, 3] = e_i)
    G4..G6: right-handed rotation about x, y, z   (G_{3+j}[0:3, 0:3] = [e_j]x)

All functions are numba ``@njit`` so the per-frame kernels can call them; they
work unchanged from Python on float64 arrays.
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
    """The six 4x4 generators G1..G6 in the note's order (translations, then rotations)."""
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
def exp_so3(w):
    """Rodrigues: R = I + A W + B W^2 with W = [w]x."""
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    a, b, _ = _exp_coefficients(theta)
    big_w = skew(w)
    return np.eye(3) + a * big_w + b * (big_w @ big_w)


@njit(cache=True)
def exp(alpha):
    """exp(hat(alpha)): R as in ``exp_so3``, t = V v with V = I + B W + Cc W^2."""
    w = alpha[3:6]
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    a, b, c = _exp_coefficients(theta)
    big_w = skew(w)
    w2 = big_w @ big_w
    out = np.eye(4)
    out[0:3, 0:3] = np.eye(3) + a * big_w + b * w2
    v_mat = np.eye(3) + b * big_w + c * w2
    out[0:3, 3] = v_mat @ np.ascontiguousarray(alpha[0:3])
    return out


@njit(cache=True)
def log_so3(r):
    """Rotation vector w with exp_so3(w) = R; stable near 0 and near pi."""
    s = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin_t = np.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
    cos_t = 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0)
    theta = np.arctan2(sin_t, cos_t)
    if theta < _SMALL:
        return (1.0 + theta * theta / 6.0) * s
    if cos_t < -0.99:
        big_b = 0.5 * (r + r.T) - cos_t * np.eye(3)
        j = 0
        for i in range(1, 3):
            if big_b[i, i] > big_b[j, j]:
                j = i
        k = big_b[:, j].copy()
        k /= np.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
        if k[0] * s[0] + k[1] * s[1] + k[2] * s[2] < 0.0:
            k = -k
        return theta * k
    return theta * s / sin_t


@njit(cache=True)
def log(e):
    """Twist alpha = (v; w) with exp(alpha) = E: w = log_so3(R), v = V^-1 t,
    V^-1 = I - W/2 + g W^2, g = (1 - (th/2) cot(th/2)) / th^2."""
    w = log_so3(np.ascontiguousarray(e[0:3, 0:3]))
    theta = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if theta < 1e-2:
        t2 = theta * theta
        g = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        half = 0.5 * theta
        g = (1.0 - half * np.cos(half) / np.sin(half)) / (theta * theta)
    big_w = skew(w)
    v_inv = np.eye(3) - 0.5 * big_w + g * (big_w @ big_w)
    out = np.empty(6)
    out[0:3] = v_inv @ np.ascontiguousarray(e[0:3, 3])
    out[3:6] = w
    return out


@njit(cache=True)
def inverse(e):
    """E^-1 = [[R^T, -R^T t], [0, 1]]."""
    out = np.eye(4)
    rt = e[0:3, 0:3].T.copy()
    out[0:3, 0:3] = rt
    out[0:3, 3] = -(rt @ np.ascontiguousarray(e[0:3, 3]))
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


def from_rotvec(rotvec, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 pose from a Rodrigues rotation vector and a translation."""
    out = np.eye(4)
    out[0:3, 0:3] = exp_so3(np.asarray(rotvec, dtype=np.float64))
    out[0:3, 3] = np.asarray(translation, dtype=np.float64)
    return out
