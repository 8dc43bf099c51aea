"""Ray casting of a body of clipped quadrics, independent of the tracker's outline code: which
component each pixel of a camera sees, with its shade and depth.

One ray per pixel (exact lens distortion: the rays go through the undistorted pixel centres) is
intersected with every clipped quadric (no conics), so a disagreement between this and
:mod:`tracker.tracking.outline` points at a bug in one of them.  The renderer (:mod:`tracker.synthetic.render`) shades,
paints and composites what a :class:`RayCaster` sees; the foreground cue (:mod:`tracker.tracking.foreground`)
takes the body's pixels from one.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from tracker.camera import Camera
from tracker.model import Model


def pixel_rays(camera: Camera) -> np.ndarray:
    """Normalised undistorted coordinates (H, W, 2) of every pixel centre: the ray (x, y, 1) in the camera frame.

    Exact inverse of the camera's lens model (``undistort_pixels`` to 1e-14), so
    the rendered images carry the rig's distortion.
    """
    w, h = camera.size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    return np.ascontiguousarray(camera.undistort_pixels(pixels).reshape(h, w, 2))


def view_quadrics(model: Model, poses: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Surfaces and clips of every quadric in the camera frame (Q, 4, 4): T^-T Q T^-1 with T = P_cam E_c."""
    transforms = camera.camera_from_world @ poses[model.quadric_component]
    inverse = np.linalg.inv(transforms)
    inverse_t = np.transpose(inverse, (0, 2, 1))
    surfaces = inverse_t @ model.quadric @ inverse
    clips = inverse_t @ model.clip @ inverse
    return (
        np.ascontiguousarray(0.5 * (surfaces + np.transpose(surfaces, (0, 2, 1)))),
        np.ascontiguousarray(0.5 * (clips + np.transpose(clips, (0, 2, 1)))),
    )


def view_boxes(model: Model, poses: np.ndarray, camera: Camera) -> np.ndarray:
    """Per quadric a box (Q, 4) [x0, y0, x1, y1] in normalised coordinates holding its image.

    From the bounding sphere's cube (an overestimate); the whole plane when the
    sphere reaches behind the camera, an empty box when it is wholly behind.
    """
    centres, radii = model.quadric_bound[:, 0:3], model.quadric_bound[:, 3] * 1.001 + 1e-6
    comp = model.quadric_component
    world = np.einsum("qab,qb->qa", poses[comp, 0:3, 0:3], centres) + poses[comp, 0:3, 3]
    cam = world @ camera.rotation.T + camera.translation
    boxes = np.empty((len(radii), 4))
    for k, (s, r) in enumerate(zip(cam, radii)):
        if not np.isfinite(r) or s[2] - r <= 1e-6:
            boxes[k] = (-np.inf, -np.inf, np.inf, np.inf) if s[2] + r > 0 else (1.0, 1.0, -1.0, -1.0)
            continue
        near, far = s[2] - r, s[2] + r
        boxes[k] = (
            min((s[0] - r) / near, (s[0] - r) / far),
            min((s[1] - r) / near, (s[1] - r) / far),
            max((s[0] + r) / near, (s[0] + r) / far),
            max((s[1] + r) / near, (s[1] + r) / far),
        )
    return boxes


@njit(cache=True, inline="always")
def _form(m, x, y, z, w):
    """X~^T M X~ for X~ = (x, y, z, w) and symmetric M."""
    return (
        m[0, 0] * x * x
        + m[1, 1] * y * y
        + m[2, 2] * z * z
        + m[3, 3] * w * w
        + 2.0
        * (m[0, 1] * x * y + m[0, 2] * x * z + m[0, 3] * x * w + m[1, 2] * y * z + m[1, 3] * y * w + m[2, 3] * z * w)
    )


