"""Lens models for the kernels (docs/method-tracking.md, section 2): OpenCV's pinhole and fisheye
distortion, their Jacobians and inverse.

A camera's lens is a kind and ``COEFFICIENTS`` numbers in OpenCV's order, zero-padded
(tracker/camera.py gives the formulas, docs/formats.md the file keys):

    PINHOLE  k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty   (rational, thin prism, tilted sensor)
    FISHEYE  k1 k2 k3 k4                                 (equidistant)

:func:`lens_distort` maps ideal normalised coordinates x = (X/Z, Y/Z) to distorted ones x_d; pixels
are ``u = K2' x_d + c0`` with ``K2' = [[fx, s], [0, fy]]``, where the skew ``s = K[0, 1]`` is 0 for a
fisheye lens (OpenCV's fisheye functions ignore it, and so does :class:`tracker.camera.Camera`).
:func:`distort` works in ideal pixels ``p = K x`` (the outline kernel's conics live there) and
:func:`undistort` inverts the map.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PINHOLE = 0
FISHEYE = 1
COEFFICIENTS = 14
PINHOLE_LENGTHS = (4, 5, 8, 12, 14)
"""The numbers of pinhole coefficients OpenCV takes (the rest are 0)."""
FISHEYE_LENGTHS = (4,)

_SMALL_RADIUS = 1e-8  # below it the fisheye map is the identity to rounding (OpenCV's cut-off)
_UNDISTORT_ITERATIONS = 20
_UNDISTORT_TOLERANCE = 1e-12  # on the residual in normalised coordinates (about 1e-9 pixels)
_BACKTRACKS = 30  # halvings of a Newton step that does not shrink the residual


@njit(cache=True)
def lens_distort(kind, coef, x, y):
    """Distorted normalised coordinates x_d of ideal ones (x, y) and the Jacobian N = dx_d/dx:
    (xd, yd, n00, n01, n10, n11).

    Pinhole, with r2 = x^2 + y^2, radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3):
    x' = x radial + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2, y' = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
    + s3 r2 + s4 r2^2, then the tilt (a, b, w) = T (x', y', 1), x_d = (a/w, b/w), with OpenCV's
    T = [[cx, 0, 0], [-sx sy, cy, 0], [sy, -cy sx, cy cx]] (cx = cos tx, sx = sin tx, cy = cos ty, ...).
    Fisheye, with r = |x|, theta = atan r: x_d = f x, f = theta (1 + k1 theta^2 + ... + k4 theta^8) / r.
    """
    r2 = x * x + y * y
    if kind == FISHEYE:
        k1, k2, k3, k4 = coef[0], coef[1], coef[2], coef[3]
        r = np.sqrt(r2)
        if r < _SMALL_RADIUS:
            f = 1.0
            g = 2.0 * (k1 - 1.0 / 3.0)  # f = 1 + (k1 - 1/3) r^2 + O(r^4): the limit of f'(r)/r
        else:
            theta = np.arctan(r)
            t2 = theta * theta
            f = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) / r
            dtheta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
            g = (dtheta_d / (1.0 + r2) - f) / r2  # f'(r)/r
        # N = f I + (f'(r)/r) x x^T
        return f * x, f * y, f + g * x * x, g * x * y, g * x * y, f + g * y * y
    k1, k2, p1, p2, k3, k4, k5, k6 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6], coef[7]
    s1, s2, s3, s4, tau_x, tau_y = coef[8], coef[9], coef[10], coef[11], coef[12], coef[13]
    numerator = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    denominator = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    radial = numerator / denominator
    # d radial / d r2, and d/d r2 of the thin prism terms
    dradial = (k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3) - radial * (k4 + r2 * (2.0 * k5 + 3.0 * r2 * k6))) / denominator
    prism_x = s1 + 2.0 * s2 * r2
    prism_y = s3 + 2.0 * s4 * r2
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + r2 * (s3 + s4 * r2)
    cross = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    n00 = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * prism_x
    n01 = cross + 2.0 * y * prism_x
    n10 = cross + 2.0 * x * prism_y
    n11 = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * prism_y
    if tau_x == 0.0 and tau_y == 0.0:
        return xd, yd, n00, n01, n10, n11
    cx, sx, cy, sy = np.cos(tau_x), np.sin(tau_x), np.cos(tau_y), np.sin(tau_y)
    t10, t20, t21 = -sx * sy, sy, -cy * sx
    a = cx * xd
    b = t10 * xd + cy * yd
    w = t20 * xd + t21 * yd + cy * cx
    # M = d(a/w, b/w)/d(x', y'), then N <- M N
    m00 = (cx * w - a * t20) / (w * w)
    m01 = -a * t21 / (w * w)
    m10 = (t10 * w - b * t20) / (w * w)
    m11 = (cy * w - b * t21) / (w * w)
    return (
        a / w,
        b / w,
        m00 * n00 + m01 * n10,
        m00 * n01 + m01 * n11,
        m10 * n00 + m11 * n10,
        m10 * n01 + m11 * n11,
    )


@njit(cache=True)
def _skew(k_mat, kind):
    """The skew K[0, 1] the lens's pixels carry: none for a fisheye lens (see the module docstring)."""
    return k_mat[0, 1] if kind == PINHOLE else 0.0


