"""Triangle meshes of a model's clipped quadrics, for drawing (not for tracking).

Each component gets one mesh in its own frame, the union of its quadrics:
spheres and ellipsoids as latitude-longitude grids (cut at their ``clip`` planes
and closed by flat caps), cylinders and cones as open tubes closed by discs at
both ends.  The viewer then only moves a mesh by its component's pose.
"""

from __future__ import annotations

import numpy as np

from tracker.geometry.quadric import axis_frame
from tracker.model import Model


def _grid_faces(rows: int, columns: int, offset: int = 0) -> np.ndarray:
    """Two triangles per cell of a rows x columns vertex grid whose columns wrap around."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(columns), indexing="ij")
    a = r * columns + c
    b = r * columns + (c + 1) % columns
    d = a + columns
    e = b + columns
    return offset + np.concatenate([np.stack([a, b, e], -1).reshape(-1, 3), np.stack([a, e, d], -1).reshape(-1, 3)])


def _cap(ring: np.ndarray, centre: np.ndarray, offset: int, outward: bool) -> tuple[np.ndarray, np.ndarray]:
    """A fan of triangles closing a ring of vertices (indices from ``offset``) around ``centre``,
    facing along the ring's axis when ``outward``, against it otherwise."""
    n = len(ring)
    i = np.arange(n)
    faces = np.stack(
        [np.full(n, offset + n), offset + i, offset + (i + 1) % n], -1
    )  # normal +z for a ring counter-clockwise about +z
    return np.vstack([ring, centre]), faces if outward else faces[:, ::-1]


def ellipsoid_mesh(centre, radii, *, clip=None, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of an ellipsoid, optionally cut to ``zmin <= z - centre_z <= zmax`` (``clip``)."""
    a, b, c = (float(r) for r in radii)
    zmin, zmax = (-c, c) if clip is None else (max(clip[0], -c), min(clip[1], c))
    polar = np.linspace(np.arccos(zmax / c), np.arccos(zmin / c), max(segments // 2, 2) + 1)
    azimuth = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    p, t = np.meshgrid(polar, azimuth, indexing="ij")
    vertices = np.stack([a * np.sin(p) * np.cos(t), b * np.sin(p) * np.sin(t), c * np.cos(p)], -1).reshape(-1, 3)
    faces = _grid_faces(len(polar), segments)[:, ::-1]
    parts_v, parts_f = [vertices], [faces]
    count = len(vertices)
    for row, z, outward in ((0, zmax, True), (len(polar) - 1, zmin, False)):
        if abs(abs(z) - c) > 1e-9 * c:  # a cut, not a pole: close it
            ring = vertices[row * segments : (row + 1) * segments]
            v, f = _cap(ring, np.array([0.0, 0.0, z]), count, outward)
            parts_v.append(v)
            parts_f.append(f)
            count += len(v)
    return np.vstack(parts_v) + np.asarray(centre, float), np.vstack(parts_f)


def cone_mesh(start, end, *, radius_start, radius_end, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a truncated cone (a cylinder when the radii are equal), closed at both ends."""
    frame = axis_frame(start, end)
    length = float(np.linalg.norm(np.asarray(end, float) - np.asarray(start, float)))
    t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    rings = [
        np.stack([r * np.cos(t), r * np.sin(t), np.full(segments, z)], -1)
        for r, z in ((radius_start, 0.0), (radius_end, length))
    ]
    vertices = np.vstack(rings)
    faces = _grid_faces(2, segments)
    bottom_v, bottom_f = _cap(rings[0], np.zeros(3), len(vertices), False)
    top_v, top_f = _cap(rings[1], np.array([0.0, 0.0, length]), len(vertices) + len(bottom_v), True)
    local = np.vstack([vertices, bottom_v, top_v])
    return local @ frame[0:3, 0:3].T + frame[0:3, 3], np.vstack([faces, bottom_f, top_f])


def quadric_mesh(shape: str, params: dict, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """The mesh of one ``[[component.quadric]]`` table (formats.md) in its component's frame."""
    if shape in ("sphere", "ellipsoid"):
        radii = [params["radius"]] * 3 if shape == "sphere" else params["radii"]
        return ellipsoid_mesh(params.get("center", (0.0, 0.0, 0.0)), radii, clip=params.get("clip"), segments=segments)
    radii = (params["radius"], params["radius"]) if shape == "cylinder" else params["radii"]
    return cone_mesh(params["from"], params["to"], radius_start=radii[0], radius_end=radii[1], segments=segments)


def component_meshes(model: Model, segments: int = 24) -> list[tuple[np.ndarray, np.ndarray]]:
    """One (vertices float32 (V,3), faces uint32 (F,3)) per component, in the component's frame."""
    out = []
    for i in range(model.size):
        vertices, faces, count = [], [], 0
        for j in np.flatnonzero(model.quadric_component == i):
            v, f = quadric_mesh(model.quadric_shape[j], model.quadric_params[j], segments)
            vertices.append(v)
            faces.append(f + count)
            count += len(v)
        if vertices:
            out.append((np.vstack(vertices).astype(np.float32), np.vstack(faces).astype(np.uint32)))
        else:
            out.append((np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)))
    return out
