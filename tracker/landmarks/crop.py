"""Regions of an image for the detector: a square around a body's landmarks, the search's tiles, and the
maps between a region's crop and the full image.

BlazePose's person detector sees the whole image shrunk to 224x224, so a body a few dozen pixels
tall in it is a few pixels there and goes unseen; its landmark model works on a 256x256 crop around
the person.  A square region of side ``a`` centred at ``c`` (full-image pixels) is cut out and resized
to ``n`` x ``n`` pixels, so a pixel ``x`` of the image lands at

    x_crop = (n / a) (x - c) + n / 2,        x = (a / n) (x_crop - n / 2) + c

(OpenCV's pixel convention on both sides; the parts of the square outside the image are black, as
the detector's own letterbox pads).  A body found once is followed in the next image by the square
around its landmarks, :data:`MARGIN` times their extent, where it fills about the share of the crop
that the detector finds best; a body never found is looked for in :func:`search`'s squares.  docs/keypoints.md,
"Small, high-seen and cut bodies".
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

CROP = 256
"""Side of a region's crop in pixels: the landmark model's input size."""

MARGIN = 2.5
"""A followed region's side over the longer side of its landmarks' bounding box."""

SMALLEST = 32.0
"""The least side of a followed region in image pixels (a body smaller than this is not followed)."""


@dataclass(frozen=True)
class Region:
    """A square of an image: ``centre`` (x, y) pixels and ``side`` pixels; it may reach beyond the image."""

    centre: tuple[float, float]
    side: float


def around(pixels: np.ndarray, margin: float = MARGIN) -> Region | None:
    """The square centred on the bounding box of the finite ``pixels`` (33, 2), ``margin`` times its longer
    side (at least :data:`SMALLEST`); None when no pixel is finite."""
    finite = pixels[np.isfinite(pixels).all(axis=1)]
    if not len(finite):
        return None
    low, high = finite.min(axis=0), finite.max(axis=0)
    centre = (low + high) / 2.0
    return Region((float(centre[0]), float(centre[1])), max(SMALLEST, margin * float((high - low).max())))


def crop_from_image(region: Region, size: int = CROP) -> np.ndarray:
    """The affine map (2, 3) of full-image pixels to the pixels of ``region``'s ``size`` x ``size`` crop."""
    scale = size / region.side
    (x, y), half = region.centre, size / 2.0
    return np.array([[scale, 0.0, half - scale * x], [0.0, scale, half - scale * y]])


def cut(image: np.ndarray, region: Region, size: int = CROP) -> np.ndarray:
    """The ``size`` x ``size`` crop of ``region`` from ``image`` (H, W[, 3]) uint8, black beyond the image."""
    return cv2.warpAffine(
        image, crop_from_image(region, size), (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
    )


def to_image(pixels_crop: np.ndarray, region: Region, size: int = CROP) -> np.ndarray:
    """Full-image pixels (M, 2) of pixels (M, 2) of ``region``'s ``size`` x ``size`` crop."""
    return (region.side / size) * (pixels_crop - size / 2.0) + np.asarray(region.centre)


def within(square: Region, region: Region, size: int = CROP) -> Region:
    """The full-image square of ``square``, a square of ``region``'s ``size`` x ``size`` crop."""
    ((x, y),) = to_image(np.array([square.centre]), region, size)
    return Region((float(x), float(y)), square.side * region.side / size)


def scaled(square: Region, factor: float) -> Region:
    """``square`` of an image reduced by ``factor`` in the full image (a reduced image spans the full one's whole
    blocks: its pixels' shares of the width and height are the full image's)."""
    return Region((factor * square.centre[0], factor * square.centre[1]), factor * square.side)


def search(width: int, height: int) -> list[Region]:
    """The squares a body never found is looked for in, over a ``width`` x ``height`` image, in order: the
    whole image shrunk into a square twice its long side (a body cut by the border, or too large, then
    fills a share of the crop the detector finds), then tiles of half the short side, each overlapping
    its neighbours by half, row by row from the top left, all inside the image (a small body then fills
    four times the share of the crop that it fills of the image)."""
    side = min(width, height) // 2
    columns = np.linspace(0, width - side, int(np.ceil(2 * (width - side) / side)) + 1)
    rows = np.linspace(0, height - side, int(np.ceil(2 * (height - side) / side)) + 1)
    whole = Region((width / 2.0, height / 2.0), 2.0 * max(width, height))
    return [whole] + [
        Region((float(x) + side / 2.0, float(y) + side / 2.0), float(side)) for y in rows for x in columns
    ]
