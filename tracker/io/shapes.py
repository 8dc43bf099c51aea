"""``shapes.npz``: the shape of every part per frame, written by ``tracker points`` beside poses.npz.

Arrays, F frames, P parts, n nodes per part, M markers:

    frame (F,) int64               frame number in the marker file
    part_names (P,) str
    q_s (F, P, 11) float64         global shape (a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3),
                                   superquadric.py; a0 = 1 (the gauge), lengths in metres
    d (F, P, n, 3) float64         nodal displacements in each part's frame, metres
    mesh (2,) int64                node rings and longitudes (superquadric.mesh rebuilds u, v)
    residual (F, P) float64        RMS marker-to-node distance per part, metres (NaN: no marker seen)
    violation (F,) float64         largest joint violation |C|, metres
    marker_names (M,) str          the markers used, part after part
    marker_part (M,) int64         the part of each marker

With poses.npz (world_from_part, and the joints) it rebuilds every node:
x_i = c + R (s(q_s; u_i, v_i) + d_i).  Written atomically, like poses.npz.
"""

from __future__ import annotations

import os

import numpy as np

from tracker.io.atomic import atomic_write
from tracker.physics.points import FrameFit, PointsModel


class ShapesWriter:
    """Collects one :class:`FrameFit` per frame; ``write`` rewrites shapes.npz with the frames so far."""

    def __init__(self, path: str | os.PathLike, model: PointsModel) -> None:
        self.path = path
        self.model = model
        self.rows: list[tuple[int, FrameFit]] = []

    def append(self, frame: int, fitted: FrameFit) -> None:
        self.rows.append((frame, fitted))

    def __len__(self) -> int:
        return len(self.rows)

    def arrays(self, count: int | None = None) -> dict[str, np.ndarray]:
        """The first ``count`` frames (default all) as the shapes.npz arrays."""
        model, rows = self.model, self.rows[:count]
        parts = len(model.parts)
        nodes = len(model.mesh.u)
        return {
            "frame": np.array([frame for frame, _ in rows], dtype=np.int64),
            "part_names": np.array(model.parts, dtype=str),
            "q_s": np.array([fit.shapes for _, fit in rows]).reshape(len(rows), parts, 11),
            "d": np.array([fit.displacements for _, fit in rows]).reshape(len(rows), parts, nodes, 3),
            "mesh": np.array([model.mesh.n_rings, model.mesh.n_longitudes], dtype=np.int64),
            "residual": np.array([fit.residual for _, fit in rows]).reshape(len(rows), parts),
            "violation": np.array([fit.violation for _, fit in rows], dtype=np.float64),
            "marker_names": np.array(model.marker_names, dtype=str),
            "marker_part": model.labels.astype(np.int64),
        }

    def write(self, count: int | None = None) -> None:
        """Rewrite shapes.npz with the first ``count`` frames (default all), atomically."""
        arrays = self.arrays(count)
        atomic_write(self.path, lambda file: np.savez(file, **arrays))
