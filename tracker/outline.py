"""Visible outline samples of every quadric in every camera (design note, section 2).

For camera k and quadric j with camera-from-component pose ``E = P_k E_world``,
the quadric in the camera frame is ``Q' = E^-T Q E^-1 = [[A, b], [b^T, c]]``
and its outline in normalised image coordinates is the conic
``C = c A - b b^T``; in ideal (undistorted) pixels ``C_pix = K^-T C K^-1``,
negative inside the silhouette, so ``n = normalise((C_pix p~)[0:2])`` is the
outward normal.  Proper conics are sampled at even arc length through the
unit-circle map ``h(theta) = H (cos theta, sin theta, 1)``; line pairs (the
outlines of cylinders and cones) are sampled along each line inside the
projected bounding sphere.  Each sample gets the contour-generator point
``X_cam = -c x / (b^T x)`` and is dropped when it lies behind the camera,
outside its clipping quadric, outside the image, or behind another quadric.

Lens distortion: the conic is exact in ideal pixels; each kept sample is
mapped to the recorded (distorted) image by ``p_d = K d(K^-1 p)`` and its
normal by the inverse transpose of that map's Jacobian ``J_d``.  The Jacobian
row of a sample (section 3) is

    L = n_d^T J_d (1/Z) [K2 | -(p - c0)] R D(X_comp),   D(X) = [I3 | -[X]x]

the predicted motion, along its normal, of the distorted image point under
the body twist alpha of its component.

Everything for all cameras and quadrics is one numba call, writing into
preallocated :class:`Samples` buffers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from tracker.geometry.se3 import inverse

_TANGENT_EPS = 1e-3
_MAX_STEPS = 20000


@dataclass(frozen=True)
class Rig:
    """Flat camera arrays: intrinsics ``matrix`` (C,3,3), ``pose`` camera-from-world (C,4,4),
    ``distortion`` (C,5) as k1 k2 p1 p2 k3, ``size`` (C,2) width and height."""

    names: tuple[str, ...]
    matrix: np.ndarray
    pose: np.ndarray
    distortion: np.ndarray
    size: np.ndarray

    @classmethod
    def from_cameras(cls, cameras) -> "Rig":
        distortion = np.zeros((len(cameras), 5))
        for k, cam in enumerate(cameras):
            d = np.asarray(cam.distortions, dtype=np.float64).ravel()[:5]
            distortion[k, : len(d)] = d
        return cls(
            names=tuple(c.name for c in cameras),
            matrix=np.array([c.matrix for c in cameras], dtype=np.float64),
            pose=np.array([c.pose for c in cameras], dtype=np.float64),
            distortion=distortion,
            size=np.array([c.size for c in cameras], dtype=np.int64),
        )


@dataclass
class Samples:
    """Struct-of-arrays buffers of outline samples; the first ``count`` rows are valid.

    ``camera``, ``component``, ``quadric`` indices; ``pixel`` and ``normal`` in the
    recorded (distorted) image; ``jacobian`` the row L (6); ``point`` the contour
    point in its component's frame.
    """

    camera: np.ndarray
    component: np.ndarray
    quadric: np.ndarray
    pixel: np.ndarray
    normal: np.ndarray
    jacobian: np.ndarray
    point: np.ndarray
    count: int = 0

    @classmethod
    def allocate(cls, capacity: int) -> "Samples":
        return cls(
            camera=np.zeros(capacity, np.int64),
            component=np.zeros(capacity, np.int64),
            quadric=np.zeros(capacity, np.int64),
            pixel=np.zeros((capacity, 2)),
            normal=np.zeros((capacity, 2)),
            jacobian=np.zeros((capacity, 6)),
            point=np.zeros((capacity, 3)),
        )

    @property
    def capacity(self) -> int:
        return len(self.camera)


@njit(cache=True)
def distort(k_mat, dist, p):
    """Ideal pixel p -> recorded pixel and the 2x2 Jacobian of that map (Brown-Conrady).

    With x = K^-1 p, r2 = |x|^2, f = 1 + k1 r2 + k2 r2^2 + k3 r2^3:
    d(x) = x f + (2 p1 x y + p2 (r2 + 2x^2), p1 (r2 + 2y^2) + 2 p2 x y).
    """
    fx, s, cx = k_mat[0, 0], k_mat[0, 1], k_mat[0, 2]
    fy, cy = k_mat[1, 1], k_mat[1, 2]
    y = (p[1] - cy) / fy
    x = (p[0] - cx - s * y) / fx
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    r2 = x * x + y * y
    f = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    df = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    dx = x * f + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    dy = y * f + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    out = np.empty(2)
    out[0] = fx * dx + s * dy + cx
    out[1] = fy * dy + cy
    jn = np.empty((2, 2))
    jn[0, 0] = f + 2.0 * x * x * df + 2.0 * p1 * y + 6.0 * p2 * x
    jn[0, 1] = 2.0 * x * y * df + 2.0 * p1 * x + 2.0 * p2 * y
    jn[1, 0] = 2.0 * x * y * df + 2.0 * p1 * x + 2.0 * p2 * y
    jn[1, 1] = f + 2.0 * y * y * df + 6.0 * p1 * y + 2.0 * p2 * x
    k2x2 = np.empty((2, 2))
    k2x2[0, 0], k2x2[0, 1], k2x2[1, 0], k2x2[1, 1] = fx, s, 0.0, fy
    k2inv = np.empty((2, 2))
    k2inv[0, 0], k2inv[0, 1], k2inv[1, 0], k2inv[1, 1] = 1.0 / fx, -s / (fx * fy), 0.0, 1.0 / fy
    return out, k2x2 @ jn @ k2inv


@njit(cache=True)
def _occluded(x_cam, j, q_cam, clip_cam):
    """True when the segment camera -> x_cam (points s x_cam, 0 < s < 1) enters another clipped quadric."""
    for l in range(q_cam.shape[0]):
        if l == j:
            continue
        q = q_cam[l]
        qa = 0.0
        qb = 0.0
        for a in range(3):
            qb += 2.0 * q[a, 3] * x_cam[a]
            for b in range(3):
                qa += x_cam[a] * q[a, b] * x_cam[b]
        qc = q[3, 3]
        disc = qb * qb - 4.0 * qa * qc
        if disc < 0.0 or qa == 0.0:
            continue
        root = np.sqrt(disc)
        big = -0.5 * (qb + root) if qb >= 0.0 else -0.5 * (qb - root)
        if big == 0.0:
            continue
        for s in (big / qa, qc / big):
            if s <= 0.0 or s >= 1.0 - _TANGENT_EPS:
                continue
            clip = clip_cam[l]
            value = clip[3, 3]
            for a in range(3):
                value += 2.0 * clip[a, 3] * s * x_cam[a]
                for b in range(3):
                    value += s * x_cam[a] * clip[a, b] * s * x_cam[b]
            if value <= 0.0:
                return True
    return False


@njit(cache=True)
def _emit(p, j, k, comp, conic, q_cam, clip_cam, cam_from_comp, k_mat, k_inv, dist, size,
          o_cam, o_comp, o_quadric, o_pixel, o_normal, o_jac, o_point, n):
    """Test one ideal-pixel outline point and append it to the buffers if visible; returns the new count."""
    if n >= o_cam.shape[0]:
        return n
    q = q_cam[j]
    xh = np.array([p[0], p[1], 1.0])
    x = k_inv @ xh
    denom = q[0, 3] * x[0] + q[1, 3] * x[1] + q[2, 3] * x[2]
    if denom == 0.0:
        return n
    depth = -q[3, 3] / denom
    if depth <= 0.0:
        return n
    x_cam = depth * x
    clip = clip_cam[j]
    value = clip[3, 3]
    for a in range(3):
        value += 2.0 * clip[a, 3] * x_cam[a]
        for b in range(3):
            value += x_cam[a] * clip[a, b] * x_cam[b]
    if value > 0.0:
        return n
    grad = conic @ xh
    gnorm = np.sqrt(grad[0] * grad[0] + grad[1] * grad[1])
    scale = 0.0
    for a in range(3):
        for b in range(3):
            scale = max(scale, abs(conic[a, b]))
    if gnorm <= 1e-9 * scale * (1.0 + abs(p[0]) + abs(p[1])):
        return n
    pd, jd = distort(k_mat, dist, p)
    if pd[0] < 0.0 or pd[1] < 0.0 or pd[0] > size[0] - 1.0 or pd[1] > size[1] - 1.0:
        return n
    if _occluded(x_cam, j, q_cam, clip_cam):
        return n
    # normal through the distortion: n_d ~ J_d^-T n
    det = jd[0, 0] * jd[1, 1] - jd[0, 1] * jd[1, 0]
    nx = (jd[1, 1] * grad[0] - jd[1, 0] * grad[1]) / det
    ny = (-jd[0, 1] * grad[0] + jd[0, 0] * grad[1]) / det
    nn = np.sqrt(nx * nx + ny * ny)
    nx /= nn
    ny /= nn
    # L = n_d^T J_d dp/dY R D(X_comp)
    r = cam_from_comp[0:3, 0:3]
    x_comp = r.T @ (x_cam - cam_from_comp[0:3, 3])
    gx = nx * jd[0, 0] + ny * jd[1, 0]
    gy = nx * jd[0, 1] + ny * jd[1, 1]
    # row of dp/dY: (1/Z) [K2 | -(p - c0)], contracted with (gx, gy)
    dy0 = gx * k_mat[0, 0] / depth
    dy1 = (gx * k_mat[0, 1] + gy * k_mat[1, 1]) / depth
    dy2 = -(gx * (p[0] - k_mat[0, 2]) + gy * (p[1] - k_mat[1, 2])) / depth
    # row in the component frame: R^T (dy0, dy1, dy2)
    rx = r[0, 0] * dy0 + r[1, 0] * dy1 + r[2, 0] * dy2
    ry = r[0, 1] * dy0 + r[1, 1] * dy1 + r[2, 1] * dy2
    rz = r[0, 2] * dy0 + r[1, 2] * dy1 + r[2, 2] * dy2
    o_jac[n, 0] = rx
    o_jac[n, 1] = ry
    o_jac[n, 2] = rz
    # g^T (-[X]x) w = (X x g) . w
    o_jac[n, 3] = x_comp[1] * rz - x_comp[2] * ry
    o_jac[n, 4] = x_comp[2] * rx - x_comp[0] * rz
    o_jac[n, 5] = x_comp[0] * ry - x_comp[1] * rx
    o_cam[n] = k
    o_comp[n] = comp
    o_quadric[n] = j
    o_pixel[n, 0] = pd[0]
    o_pixel[n, 1] = pd[1]
    o_normal[n, 0] = nx
    o_normal[n, 1] = ny
    o_point[n] = x_comp
    return n + 1


@njit(cache=True)
def outline_kernel(quadric, clip, bound, quadric_component, poses, cam_matrix, cam_pose, cam_dist, cam_size,
                   spacing, o_cam, o_comp, o_quadric, o_pixel, o_normal, o_jac, o_point):
    """Sample the visible outlines of all quadrics in all cameras; returns the sample count."""
    n_quadrics = quadric.shape[0]
    q_cam = np.empty((n_quadrics, 4, 4))
    clip_cam = np.empty((n_quadrics, 4, 4))
    cam_from_comp = np.empty((n_quadrics, 4, 4))
    n = 0
    for k in range(cam_matrix.shape[0]):
        k_mat = cam_matrix[k]
        k_inv = np.linalg.inv(k_mat)
        size = cam_size[k]
        width, height = float(size[0]), float(size[1])
        for j in range(n_quadrics):
            e = cam_pose[k] @ poses[quadric_component[j]]
            e_inv = inverse(e)
            cam_from_comp[j] = e
            q_cam[j] = e_inv.T @ quadric[j] @ e_inv
            clip_cam[j] = e_inv.T @ clip[j] @ e_inv
        for j in range(n_quadrics):
            e = cam_from_comp[j]
            centre = e[0:3, 0:3] @ bound[j, 0:3].copy() + e[0:3, 3]
            radius = bound[j, 3]
            if centre[2] + radius <= 0.0:
                continue
            # projected bounding disc (ideal pixels); the whole plane when the sphere reaches the camera
            focal = max(k_mat[0, 0], k_mat[1, 1])
            if centre[2] - radius > 1e-6:
                disc_c = k_mat @ (centre / centre[2])
                disc_r = focal * radius / (centre[2] - radius) * (1.0 + np.sqrt(centre[0] ** 2 + centre[1] ** 2) / centre[2])
                if (disc_c[0] + disc_r < -0.25 * width or disc_c[0] - disc_r > 1.25 * width
                        or disc_c[1] + disc_r < -0.25 * height or disc_c[1] - disc_r > 1.25 * height):
                    continue
            else:
                disc_c = np.array([0.5 * width, 0.5 * height, 1.0])
                disc_r = 4.0 * (width + height)
            qc = q_cam[j]
            a_mat = qc[0:3, 0:3]
            b_vec = qc[0:3, 3].copy()
            conic_n = qc[3, 3] * a_mat - np.outer(b_vec, b_vec)
            conic = k_inv.T @ conic_n @ k_inv
            # classify and factor in normalised coordinates, where the spectrum is well scaled;
            # H_pix = K H_n and l_pix = K^-T l_n carry the factors to pixels
            lam, vec = np.linalg.eigh(conic_n)
            big = max(abs(lam[0]), abs(lam[2]))
            if big == 0.0:
                continue
            tol = 1e-9 * big
            n_pos = 0
            n_neg = 0
            for a in range(3):
                if lam[a] > tol:
                    n_pos += 1
                elif lam[a] < -tol:
                    n_neg += 1
            comp = quadric_component[j]
            if n_pos + n_neg == 3 and n_pos > 0 and n_neg > 0:
                # proper conic: make one eigenvalue negative and two positive (on this copy only)
                sign = 1.0 if n_neg == 1 else -1.0
                ls = sign * lam
                i0 = 0 if ls[0] < 0 else 2
                i1 = 1
                i2 = 2 if i0 == 0 else 0
                h_n = np.empty((3, 3))
                h_n[:, 0] = vec[:, i1] / np.sqrt(ls[i1])
                h_n[:, 1] = vec[:, i2] / np.sqrt(ls[i2])
                h_n[:, 2] = vec[:, i0] / np.sqrt(-ls[i0])
                h_mat = k_mat @ h_n
                theta = 0.0
                min_step = 2.0 * np.pi / _MAX_STEPS
                while theta < 2.0 * np.pi:
                    ct = np.cos(theta)
                    st = np.sin(theta)
                    h0 = h_mat[0, 0] * ct + h_mat[0, 1] * st + h_mat[0, 2]
                    h1 = h_mat[1, 0] * ct + h_mat[1, 1] * st + h_mat[1, 2]
                    h2 = h_mat[2, 0] * ct + h_mat[2, 1] * st + h_mat[2, 2]
                    d0 = -h_mat[0, 0] * st + h_mat[0, 1] * ct
                    d1 = -h_mat[1, 0] * st + h_mat[1, 1] * ct
                    d2 = -h_mat[2, 0] * st + h_mat[2, 1] * ct
                    if abs(h2) < 1e-12:
                        theta += min_step
                        continue
                    px = h0 / h2
                    py = h1 / h2
                    vx = (d0 * h2 - h0 * d2) / (h2 * h2)
                    vy = (d1 * h2 - h1 * d2) / (h2 * h2)
                    speed = np.sqrt(vx * vx + vy * vy)
                    if (px - disc_c[0]) ** 2 + (py - disc_c[1]) ** 2 <= disc_r * disc_r:
                        n = _emit(np.array([px, py]), j, k, comp, conic, q_cam, clip_cam, cam_from_comp[j],
                                  k_mat, k_inv, cam_dist[k], size, o_cam, o_comp, o_quadric, o_pixel, o_normal,
                                  o_jac, o_point, n)
                    theta += max(spacing / max(speed, 1e-12), min_step)
            elif n_pos + n_neg == 2 and n_pos == 1 and n_neg == 1:
                # line pair l+- = sqrt(la) va +- sqrt(-lb) vb (rank 2, opposite signs)
                ia = 0 if lam[0] > tol else (1 if lam[1] > tol else 2)
                ib = 0 if lam[0] < -tol else (1 if lam[1] < -tol else 2)
                for side in (1.0, -1.0):
                    line = k_inv.T @ (np.sqrt(lam[ia]) * vec[:, ia] + side * np.sqrt(-lam[ib]) * vec[:, ib])
                    ln = np.sqrt(line[0] ** 2 + line[1] ** 2)
                    if ln == 0.0:
                        continue
                    # foot of the disc centre on the line, then +- half chord
                    dist_c = (line[0] * disc_c[0] + line[1] * disc_c[1] + line[2]) / ln
                    if abs(dist_c) >= disc_r:
                        continue
                    ux = line[0] / ln
                    uy = line[1] / ln
                    fx = disc_c[0] - dist_c * ux
                    fy = disc_c[1] - dist_c * uy
                    half = np.sqrt(disc_r * disc_r - dist_c * dist_c)
                    steps = int(2.0 * half / spacing) + 1
                    for s_i in range(steps):
                        t = -half + (s_i + 0.5) * (2.0 * half / steps)
                        n = _emit(np.array([fx - t * uy, fy + t * ux]), j, k, comp, conic, q_cam, clip_cam,
                                  cam_from_comp[j], k_mat, k_inv, cam_dist[k], size, o_cam, o_comp, o_quadric,
                                  o_pixel, o_normal, o_jac, o_point, n)
    return n


def sample_outlines(model, poses: np.ndarray, rig: Rig, spacing: float, samples: Samples) -> Samples:
    """Fill ``samples`` with the visible outline of ``model`` at ``poses`` (N,4,4) seen by ``rig``."""
    samples.count = outline_kernel(
        model.quadric, model.clip, model.quadric_bound, model.quadric_component, poses,
        rig.matrix, rig.pose, rig.distortion, rig.size, float(spacing),
        samples.camera, samples.component, samples.quadric, samples.pixel, samples.normal,
        samples.jacobian, samples.point,
    )
    return samples
