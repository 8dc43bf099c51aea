"""A ray caster for bodies of clipped quadrics, independent of the tracker's outline code.

One ray per pixel (exact lens distortion: the rays go through the undistorted
pixel centres) is intersected with every clipped quadric (no conics), so a
disagreement between this renderer and :mod:`tracker.outline` points at a bug
in one of them.  :class:`Renderer` shades the hits, softens the edges and
composites the body over a background (a photo, or a rendered room: :mod:`tracker.room`) with
sensor noise; optionally it paints clothes on the body (:mod:`tracker.texture`) and a face on its
head (:mod:`tracker.face`), stands opaque props such as a table in the scene (:mod:`tracker.props`)
and averages sub-frame poses into motion blur.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numba import njit, prange

from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.face import Face, paint_face
from tracker.model import Model
from tracker.props import Box, backdrop
from tracker.texture import Texture, paint

BACKGROUNDS = Path(__file__).resolve().parent / "data" / "backgrounds"
"""Folder of the background photos shipped with the package (OpenCV samples, licence in its README.md)."""

DEFAULT_BACKGROUNDS = ("basketball1.png", "basketball2.png")
"""The room photos used by default (``board.jpg`` is a circuit-board texture, not a room, and
its fine detail makes Motion-JPEG videos about three times larger; pass it explicitly if wanted)."""


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


def render(rays, surfaces, clips, owner, light, ambient=0.35, key=0.45, fill=0.3):
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

ALBEDO = {
    # BGR reflectances: limbs differ from each other, left from right, and from typical backgrounds
    "pelvis": (0.42, 0.22, 0.16),  # dark blue shorts
    "torso": (0.80, 0.88, 0.92),  # light shirt
    "head": (0.50, 0.62, 0.82),  # skin
    "upperarm_l": (0.25, 0.55, 0.90),  # orange sleeve
    "upperarm_r": (0.20, 0.22, 0.48),  # dark red sleeve
    "forearm_l": (0.70, 0.80, 0.86),  # light
    "forearm_r": (0.20, 0.24, 0.30),  # dark
    "hand_l": (0.45, 0.56, 0.78),
    "hand_r": (0.38, 0.48, 0.70),
    "thigh_l": (0.62, 0.38, 0.22),  # blue
    "thigh_r": (0.26, 0.42, 0.28),  # dark green
    "shin_l": (0.92, 0.90, 0.86),  # white
    "shin_r": (0.14, 0.14, 0.16),  # black
    "foot_l": (0.10, 0.10, 0.12),
    "foot_r": (0.90, 0.92, 0.95),
}


def albedos(model: Model) -> np.ndarray:
    """BGR reflectance per component (N, 3): :data:`ALBEDO` by name, else alternating light and dark."""
    fallback = [(0.85, 0.85, 0.80), (0.20, 0.25, 0.35), (0.55, 0.70, 0.85), (0.60, 0.35, 0.20)]
    return np.array([ALBEDO.get(n, fallback[i % len(fallback)]) for i, n in enumerate(model.names)])


def load_backgrounds(cameras: list[Camera], paths=None, seed: int = 0) -> tuple[list[np.ndarray], list[Path]]:
    """One BGR background (H, W, 3) uint8 per camera and the photo files used.

    ``paths``: image files, or None for :data:`DEFAULT_BACKGROUNDS` in
    :data:`BACKGROUNDS` (those present). Camera k takes photo k mod n, mirrored on every second pass round the
    list, resized to cover the image and centre-cropped. Without photos, a
    smooth procedural backdrop with a few blurred blocks.
    """
    if paths is None:
        paths = [BACKGROUNDS / name for name in DEFAULT_BACKGROUNDS if (BACKGROUNDS / name).is_file()]
    paths = [Path(p) for p in paths]
    photos = []
    for p in paths:
        image = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if image is None:
            raise TrackerInputError(f"{p}: cannot read the background image; give a readable .png or .jpg")
        photos.append(image)
    out, used = [], []
    rng = np.random.default_rng(seed)
    for k, cam in enumerate(cameras):
        w, h = cam.size
        if photos:
            image = photos[k % len(photos)]
            if (k // len(photos)) % 2 == 1:
                image = image[:, ::-1]
            used.append(paths[k % len(photos)])
            scale = max(w / image.shape[1], h / image.shape[0])
            size = (max(w, round(image.shape[1] * scale)), max(h, round(image.shape[0] * scale)))
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
            x0, y0 = (image.shape[1] - w) // 2, (image.shape[0] - h) // 2
            out.append(np.ascontiguousarray(image[y0 : y0 + h, x0 : x0 + w]))
        else:
            yy, xx = np.mgrid[0:h, 0:w] / max(w, h)
            base = 90 + 60 * xx + 30 * yy + rng.uniform(-20, 20)
            image = np.repeat(base[..., None], 3, axis=2)
            for _ in range(12):
                x0, y0 = rng.integers(0, w), rng.integers(0, h)
                image[y0 : y0 + rng.integers(10, h // 3), x0 : x0 + rng.integers(10, w // 3)] = rng.uniform(30, 220, 3)
            out.append(np.clip(cv2.GaussianBlur(image, (0, 0), 3.0), 0, 255).astype(np.uint8))
    return out, sorted(set(used))


class Renderer:
    """Renders one camera: pixel rays precomputed once, then :meth:`render` per frame.

    ``texture`` paints the body's colours (None: the plain :func:`albedos`), ``face`` a face and hair
    on its head over them; ``props`` are drawn into the background once, and their depth hides the
    body behind them.
    """

    def __init__(
        self,
        model: Model,
        camera: Camera,
        background: np.ndarray | None = None,
        light=DEFAULT_LIGHT,
        ambient: float = 0.35,
        key: float = 0.45,
        fill: float = 0.3,
        blur: float = 0.7,
        noise: float = 3.0,
        *,
        texture: Texture | None = None,
        face: Face | None = None,
        props: tuple[Box, ...] = (),
    ):
        self.model, self.camera = model, camera
        self.rays = pixel_rays(camera)
        w, h = camera.size
        self.background = np.full((h, w, 3), 128, np.uint8) if background is None else background
        if self.background.shape != (h, w, 3):
            raise ValueError(
                f"background shape {self.background.shape} does not match camera {camera.name} ({h}, {w}, 3)"
            )
        light = np.asarray(light, dtype=np.float64)
        self.light_world = light / np.linalg.norm(light)
        self.ambient, self.key, self.fill = ambient, key, fill
        self.blur, self.noise = blur, noise
        self.props_depth: np.ndarray | None = None  # depth (H, W) of the props, inf where there are none
        if props:
            self.background, self.props_depth = backdrop(
                list(props),
                camera,
                self.rays,
                self.background,
                self.light_world,
                ambient=ambient,
                key=key,
                fill=fill,
                blur=blur,
            )
        self._background_f32 = self.background.astype(np.float32)
        self.albedo = albedos(model).astype(np.float32) * 255.0
        self.texture, self.face = texture, face
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

    def render(self, poses: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """BGR uint8 image of the body at ``poses`` over the background, soft edges, sensor noise.

        ``poses`` (N, 4, 4), or (S, N, 4, 4) for an exposure: the body layers of the S sub-frame poses
        are averaged (motion blur). The body layer (albedo, or the texture's colour, x shade) and its
        coverage are blurred with a Gaussian of ``blur`` px (premultiplied alpha, so edges mix body and
        background like a lens does), composited over the background (props included, which hide the
        body behind them), then Gaussian noise of ``noise`` grey levels (the same in the three channels)
        is added.
        """
        exposure = poses[None] if poses.ndim == 3 else poses
        layers = [layer for layer in (self._layer(p) for p in exposure) if layer is not None]
        image = self._background_f32.copy()
        if layers:
            y0, x0 = min(layer[0] for layer in layers), min(layer[1] for layer in layers)
            y1, x1 = (
                max(layer[0] + layer[3].shape[0] for layer in layers),
                max(layer[1] + layer[3].shape[1] for layer in layers),
            )
            body = np.zeros((y1 - y0, x1 - x0, 3), np.float32)
            mask = np.zeros((y1 - y0, x1 - x0), np.float32)
            for top, left, colour, coverage in layers:
                rows, cols = (
                    slice(top - y0, top - y0 + coverage.shape[0]),
                    slice(left - x0, left - x0 + coverage.shape[1]),
                )
                body[rows, cols] += colour
                mask[rows, cols] += coverage
            if len(exposure) > 1:
                body /= np.float32(len(exposure))
                mask /= np.float32(len(exposure))
            if self.blur > 0:
                body = cv2.GaussianBlur(body, (0, 0), self.blur, borderType=cv2.BORDER_REPLICATE)
                mask = cv2.GaussianBlur(mask, (0, 0), self.blur, borderType=cv2.BORDER_REPLICATE)
            image[y0:y1, x0:x1] = body + (1.0 - mask)[..., None] * image[y0:y1, x0:x1]
        if self.noise > 0:
            rng = np.random.default_rng() if rng is None else rng
            image += (rng.standard_normal(image.shape[:2], dtype=np.float32) * np.float32(self.noise))[..., None]
        np.clip(image, 0.0, 255.0, out=image)
        return (image + 0.5).astype(np.uint8)

    def _layer(self, poses: np.ndarray) -> tuple[int, int, np.ndarray, np.ndarray] | None:
        """The body at ``poses`` (N, 4, 4) in the box around it padded for the blur: its top row, left
        column, premultiplied colour (h, w, 3) float32 and coverage (h, w) float32; None when unseen."""
        comp, shade, depth = self.cast(poses)
        if self.props_depth is not None:
            comp = np.where(depth < self.props_depth, comp, -1)
        rows = np.flatnonzero((comp >= 0).any(axis=1))
        if not len(rows):
            return None
        cols = np.flatnonzero((comp[rows[0] : rows[-1] + 1] >= 0).any(axis=0))
        pad = int(np.ceil(4.0 * self.blur)) + 1
        h, w = comp.shape
        y0, y1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, h)
        x0, x1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)
        c = comp[y0:y1, x0:x1]
        mask: np.ndarray = (c >= 0).astype(np.float32)
        if self.texture is None and self.face is None:
            albedo = self.albedo[np.maximum(c, 0)]
        else:
            albedo = np.zeros((*c.shape, 3), np.float32)
            seen = c >= 0
            points = self._surface_points(poses, c[seen], depth[y0:y1, x0:x1][seen], self.rays[y0:y1, x0:x1][seen])
            colours = albedos(self.model)[c[seen]] if self.texture is None else paint(self.texture, c[seen], points)
            if self.face is not None:
                head = c[seen] == self.face.component
                colours[head] = paint_face(self.face, points[head])
            albedo[seen] = 255.0 * colours
        body = albedo * (shade[y0:y1, x0:x1].astype(np.float32) * mask)[..., None]
        return int(y0), int(x0), body, mask

    def _surface_points(self, poses: np.ndarray, comp: np.ndarray, depth: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """Hit points (M, 3) in their components' frames: component_from_camera (depth (x, y, 1))."""
        component_from_camera = np.linalg.inv(self.camera.camera_from_world @ poses)[comp]
        hits = depth[:, None] * np.concatenate([rays, np.ones((len(rays), 1))], axis=1)
        return np.einsum("mab,mb->ma", component_from_camera[:, 0:3, 0:3], hits) + component_from_camera[:, 0:3, 3]