@njit(cache=True)
def distort(k_mat, kind, coef, px, py):
    """Ideal pixel (px, py) -> recorded pixel and the 2x2 Jacobian of that map: (u, v, j00, j01, j10, j11).

    With x = K^-1 p and (x_d, N) from :func:`lens_distort`: u = K2' x_d + c0 and
    J_d = K2' N K2^-1 (K2 = [[fx, K[0, 1]], [0, fy]], K2' its lens's skew, see the module docstring).
    """
    fx, s, cx = k_mat[0, 0], k_mat[0, 1], k_mat[0, 2]
    fy, cy = k_mat[1, 1], k_mat[1, 2]
    y = (py - cy) / fy
    x = (px - cx - s * y) / fx
    xd, yd, n00, n01, n10, n11 = lens_distort(kind, coef, x, y)
    s_out = _skew(k_mat, kind)
    # K2' N, then times K2^-1 = [[1/fx, -s/(fx fy)], [0, 1/fy]]
    a00 = fx * n00 + s_out * n10
    a01 = fx * n01 + s_out * n11
    a10 = fy * n10
    a11 = fy * n11
    j00 = a00 / fx
    j01 = -a00 * s / (fx * fy) + a01 / fy
    j10 = a10 / fx
    j11 = -a10 * s / (fx * fy) + a11 / fy
    return fx * xd + s_out * yd + cx, fy * yd + cy, j00, j01, j10, j11


@njit(cache=True)
def undistort(k_mat, kind, coef, px, py):
    """Recorded pixel -> ideal normalised coordinates (x, y): the inverse of :func:`distort`, by Newton's
    method on :func:`lens_distort` from the distorted point until the residual is below 1e-12 (quadratic
    convergence: a few steps for ordinary lenses).

    A step that does not shrink the residual is halved, and the search stops where the lens folds over
    (det N <= 0): a pixel that no ray reaches (beyond the largest radius the lens images, as the corners
    of a strongly rational lens can be) gets a ray near the edge of what the lens images, not a diverging
    one."""
    fy, cy = k_mat[1, 1], k_mat[1, 2]
    yd = (py - cy) / fy
    xd = (px - k_mat[0, 2] - _skew(k_mat, kind) * yd) / k_mat[0, 0]
    x, y = xd, yd
    ex, ey, n00, n01, n10, n11 = lens_distort(kind, coef, x, y)
    ex -= xd
    ey -= yd
    residual = abs(ex) + abs(ey)
    for _ in range(_UNDISTORT_ITERATIONS):
        det = n00 * n11 - n01 * n10
        if residual < _UNDISTORT_TOLERANCE or det <= 0.0:
            break
        step_x = (n11 * ex - n01 * ey) / det
        step_y = (n00 * ey - n10 * ex) / det
        shrunk = False
        for _ in range(_BACKTRACKS):
            ux, uy, m00, m01, m10, m11 = lens_distort(kind, coef, x - step_x, y - step_y)
            if abs(ux - xd) + abs(uy - yd) < residual:
                shrunk = True
                break
            step_x *= 0.5
            step_y *= 0.5
        if not shrunk:
            break
        x, y, ex, ey = x - step_x, y - step_y, ux - xd, uy - yd
        n00, n01, n10, n11 = m00, m01, m10, m11
        residual = abs(ex) + abs(ey)
    return x, y
