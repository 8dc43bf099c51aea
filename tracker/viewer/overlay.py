"""Camera images annotated with what the edge search saw (:class:`tracker.tracking.frame_loop.Inspection`).

On each camera's image: every sample's search line, coloured by its IRLS weight
relative to a perfect fit, ``w c = c / (c + |m|)`` (green when the edge lies on
the predicted outline, through yellow to red as it lies farther off, grey when
no edge was found); the predicted outline as dots in its component's colour; and
the edge each search found as a white dot.  A limb that drifts shows as a run of
red or grey lines, and the white dots show which edge pulled it.  A part the images
do not hold (:mod:`tracker.tracking.held`: a leg behind a table, carried by the prior
and its joints alone) is drawn dim, a sparse dotted outline with no search lines.
"""

from __future__ import annotations

import colorsys
from collections.abc import Sequence
from typing import cast

import cv2
import numpy as np

from tracker.io.mosaic import MosaicWriter
from tracker.status import HELD
from tracker.tracking.workspace import Inspection

_SHIFT = 2  # sub-pixel drawing: coordinates in quarter pixels
_BINS = 6  # weight colours
_NO_EDGE = (110, 110, 110)
DIM_EVERY = 3  # a part the images do not hold: one outline sample in this many drawn (draw_dim)
DIM_OPACITY = 0.4  # ... at this opacity over the image


def component_colours(count: int) -> np.ndarray:
    """Distinct RGB uint8 colours, one per component (hues spread around the circle)."""
    hues = (np.arange(count) * 0.618034) % 1.0
    return np.array([[round(255 * c) for c in colorsys.hsv_to_rgb(h, 0.65, 0.95)] for h in hues], np.uint8)


def weight_colour(quality: float) -> tuple[int, int, int]:
    """RGB from red (quality 0) through yellow to green (quality 1)."""
    q = float(np.clip(quality, 0.0, 1.0))
    return (round(255 * min(1.0, 2.0 * (1.0 - q))), round(255 * min(1.0, 2.0 * q)), 40)


def _fixed(points: np.ndarray) -> np.ndarray:
    return np.round(points * (1 << _SHIFT)).astype(np.int32)


def draw(
    image: np.ndarray,
    inspection: Inspection,
    camera: int,
    *,
    robust_c: float,
    colours: np.ndarray,
    held: np.ndarray | None = None,
) -> np.ndarray:
    """RGB uint8 copy of a grey (or RGB) ``image`` with camera ``camera``'s search lines, outline and edges; given
    ``held`` (N,) codes (:data:`tracker.status.HELD`, ...), the parts the images do not hold are drawn dim
    (:func:`draw_dim`) and the rest as always."""
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB) if image.ndim == 2 else image.copy()
    mine = inspection.camera == camera
    if held is not None:
        loose = mine & (held[inspection.component] != HELD)
        draw_dim(out, inspection.pixel[loose], inspection.component[loose], colours=colours)
        mine &= ~loose
    pixel, normal = inspection.pixel[mine], inspection.normal[mine]
    offset, weight = inspection.offset[mine], inspection.weight[mine]
    start = _fixed(pixel + inspection.lo[mine, None] * normal)
    end = _fixed(pixel + inspection.hi[mine, None] * normal)
    lines = np.stack([start, end], 1)[:, :, None, :]  # (n, 2, 1, 2) for polylines
    found = ~np.isnan(offset)
    level = np.minimum((weight * robust_c * _BINS).astype(np.int64), _BINS - 1)
    groups = [(~found, _NO_EDGE)] + [(found & (level == b), weight_colour((b + 0.5) / _BINS)) for b in range(_BINS)]
    for chosen, colour in groups:
        if chosen.any():
            cv2.polylines(out, list(lines[chosen]), False, colour, 1, cv2.LINE_AA, _SHIFT)
    outline = _fixed(pixel)
    component = inspection.component[mine]
    for i in np.unique(component):
        colour = cast(tuple[int, int, int], tuple(int(c) for c in colours[i]))  # RGB
        for x, y in outline[component == i]:
            cv2.circle(out, (int(x), int(y)), 2 << _SHIFT, colour, -1, cv2.LINE_AA, _SHIFT)
    for x, y in _fixed(pixel[found] + offset[found, None] * normal[found]):
        cv2.circle(out, (int(x), int(y)), 1 << _SHIFT, (255, 255, 255), -1, cv2.LINE_AA, _SHIFT)
    return out


def draw_dim(out: np.ndarray, pixel: np.ndarray, component: np.ndarray, *, colours: np.ndarray) -> None:
    """Draw on ``out`` (H, W, 3) RGB uint8, in place, the outline samples at ``pixel`` (M, 2) of parts the images do
    not hold, dim: every :data:`DIM_EVERY`-th sample of each part as a small dot in its colour at :data:`DIM_OPACITY`,
    with no search line or edge, so that a part the prior alone carries shows where it is assumed, not as a part
    the images found."""
    if not len(pixel):
        return
    layer = out.copy()
    fixed = _fixed(pixel)
    for i in np.unique(component):
        colour = cast(tuple[int, int, int], tuple(int(c) for c in colours[i]))  # RGB
        for x, y in fixed[component == i][::DIM_EVERY]:
            cv2.circle(layer, (int(x), int(y)), 2 << _SHIFT, colour, -1, cv2.LINE_AA, _SHIFT)
    cv2.addWeighted(layer, DIM_OPACITY, out, 1.0 - DIM_OPACITY, 0.0, dst=out)


class OverlayVideo:
    """A video of every camera side by side with :func:`draw`'s annotations (``tracker track --overlay``)."""

    def __init__(self, path, cameras, fps: float, components: int, robust_c: float):
        self.writer = MosaicWriter(path, [camera.size for camera in cameras], fps)
        self.colours = component_colours(components)
        self.robust_c = robust_c

    def write(self, images: Sequence[np.ndarray], inspection: Inspection, held: np.ndarray | None = None) -> None:
        """One frame: the ``images`` (rig order) drawn with ``inspection`` and, given, the parts ``held`` (N,)."""
        self.writer.write(
            [
                draw(image, inspection, k, robust_c=self.robust_c, colours=self.colours, held=held)
                for k, image in enumerate(images)
            ]
        )

    def close(self) -> None:
        self.writer.close()
