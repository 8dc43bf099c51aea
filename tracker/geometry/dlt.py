"""Points from rays: the linear (DLT) triangulation of a point seen in several calibrated views.

Each view's ideal normalised image point (x, y) and its camera's [R | t] give two linear equations in the
point's homogeneous coordinates X: x (r3 . X) - (r1 . X) = 0 and y (r3 . X) - (r2 . X) = 0.  Stacked over the
views, the right singular vector of the smallest singular value is the point nearest to every equation in
the least-squares sense: the linear triangulation of Hartley and Zisserman's "Multiple View Geometry".
"""

from __future__ import annotations

import numpy as np


def triangulate_many(projections: np.ndarray, normalised: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """World points (M, 3) nearest in the linear (DLT) sense to the rays of ``normalised`` (M, C, 2) in the
    cameras whose ``seen`` (M, C) is set; NaN where fewer than two cameras see a point.  ``projections``
    (C, 3, 4): each camera's [R | t]."""
    x, y = normalised[..., 0:1], normalised[..., 1:2]  # (M, C, 1)
    rows = np.concatenate(
        [x * projections[None, :, 2] - projections[None, :, 0], y * projections[None, :, 2] - projections[None, :, 1]],
        axis=1,
    )  # (M, 2C, 4)
    weight = np.concatenate([seen, seen], axis=1)[..., None]
    rows = np.where(weight, np.nan_to_num(rows), 0.0)
    point = np.linalg.svd(rows)[2][:, -1]  # (M, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        world = point[:, :3] / point[:, 3:4]
    world[seen.sum(axis=1) < 2] = np.nan
    return world
