"""Which parts the images hold in a frame, and which only the prior and the joints carry (docs/method-tracking.md,
section 6, "Which parts the images hold").

Each cue's readings of a frame give each component ``i`` an information ``E_i`` (6 x 6) about its body twist
``alpha = (v, w)`` (:meth:`tracker.tracking.cue.Cue.evidence`): the edges' and colour lines' ``sum w L^T L``, the
landmarks' ``sum w J^T J`` of every landmark seen with confidence.  A twist moves the part's surface along its
normal by ``a(X)^T alpha`` at a surface point ``X`` with outward normal ``n``, ``a = (n, X x n)``, so

    M_i = mean over the part's surface of a a^T      (area-weighted, clipped quadrics, component frame)

gives the mean squared normal motion of the surface, ``alpha^T M_i alpha`` (m^2), and its null space holds the
motions no image can see (a cone turned about its axis).  The images hold the part in its least-seen direction by

    lambda_i = min over alpha in range(M_i) of  alpha^T E_i alpha / alpha^T M_i alpha,

their information per m^2 of that surface motion: ``1 / sqrt(lambda_i)`` is how far (m, root mean square over the
surface) the part can move in that direction for the cost of one well-fitting sample.  A part is :data:`HELD`
(:mod:`tracker.status`) when that distance is at most ``held_within``, :data:`UNSEEN` when no cue reads anything of
it (``E_i`` = 0: hidden from every view, no edge found, no landmark), and :data:`LOOSE` between: the images see it
but the prior and the joints carry it in some direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker.model import Model
from tracker.status import HELD, LOOSE, UNSEEN
from tracker.tracking.rig import Rig

RAYS = 2000
"""Rays cast from each quadric's centre to sample its surface (:func:`surface_motion`)."""

SEEN = 1e-9
"""The share of a part's surface motion below which a direction is one no image sees (the range of M_i)."""


def _fibonacci(count: int) -> np.ndarray:
    """``count`` unit vectors (count, 3) spread evenly over the sphere."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    r = np.sqrt(1.0 - z * z)
    turn = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.column_stack([r * np.cos(turn), r * np.sin(turn), z])


def surface_points(surface: np.ndarray, clip: np.ndarray, centre: np.ndarray, rays: int = RAYS):
    """Points (P, 3) of the clipped quadric ``surface`` (4 x 4, kept where ``clip`` <= 0), their outward unit normals
    (P, 3) and area weights (P,), from rays cast out of ``centre`` (3,) inside it: a ray along ``d`` that meets the
    surface at ``t`` stands for ``t^2 / |n . d|`` of its area per steradian."""
    d = _fibonacci(rays)
    c = np.append(centre, 1.0)
    qa = np.einsum("ri,ij,rj->r", d, surface[:3, :3], d)
    qb = 2.0 * d @ (surface[:3, :] @ c)
    qc = c @ surface @ c
    disc = qb * qb - 4.0 * qa * qc
    ok = (disc >= 0.0) & (np.abs(qa) > 1e-12)
    root = np.sqrt(np.where(ok, disc, 0.0))
    a = np.where(ok, qa, 1.0)
    t = np.maximum((-qb + root) / (2.0 * a), (-qb - root) / (2.0 * a))  # the far root: centre inside, so one > 0
    points = centre + t[:, None] * d
    h = np.hstack([points, np.ones((rays, 1))])
    inside = np.einsum("ri,ij,rj->r", h, clip, h) <= 1e-12
    keep = ok & (t > 0.0) & inside
    gradient = (h @ surface)[:, :3]
    normal = gradient / np.linalg.norm(gradient, axis=1, keepdims=True).clip(1e-300)
    slant = np.abs(np.einsum("ri,ri->r", normal, d))
    weight = np.where(keep, t * t / np.maximum(slant, 1e-3), 0.0)
    return points[keep], normal[keep], weight[keep]


@dataclass(frozen=True)
class Surfaces:
    """What a model's parts show the images: per component a basis (6, k) of the twists that move its surface, scaled
    so that M_i is the identity on them (``directions``; :func:`surface_motion`), and its surface's area-weighted
    centre (N, 3) in its frame (``centre``)."""

    directions: tuple[np.ndarray, ...]
    centre: np.ndarray

    @classmethod
    def of(cls, model: Model, rays: int = RAYS) -> Surfaces:
        motion, centre = surface_motion(model, rays)
        return cls(tuple(seen_directions(motion)), centre)


def surface_motion(model: Model, rays: int = RAYS) -> tuple[np.ndarray, np.ndarray]:
    """M_i (N, 6, 6), the mean over each component's clipped quadrics' surface of a a^T, a = (n, X x n) (module
    docstring), and the surface's centre (N, 3), both in its frame."""
    motion = np.zeros((model.size, 6, 6))
    centre = np.zeros((model.size, 3))
    area = np.zeros(model.size)
    for j, i in enumerate(model.quadric_component):
        points, normal, weight = surface_points(model.quadric[j], model.clip[j], model.quadric_bound[j, :3], rays)
        a = np.hstack([normal, np.cross(points, normal)])
        motion[i] += np.einsum("p,pi,pj->ij", weight, a, a)
        centre[i] += weight @ points
        area[i] += weight.sum()
    area = np.maximum(area, 1e-300)
    return motion / area[:, None, None], centre / area[:, None]