@njit(cache=True)
def _nearest_hit(q, clip, x, y):
    """Smallest depth t > 0 at which the ray t (x, y, 1) meets the kept part of quadric ``q``; inf if none.

    Roots of a t^2 + b t + c = 0 (a = d^T Q d, b = 2 d^T q, c = Q_44 with the ray
    from the origin); the near root when it passes the clip, else the far one
    (no end caps: the inside of a tube shows through its open end).
    """
    a = _form(q, x, y, 1.0, 0.0)
    b = 2.0 * (q[0, 3] * x + q[1, 3] * y + q[2, 3])
    c = q[3, 3]
    scale = abs(a) + abs(b) + abs(c)
    if abs(a) <= 1e-12 * scale:
        if abs(b) <= 1e-300:
            return np.inf
        t1 = -c / b
        t2 = np.inf
    else:
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return np.inf
        root = np.sqrt(disc)
        h = -0.5 * (b + root) if b >= 0.0 else -0.5 * (b - root)
        if h == 0.0:
            t1 = t2 = 0.0
        else:
            t1 = h / a
            t2 = c / h
        if t1 > t2:
            t1, t2 = t2, t1
    for t in (t1, t2):
        if t > 1e-9 and t < np.inf and _form(clip, t * x, t * y, t, 1.0) <= 0.0:
            return t
    return np.inf


@njit(cache=True, parallel=True)
def render_kernel(rays, surfaces, clips, boxes, owner, light, ambient, key, fill, comp_out, shade_out, depth_out):
    """Ray-cast every pixel against every clipped quadric (numba; see :func:`render`).

    ``rays`` (H, W, 2) normalised coordinates of the pixel centres, ``surfaces``/
    ``clips`` (Q, 4, 4) in the camera frame, ``boxes`` (Q, 4) normalised bounds,
    ``owner`` (Q,) component per quadric, ``light`` (3,) unit direction towards
    the key light in the camera frame.  Writes per pixel the nearest hit's
    component (-1: none), shade ``ambient + key max(0, n.l) + fill |n.v|`` with n
    the unit surface normal turned towards the camera, and its depth z (inf: none).
    """
    h, w = rays.shape[0], rays.shape[1]
    nq = surfaces.shape[0]
    for v in prange(h):
        for u in range(w):
            x = rays[v, u, 0]
            y = rays[v, u, 1]
            best = np.inf
            hit = -1
            for k in range(nq):
                if x < boxes[k, 0] or x > boxes[k, 2] or y < boxes[k, 1] or y > boxes[k, 3]:
                    continue
                t = _nearest_hit(surfaces[k], clips[k], x, y)
                if t < best:
                    best = t
                    hit = k
            depth_out[v, u] = best
            if hit < 0:
                comp_out[v, u] = -1
                shade_out[v, u] = 0.0
                continue
            q = surfaces[hit]
            px, py, pz = best * x, best * y, best
            nx = q[0, 0] * px + q[0, 1] * py + q[0, 2] * pz + q[0, 3]
            ny = q[1, 0] * px + q[1, 1] * py + q[1, 2] * pz + q[1, 3]
            nz = q[2, 0] * px + q[2, 1] * py + q[2, 2] * pz + q[2, 3]
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            vn = np.sqrt(x * x + y * y + 1.0)
            facing = (nx * x + ny * y + nz) / (norm * vn)  # n . (ray direction)
            sign = -1.0 if facing > 0.0 else 1.0
            lambert = sign * (nx * light[0] + ny * light[1] + nz * light[2]) / norm
            comp_out[v, u] = owner[hit]
            shade_out[v, u] = ambient + key * max(lambert, 0.0) + fill * abs(facing)


_forms = _form.py_func
"""Vectorised X~^T M X~ over arrays x, y, z, w: :func:`_form` itself, run by numpy."""


