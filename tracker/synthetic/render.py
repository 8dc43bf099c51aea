"""A renderer of bodies of clipped quadrics: the ray caster's hits (:mod:`tracker.raycast`, independent
of the tracker's outline code) shaded and composited.

:class:`Renderer` shades the hits, softens the edges and
composites the body over a background (a photo, or a rendered room: :mod:`tracker.synthetic.room`) with
sensor noise; optionally it paints clothes on the body (:mod:`tracker.synthetic.texture`) and a face on its
head (:mod:`tracker.synthetic.face`), stands opaque props such as a table in the scene (:mod:`tracker.synthetic.props`)
and averages sub-frame poses into motion blur.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.model import Model
from tracker.raycast import DEFAULT_LIGHT, RayCaster
from tracker.synthetic.face import Face, paint_face
from tracker.synthetic.props import Box, backdrop
from tracker.synthetic.texture import Texture, paint

BACKGROUNDS = Path(__file__).resolve().parent / "data" / "backgrounds"
"""Folder of the background photos shipped with the package (OpenCV samples, licence in its README.md)."""

DEFAULT_BACKGROUNDS = ("basketball1.png", "basketball2.png")
"""The room photos used by default (``board.jpg`` is a circuit-board texture, not a room, and
its fine detail makes Motion-JPEG videos about three times larger; pass it explicitly if wanted)."""


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


class Renderer(RayCaster):
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
        super().__init__(model, camera, light, ambient, key, fill)
        w, h = camera.size
        self.background = np.full((h, w, 3), 128, np.uint8) if background is None else background
        if self.background.shape != (h, w, 3):
            raise ValueError(
                f"background shape {self.background.shape} does not match camera {camera.name} ({h}, {w}, 3)"
            )
        self.blur, self.noise = blur, noise
        self.props_depth: np.ndarray | None = None  # depth (H, W) of the props, inf where there are none
        if props:
            self.background, self.props_depth = backdrop(
                list(props),
                camera,
                self.rays,
                background=self.background,
                light_world=self.light_world,
                ambient=ambient,
                key=key,
                fill=fill,
                blur=blur,
            )
        self._background_f32 = self.background.astype(np.float32)
        self.albedo = albedos(model).astype(np.float32) * 255.0
        self.texture, self.face = texture, face

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