def seen_directions(motion: np.ndarray) -> list[np.ndarray]:
    """Per component a basis (6, k) of the range of its M_i (``motion`` (N, 6, 6)), scaled so that M_i is the
    identity on it (the directions of unit mean squared surface motion)."""
    out = []
    for m in motion:
        values, vectors = np.linalg.eigh(m)
        kept = values > SEEN * max(values[-1], 1e-300)
        out.append(vectors[:, kept] / np.sqrt(values[kept]))
    return out


def firmness(evidence: np.ndarray, directions) -> np.ndarray:
    """lambda_i (N,): the least information ``evidence`` (N, 6, 6) gives per m^2 of mean squared surface motion, over
    each component's ``directions`` (:func:`seen_directions`); 0 where it gives none."""
    out = np.zeros(len(evidence))
    for i, (e, basis) in enumerate(zip(evidence, directions)):
        if basis.shape[1] and e.any():
            out[i] = max(float(np.linalg.eigvalsh(basis.T @ e @ basis)[0]), 0.0)
    return out


def pixels_per_metre(points: np.ndarray, rig: Rig) -> np.ndarray:
    """How many pixels a metre at each world point (N, 3) spans in the views (N,): the root mean square of f / Z over
    the cameras of ``rig`` in whose image it lies (pinhole, focal length f the mean of fx and fy), else over those it
    lies in front of; 0 for a point behind every camera."""
    camera = np.einsum("cij,nj->cni", rig.camera_from_world[:, :3, :3], points) + rig.camera_from_world[:, None, :3, 3]
    depth = camera[..., 2]
    front = depth > 1e-6
    focal = 0.5 * (rig.matrix[:, 0, 0] + rig.matrix[:, 1, 1])
    z = np.where(front, depth, 1.0)
    u = rig.matrix[:, None, 0, 0] * camera[..., 0] / z + rig.matrix[:, None, 0, 2]
    v = rig.matrix[:, None, 1, 1] * camera[..., 1] / z + rig.matrix[:, None, 1, 2]
    width, height = rig.size[:, None, 0], rig.size[:, None, 1]
    inside = front & (u >= 0) & (u <= width) & (v >= 0) & (v <= height)
    counted = np.where(inside.any(axis=0)[None], inside, front)
    squared = np.where(counted, (focal[:, None] / z) ** 2, 0.0)
    return np.sqrt(squared.sum(axis=0) / np.maximum(counted.sum(axis=0), 1))


def held_codes(
    evidence: np.ndarray, surfaces: Surfaces, *, poses: np.ndarray, rig: Rig, within: float, seen: np.ndarray
) -> np.ndarray:
    """Each component's code (N,) int8: :data:`HELD` where the images place its outline within ``within`` pixels in
    its least-seen direction (lambda_i >= (scale_i / within)^2, scale_i the views' pixels per metre at its centre,
    :func:`pixels_per_metre`), :data:`UNSEEN` where ``evidence`` (N, 6, 6) is nothing, :data:`LOOSE` otherwise
    (module docstring); the components at ``poses`` (N, 4, 4) in ``rig``."""
    centre = np.einsum("nij,nj->ni", poses[:, :3, :3], surfaces.centre) + poses[:, :3, 3]
    scale = pixels_per_metre(centre, rig)
    lam = firmness(evidence, surfaces.directions)
    codes = np.where((lam * within * within >= scale * scale) & (scale > 0), HELD, LOOSE).astype(np.int8)
    codes[~seen & ~evidence.any(axis=(1, 2))] = UNSEEN
    return codes
