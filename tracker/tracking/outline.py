"""Visible outline samples of every quadric in every camera (docs/method-tracking.md, section 2).

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
outside its clipping quadric, outside the image, where the lens folds over
(det J_d <= 0, beyond the widest ray the camera images), or behind another quadric.

Lens distortion: the conic is exact in ideal pixels; each kept sample is
mapped to the recorded (distorted) image by ``p_d = K d(K^-1 p)``, d the
camera's calibrated lens model (:mod:`tracker.geometry.lens`), and its
normal by the inverse transpose of that map's Jacobian ``J_d``.  The Jacobian
row of a sample (section 3) is

    L = n_d^T J_d (1/Z) [K2 | -(p - c0)] R D(X_comp),   D(X) = [I3 | -[X]x]

the predicted motion, along its normal, of the distorted image point under
the body twist alpha of its component.

Everything for all cameras and quadrics is one numba call, writing into
preallocated :class:`Samples` buffers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.geometry.lens import distort
from tracker.tracking.rig import Rig
from tracker.tracking.samples import Placed, Samples

_TANGENT_EPS = 1e-3
_MAX_STEPS = 4096


@njit(cache=True, inline="always")
def component_row(k_mat, camera_from_component, px, py, depth, gx, gy):
    """g^T dp/dY R for a direction g = (gx, gy) at the ideal pixel (px, py) of a point at ``depth``: the
    change of g . p per unit motion of the point in the component's frame, (3,), with
    dp/dY = (1/Z) [K2 | -(p - c0)] and R the rotation of ``camera_from_component``."""
    dy0 = gx * k_mat[0, 0] / depth
    dy1 = (gx * k_mat[0, 1] + gy * k_mat[1, 1]) / depth
    dy2 = -(gx * (px - k_mat[0, 2]) + gy * (py - k_mat[1, 2])) / depth
    e = camera_from_component
    rx = e[0, 0] * dy0 + e[1, 0] * dy1 + e[2, 0] * dy2
    ry = e[0, 1] * dy0 + e[1, 1] * dy1 + e[2, 1] * dy2
    rz = e[0, 2] * dy0 + e[1, 2] * dy1 + e[2, 2] * dy2
    return rx, ry, rz


@njit(cache=True)
def _outside(px, py, width, height):
    """Distance (ideal pixels) from (px, py) to the image grown by a quarter of its size on each side
    (room for lens distortion); 0 inside."""
    margin = 0.25 * max(width, height)
    dx = max(-margin - px, 0.0, px - (width - 1.0 + margin))
    dy = max(-margin - py, 0.0, py - (height - 1.0 + margin))
    return np.sqrt(dx * dx + dy * dy)


@njit(cache=True)
def _occluded(x_cam, occluders, n_occluders, q_cam, clip_cam, sphere):
    """True when the segment camera -> x_cam (points s x_cam, 0 < s < 1) enters another clipped quadric.

    Only the quadrics ``occluders[:n_occluders]`` can (see :func:`_occluders`); ``sphere`` (Q, 4)
    holds each quadric's bounding sphere in the camera frame: a quadric whose sphere the
    segment misses is skipped before the exact test.
    """
    xx = x_cam[0] * x_cam[0] + x_cam[1] * x_cam[1] + x_cam[2] * x_cam[2]
    length = np.sqrt(xx)
    for index in range(n_occluders):
        l = occluders[index]
        cx = sphere[l, 0] * x_cam[0] + sphere[l, 1] * x_cam[1] + sphere[l, 2] * x_cam[2]
        cc = sphere[l, 0] * sphere[l, 0] + sphere[l, 1] * sphere[l, 1] + sphere[l, 2] * sphere[l, 2]
        r = sphere[l, 3]
        if cc * xx - cx * cx > r * r * xx or cx / length - r >= length or cx / length + r <= 0.0:
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
def _cones(sphere, cone):
    """Per quadric the cone of camera rays through its bounding sphere (cone (Q, 6)): unit axis,
    cos, sin and the half angle itself; a sphere around the camera gets the whole space (angle pi)."""
    for j in range(sphere.shape[0]):
        c = sphere[j]
        norm = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
        if norm <= c[3]:
            cone[j, 0:3] = 0.0
            cone[j, 3] = -1.0
            cone[j, 4] = 0.0
            cone[j, 5] = np.pi
            continue
        cone[j, 0] = c[0] / norm
        cone[j, 1] = c[1] / norm
        cone[j, 2] = c[2] / norm
        cone[j, 4] = c[3] / norm
        cone[j, 3] = np.sqrt(1.0 - cone[j, 4] * cone[j, 4])
        cone[j, 5] = np.arcsin(cone[j, 4])


@njit(cache=True, nogil=True)
def cone_gap(cone_j, cone_l, cos_w, sin_w):
    """``cos(angle between the axes of cones j and l) - cos(a_j + w)`` for rows of :func:`_cones` and a half
    angle ``w`` (its cosine and sine) given to cone l, its own or widened: the cones meet when this is
    ``>= 0``, provided ``a_j + w <= pi`` (callers treat wider pairs, and whole-sphere cones, as meeting)."""
    cos_axes = cone_j[0] * cone_l[0] + cone_j[1] * cone_l[1] + cone_j[2] * cone_l[2]
    return cos_axes - (cone_j[3] * cos_w - cone_j[4] * sin_w)


@njit(cache=True)
def _occluders(j, cone, out):
    """The quadrics other than j whose ray cones meet j's (only they can hide j's outline);
    returns their count in ``out``.  Cones meet when the angle between their axes is at most
    the sum of their half angles, cos(axes) >= cos(a_j + a_l) (:func:`cone_gap`; a_j + a_l < pi as
    both are below pi/2), or when either cone is the whole sphere of rays (cos = -1)."""
    count = 0
    for l in range(cone.shape[0]):
        if l == j:
            continue
        if cone[j, 3] > -1.0 and cone[l, 3] > -1.0 and cone_gap(cone[j], cone[l], cone[l, 3], cone[l, 4]) < 0.0:
            continue
        out[count] = l
        count += 1
    return count


@njit(cache=True)
def _emit(
    px,
    py,
    j,
    k,
    comp,
    conic,
    conic_scale,
    q_cam,
    clip_cam,
    sphere,
    occluders,
    n_occluders,
    cam_from_comp,
    k_mat,
    k_inv,
    lens,
    dist,
    size,
    o_cam,
    o_comp,
    o_quadric,
    o_pixel,
    o_normal,
    o_jac,
    o_point,
    n,
):
    """Test one ideal-pixel outline point and append it to the buffers if visible; returns the new count."""
    if n >= o_cam.shape[0]:
        return n
    q = q_cam[j]
    x0 = k_inv[0, 0] * px + k_inv[0, 1] * py + k_inv[0, 2]
    x1 = k_inv[1, 1] * py + k_inv[1, 2]
    denom = q[0, 3] * x0 + q[1, 3] * x1 + q[2, 3]
    if denom == 0.0:
        return n
    depth = -q[3, 3] / denom
    if depth <= 0.0:
        return n
    x_cam = np.empty(3)
    x_cam[0] = depth * x0
    x_cam[1] = depth * x1
    x_cam[2] = depth
    clip = clip_cam[j]
    value = clip[3, 3]
    for a in range(3):
        value += 2.0 * clip[a, 3] * x_cam[a]
        for b in range(3):
            value += x_cam[a] * clip[a, b] * x_cam[b]
    if value > 0.0:
        return n
    # outward normal (C_pix p~)[0:2]; undefined at a line pair's vertex
    g0 = conic[0, 0] * px + conic[0, 1] * py + conic[0, 2]
    g1 = conic[1, 0] * px + conic[1, 1] * py + conic[1, 2]
    if np.sqrt(g0 * g0 + g1 * g1) <= 1e-9 * conic_scale * (1.0 + abs(px) + abs(py)):
        return n
    u, v, j00, j01, j10, j11 = distort(k_mat, lens, dist, px, py)
    det = j00 * j11 - j01 * j10
    # det <= 0: the lens folds over, a ray beyond the widest the camera images lands back inside the image
    if det <= 0.0 or u < 0.0 or v < 0.0 or u > size[0] - 1.0 or v > size[1] - 1.0:
        return n
    if _occluded(x_cam, occluders, n_occluders, q_cam, clip_cam, sphere):
        return n
    # normal through the distortion: n_d ~ J_d^-T n
    nx = (j11 * g0 - j10 * g1) / det
    ny = (-j01 * g0 + j00 * g1) / det
    nn = np.sqrt(nx * nx + ny * ny)
    nx /= nn
    ny /= nn
    # L = n_d^T J_d dp/dY R D(X_comp): first g = J_d^T n_d, then the row of dp/dY,
    # (1/Z) [K2 | -(p - c0)], contracted with g, then R^T of it (the component frame)
    gx = nx * j00 + ny * j10
    gy = nx * j01 + ny * j11
    e = cam_from_comp
    rx, ry, rz = component_row(k_mat, e, px, py, depth, gx, gy)
    d0 = x_cam[0] - e[0, 3]
    d1 = x_cam[1] - e[1, 3]
    d2 = x_cam[2] - e[2, 3]
    xc0 = e[0, 0] * d0 + e[1, 0] * d1 + e[2, 0] * d2
    xc1 = e[0, 1] * d0 + e[1, 1] * d1 + e[2, 1] * d2
    xc2 = e[0, 2] * d0 + e[1, 2] * d1 + e[2, 2] * d2
    o_jac[n, 0] = rx
    o_jac[n, 1] = ry
    o_jac[n, 2] = rz
    # g^T (-[X]x) w = (X x g) . w
    o_jac[n, 3] = xc1 * rz - xc2 * ry
    o_jac[n, 4] = xc2 * rx - xc0 * rz
    o_jac[n, 5] = xc0 * ry - xc1 * rx
    o_cam[n] = k
    o_comp[n] = comp
    o_quadric[n] = j
    o_pixel[n, 0] = u
    o_pixel[n, 1] = v
    o_normal[n, 0] = nx
    o_normal[n, 1] = ny
    o_point[n, 0] = xc0
    o_point[n, 1] = xc1
    o_point[n, 2] = xc2
    return n + 1


@njit(cache=True, nogil=True)
def place(
    quadric, clip, bound, quadric_component, poses, camera_from_world, o_from, o_quadric, o_clip, o_sphere, o_cone
):
    """Every quadric in every camera's frame: with E = P_k W_kc (camera from component, ``poses`` (C, N, 4, 4) each
    camera's own, :func:`sample_outlines`), ``o_from`` = E,
    ``o_quadric`` = E^-T Q E^-1 and ``o_clip`` = E^-T Q2 E^-1 (C, Q, 4, 4), ``o_sphere`` (C, Q, 4)
    the bounding sphere (centre in the camera frame, radius) and ``o_cone`` (C, Q, 6) the cone of
    rays through it (see :func:`_cones`).  No allocation."""
    e_inv = np.zeros((4, 4))
    half = np.empty((4, 4))
    e_inv[3, 3] = 1.0
    for k in range(camera_from_world.shape[0]):
        p = camera_from_world[k]
        for j in range(quadric.shape[0]):
            w = poses[k, quadric_component[j]]
            e = o_from[k, j]
            for a in range(3):
                for b in range(4):
                    e[a, b] = p[a, 0] * w[0, b] + p[a, 1] * w[1, b] + p[a, 2] * w[2, b] + (p[a, 3] if b == 3 else 0.0)
            e[3, 0] = e[3, 1] = e[3, 2] = 0.0
            e[3, 3] = 1.0
            for a in range(3):  # E^-1 = [[R^T, -R^T t], [0, 1]]
                for b in range(3):
                    e_inv[a, b] = e[b, a]
                e_inv[a, 3] = -(e[0, a] * e[0, 3] + e[1, a] * e[1, 3] + e[2, a] * e[2, 3])
                o_sphere[k, j, a] = e[a, 0] * bound[j, 0] + e[a, 1] * bound[j, 1] + e[a, 2] * bound[j, 2] + e[a, 3]
            o_sphere[k, j, 3] = bound[j, 3]
            for m in range(2):
                src = quadric[j] if m == 0 else clip[j]
                dst = o_quadric[k, j] if m == 0 else o_clip[k, j]
                for a in range(4):  # half = Q E^-1, dst = E^-T half
                    for b in range(4):
                        acc = 0.0
                        for c in range(4):
                            acc += src[a, c] * e_inv[c, b]
                        half[a, b] = acc
                for a in range(4):
                    for b in range(4):
                        acc = 0.0
                        for c in range(4):
                            acc += e_inv[c, a] * half[c, b]
                        dst[a, b] = acc
        _cones(o_sphere[k], o_cone[k])


@njit(cache=True, nogil=True)
def outline_kernel(
    quadric,
    clip,
    bound,
    quadric_component,
    poses,
    cam_matrix,
    camera_from_world,
    cam_lens,
    cam_dist,
    cam_size,
    spacing,
    placed_from,
    placed_quadric,
    placed_clip,
    placed_sphere,
    placed_cone,
    o_cam,
    o_comp,
    o_quadric,
    o_pixel,
    o_normal,
    o_jac,
    o_point,
):
    """Sample the visible outlines of all quadrics in all cameras; returns the sample count.

    The ``placed_*`` buffers receive :func:`place`'s camera-frame quadrics (later stages reuse them)."""
    place(
        quadric,
        clip,
        bound,
        quadric_component,
        poses,
        camera_from_world,
        placed_from,
        placed_quadric,
        placed_clip,
        placed_sphere,
        placed_cone,
    )
    n_quadrics = quadric.shape[0]
    occluders = np.empty(n_quadrics, np.int64)
    n = 0
    for k in range(cam_matrix.shape[0]):
        k_mat = cam_matrix[k]
        k_inv = np.linalg.inv(k_mat)
        size = cam_size[k]
        width, height = float(size[0]), float(size[1])
        q_cam = placed_quadric[k]
        clip_cam = placed_clip[k]
        cam_from_comp = placed_from[k]
        sphere = placed_sphere[k]
        cone = placed_cone[k]
        for j in range(n_quadrics):
            centre = sphere[j, 0:3].copy()
            radius = sphere[j, 3]
            if centre[2] + radius <= 0.0:
                continue
            # projected bounding disc (ideal pixels); the whole plane when the sphere reaches the camera
            focal = max(k_mat[0, 0], k_mat[1, 1])
            if centre[2] - radius > 1e-6:
                disc_c = k_mat @ (centre / centre[2])
                disc_r = (
                    focal * radius / (centre[2] - radius) * (1.0 + np.sqrt(centre[0] ** 2 + centre[1] ** 2) / centre[2])
                )
                if (
                    disc_c[0] + disc_r < -0.25 * width
                    or disc_c[0] - disc_r > 1.25 * width
                    or disc_c[1] + disc_r < -0.25 * height
                    or disc_c[1] - disc_r > 1.25 * height
                ):
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
            conic_scale = np.abs(conic).max()
            big = max(abs(lam[0]), abs(lam[2]))
            if big == 0.0:
                continue
            n_occluders = _occluders(j, cone, occluders)  # only for the quadrics that pass the culls above
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
                    outside = _outside(px, py, width, height)
                    if outside == 0.0 and (px - disc_c[0]) ** 2 + (py - disc_c[1]) ** 2 <= disc_r * disc_r:
                        n = _emit(
                            px,
                            py,
                            j,
                            k,
                            comp,
                            conic,
                            conic_scale,
                            q_cam,
                            clip_cam,
                            sphere,
                            occluders,
                            n_occluders,
                            cam_from_comp[j],
                            k_mat,
                            k_inv,
                            cam_lens[k],
                            cam_dist[k],
                            size,
                            o_cam,
                            o_comp,
                            o_quadric,
                            o_pixel,
                            o_normal,
                            o_jac,
                            o_point,
                            n,
                        )
                    # arc length >= distance: off the image, skip straight to where it could re-enter
                    theta += max(max(spacing, outside) / max(speed, 1e-12), min_step)
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
                        if _outside(fx - t * uy, fy + t * ux, width, height) > 0.0:
                            continue
                        n = _emit(
                            fx - t * uy,
                            fy + t * ux,
                            j,
                            k,
                            comp,
                            conic,
                            conic_scale,
                            q_cam,
                            clip_cam,
                            sphere,
                            occluders,
                            n_occluders,
                            cam_from_comp[j],
                            k_mat,
                            k_inv,
                            cam_lens[k],
                            cam_dist[k],
                            size,
                            o_cam,
                            o_comp,
                            o_quadric,
                            o_pixel,
                            o_normal,
                            o_jac,
                            o_point,
                            n,
                        )
    return n


def sample_outlines(
    model, poses: np.ndarray, rig: Rig, *, spacing: float, samples: Samples, placed: Placed | None = None
) -> Samples:
    """Fill ``samples`` with the visible outline of ``model`` at ``poses`` (N,4,4) seen by ``rig``, or (C, N, 4, 4)
    each camera's own (each view at its capture time, docs/sync.md), and ``placed``, if given, with the
    camera-frame quadrics."""
    cameras = len(rig.names)
    placed = Placed.allocate(cameras, model.quadric.shape[0]) if placed is None else placed
    if poses.ndim == 3:
        poses = np.broadcast_to(poses, (cameras, *poses.shape))
    samples.count = outline_kernel(
        model.quadric,
        model.clip,
        model.quadric_bound,
        model.quadric_component,
        np.ascontiguousarray(poses),
        rig.matrix,
        rig.camera_from_world,
        rig.lens,
        rig.distortion,
        rig.size,
        float(spacing),
        placed.camera_from,
        placed.quadric,
        placed.clip,
        placed.sphere,
        placed.cone,
        samples.camera,
        samples.component,
        samples.quadric,
        samples.pixel,
        samples.normal,
        samples.jacobian,
        samples.point,
    )
    return samples
