"""The person's mask on the region cue's grid, against a brute-force bilinear reading of the mask."""

from __future__ import annotations

import numpy as np
import pytest

from tracker.landmarks.crop import Region, cut
from tracker.tracking.person import person_grid


def bilinear(mask: np.ndarray, x: float, y: float) -> float:
    """``mask`` at (x, y), pixel centres at integers, 0 beyond it."""
    u, v = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - u, y - v
    total = 0.0
    for du, dv, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        if 0 <= v + dv < mask.shape[0] and 0 <= u + du < mask.shape[1]:
            total += w * mask[v + dv, u + du]
    return total


@pytest.mark.parametrize("factor", [2, 4])
@pytest.mark.parametrize("square", [(100.0, 80.0, 120.0), (37.3, 151.9, 64.5)])
def test_each_grid_pixel_reads_the_mask_where_its_full_size_point_falls(square, factor):
    """A pixel (u, v) of a colour grid of ``factor`` full-size pixels each is the full-size point (f u + (f - 1) / 2,
    f v + (f - 1) / 2): half size (2) for most views, a quarter for those the edge search reduces by 2."""
    rng = np.random.default_rng(3)
    mask = rng.integers(0, 256, (32, 32)).astype(np.uint8)
    size = np.array([110, 100])
    grid = person_grid(mask, np.array(square), size, factor=factor)
    assert grid.shape == (100, 110) and grid.dtype == np.uint8
    cx, cy, side = square
    for v, u in rng.integers(0, 100, (200, 2)):
        x, y = factor * u + (factor - 1) / 2, factor * v + (factor - 1) / 2
        mx, my = 32 / side * (x - cx) + 16, 32 / side * (y - cy) + 16
        expected = bilinear(mask, mx, my) if -1 < mx < 32 and -1 < my < 32 else 0.0
        assert grid[v, u] == pytest.approx(expected, abs=1.0), (u, v)


def test_a_mask_cut_from_the_image_comes_back_to_it():
    """The detector cuts its mask to a square of the image (tracker.landmarks.crop.cut); on the half-size grid
    it is back where the image had it: a disc of radius 40 about (130, 90) in a 260 x 200 image."""
    v, u = np.mgrid[0:200, 0:260]
    image = ((u - 130.0) ** 2 + (v - 90.0) ** 2 <= 40.0**2).astype(np.float32)
    square = Region((128.0, 95.0), 150.0)
    mask = np.rint(cut(image, square) * 255).astype(np.uint8)
    grid = person_grid(mask, np.array([*square.centre, square.side]), np.array([130, 100]))
    hv, hu = np.mgrid[0:100, 0:130]
    distance = np.hypot(2 * hu + 0.5 - 130.0, 2 * hv + 0.5 - 90.0)
    assert (grid[distance < 37] >= 128).all() and (grid[distance > 43] < 128).all()
