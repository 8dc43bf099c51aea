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
from typing import Any, cast

import numpy as np

from tracker.atomic import atomic_write
from tracker.io.poses import flush_due
from tracker.physics.points import FrameFit, PointsModel


class ShapesWriter:
    """Collects each frame's shapes, residuals and joint violation of a :class:`FrameFit` and keeps
    shapes.npz up to date on PosesWriter's schedule (:func:`tracker.io.poses.flush_due`); ``write``
    rewrites it with the frames so far (or the first ``count``)."""

    def __init__(self, path: str | os.PathLike, model: PointsModel, flush_every: int = 25) -> None:
        self.path = path
        self.model = model
        self.flush_every = flush_every
        self.columns: dict[str, list] = {"frame": [], "q_s": [], "d": [], "residual": [], "violation": []}
        self._unflushed = 0

    def append(self, frame: int, fitted: FrameFit) -> None:
        row = {
            "frame": frame,
            "q_s": fitted.shapes,
            "d": fitted.displacements,
            "residual": fitted.residual,
            "violation": fitted.violation,
        }
        for key, value in row.items():
            self.columns[key].append(value)
        self._unflushed += 1
        if flush_due(self._unflushed, len(self.columns["frame"]), self.flush_every):
            self.write()

    def arrays(self, count: int | None = None) -> dict[str, np.ndarray]:
        """The first ``count`` frames (default all) as the shapes.npz arrays."""
        model, columns = self.model, {key: values[:count] for key, values in self.columns.items()}
        frames, parts, nodes = len(columns["frame"]), len(model.parts), len(model.mesh.u)
        return {
            "frame": np.array(columns["frame"], dtype=np.int64),
            "part_names": np.array(model.parts, dtype=str),
            "q_s": np.array(columns["q_s"]).reshape(frames, parts, 11),
            "d": np.array(columns["d"]).reshape(frames, parts, nodes, 3),
            "mesh": np.array([model.mesh.n_rings, model.mesh.n_longitudes], dtype=np.int64),
            "residual": np.array(columns["residual"]).reshape(frames, parts),
            "violation": np.array(columns["violation"], dtype=np.float64),
            "marker_names": np.array(model.marker_names, dtype=str),
            "marker_part": model.labels.astype(np.int64),
        }

    def write(self, count: int | None = None) -> dict[str, np.ndarray]:
        """Rewrite shapes.npz with the first ``count`` frames (default all), atomically; returns its arrays."""
        arrays = self.arrays(count)
        # the cast: numpy's stub takes any key of **arrays for allow_pickle (a bool)
        atomic_write(self.path, lambda file: np.savez(file, **cast(dict[str, Any], arrays)))
        self._unflushed = 0
        return arrays