def render(rays, surfaces, clips, *, owner, light, ambient=0.35, key=0.45, fill=0.3):
    """Pure-numpy reference of :func:`render_kernel` (no boxes): (component, shade, depth) per pixel.

    Same mathematics, vectorised over pixels one quadric at a time; slow, for tests.
    """
    x, y = rays[..., 0], rays[..., 1]
    one = np.ones_like(x)
    best = np.full(x.shape, np.inf)
    hit = np.full(x.shape, -1, dtype=np.int64)
    for k, (q, clip) in enumerate(zip(surfaces, clips)):
        a = _forms(q, x, y, one, 0.0 * one)
        b = 2.0 * (q[0, 3] * x + q[1, 3] * y + q[2, 3])
        c = q[3, 3] * one
        with np.errstate(invalid="ignore", divide="ignore"):
            disc = b * b - 4.0 * a * c
            root = np.sqrt(np.maximum(disc, 0.0))
            linear = np.abs(a) <= 1e-12 * (np.abs(a) + np.abs(b) + np.abs(c))
            t_a = np.where(linear, -c / b, (-b - root) / (2.0 * a))
            t_b = np.where(linear, np.inf, (-b + root) / (2.0 * a))
        t1, t2 = np.minimum(t_a, t_b), np.maximum(t_a, t_b)
        valid = linear | (disc >= 0.0)
        t = np.full(x.shape, np.inf)
        for root_t in (t2, t1):  # the near root wins when both pass
            with np.errstate(invalid="ignore"):
                ok = valid & np.isfinite(root_t) & (root_t > 1e-9)
                ok &= _forms(clip, root_t * x, root_t * y, root_t, one) <= 0.0
            t = np.where(ok, root_t, t)
        closer = t < best
        best = np.where(closer, t, best)
        hit = np.where(closer, k, hit)
    comp = np.where(hit >= 0, np.asarray(owner)[np.maximum(hit, 0)], -1)
    shade = np.zeros(x.shape)
    for k, q in enumerate(surfaces):
        sel = hit == k
        if not sel.any():
            continue
        points = np.stack([best[sel] * x[sel], best[sel] * y[sel], best[sel], np.ones(sel.sum())], axis=1)
        normals = points @ q[:, 0:3]
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        view = np.stack([x[sel], y[sel], np.ones(sel.sum())], axis=1)
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        facing = np.sum(normals * view, axis=1)
        normals[facing > 0] *= -1.0
        shade[sel] = ambient + key * np.maximum(normals @ light, 0.0) + fill * np.abs(facing)
    return comp, shade, best


DEFAULT_LIGHT = np.array([0.35, -0.45, 0.82])
"""Direction towards the key light in world (above, in front of the walking subject, to its left)."""


class RayCaster:
    """Casts one camera's pixel rays (precomputed once) at a body: :meth:`cast` per pose.

    The shade of a hit is ``ambient + key max(0, n.l) + fill |n.v|`` with ``light`` the direction
    towards the key light in world (:func:`render_kernel`).
    """

    def __init__(self, model: Model, camera: Camera, light=DEFAULT_LIGHT, ambient=0.35, key=0.45, fill=0.3):
        self.model, self.camera = model, camera
        self.rays = pixel_rays(camera)
        light = np.asarray(light, dtype=np.float64)
        self.light_world = light / np.linalg.norm(light)
        self.ambient, self.key, self.fill = ambient, key, fill
        w, h = camera.size
        self.comp = np.empty((h, w), np.int64)
        self.shade = np.empty((h, w), np.float64)
        self.depth = np.empty((h, w), np.float64)

    def cast(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Component id (-1: background), shade and depth per pixel for model poses (N, 4, 4)."""
        surfaces, clips = view_quadrics(self.model, poses, self.camera)
        boxes = view_boxes(self.model, poses, self.camera)
        light = self.camera.rotation @ self.light_world
        render_kernel(
            self.rays,
            surfaces,
            clips,
            boxes,
            self.model.quadric_component,
            light,
            self.ambient,
            self.key,
            self.fill,
            self.comp,
            self.shade,
            self.depth,
        )
        return self.comp, self.shade, self.depth
