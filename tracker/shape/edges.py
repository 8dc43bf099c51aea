"""The shape fitted to the image edges along the model's outlines (docs/fit-model.md, "From the edges").

An outline sample of quadric q on component c, at contour point X in c's frame, finds its edge at offset m along
its image normal (:mod:`tracker.tracking.measure`); the first three entries g of its Jacobian row are the change of its
offset per unit motion of X in c's frame (docs/method-tracking.md, section 3).  A change dx of the shape
(:class:`tracker.shape.layout.Layout`) moves X

    by S(X) da_c in c's frame, the quadric stretched: S = diag(X / a) on an ellipsoid; on a cone or cylinder of
        unit axis d, with P the axis point nearest X, diag(P / a) for the axis and (X - P) (1 - d^2)^T / (2 across)
        for the radius (``across`` its current mean factor across the axis); on a sphere of centre C,
        diag(C / a) + (X - C) 1^T / (3 mean(a));
    by sum over the joints i from c up to the root of R_p(i) d at_i in the world: the joints above c moved;
    by dt in the world: the root moved (each frame its own);

so its outline moves by ``g . S da_c + (R_c g) . (sum R_p(i) d at_i + dt)`` along the normal: a row, linear in dx
and dt, as the tracker's rows are in the twists.  With each frame's rotations held, the shape step minimises the
tracker's robust cost with the layout's prior over every sample of every frame:

    sum w (row dx + (R_c g) . dt_f - m)^2 + |P (x + dx)|^2,    w = 1 / (c + |m|)

(a region line of the same sample, :meth:`tracker.tracking.frame_loop.Tracker.inspect_cues`, gives a row of its own:
the same row, with the posterior mean of where the colours change as its m and the tracker's weight of it as its w),
solved as one set of normal equations (:func:`shape_step`); the poses are then fitted to the edges again with the
new shape (:mod:`tracker.shape.model_fit`), and so on in turn.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from tracker.geometry import se3
from tracker.model import Model
from tracker.seeding.pose_fit import Body
from tracker.shape.layout import Layout
from tracker.tracking.workspace import Inspection


def stretch_rows(model: Model, factors: np.ndarray, inspection: Inspection) -> np.ndarray:
    """Each sample's change of outline offset per unit change of its component's three factors (S, 3):
    ``g^T S(X)`` (module docstring), ``factors`` (N, 3) the current model's."""
    count = len(inspection.component)
    gradient = inspection.jacobian[:, :3]
    point = inspection.point
    factor = factors[inspection.component]
    out = np.zeros((count, 3))
    shapes = np.array(model.quadric_shape)[inspection.quadric]
    ellipsoid = shapes == "ellipsoid"
    out[ellipsoid] = gradient[ellipsoid] * point[ellipsoid] / factor[ellipsoid]
    for q in np.unique(inspection.quadric[~ellipsoid]):
        mine = inspection.quadric == q
        params = model.quadric_params[q]
        a = factor[mine]
        if model.quadric_shape[q] == "sphere":
            centre = np.asarray(params.get("center", [0.0, 0.0, 0.0]), np.float64)
            radial = np.einsum("sk,sk->s", gradient[mine], point[mine] - centre)
            out[mine] = gradient[mine] * centre / a + (radial / (3.0 * a.mean(axis=1)))[:, None]
            continue
        start, end = np.asarray(params["from"], np.float64), np.asarray(params["to"], np.float64)
        axis = (end - start) / np.linalg.norm(end - start)
        across_weights = (1.0 - axis**2) / 2.0
        on_axis = start + np.outer((point[mine] - start) @ axis, axis)
        radial = np.einsum("sk,sk->s", gradient[mine], point[mine] - on_axis)
        out[mine] = gradient[mine] * on_axis / a + np.outer(radial / (a @ across_weights), across_weights)
    return out


def chain_maps(layout: Layout, model: Model, poses: np.ndarray) -> np.ndarray:
    """The world motion of each component's origin per unit change of x (N, 3, width), at world-from-component
    ``poses`` (N, 4, 4) held: the sum over the joints from it up to the root of R_parent joint_map."""
    out = np.zeros((model.size, 3, layout.width))
    for i in range(1, model.size):
        p = int(model.parent[i])
        out[i] = out[p] + poses[p, :3, :3] @ layout.joint_map(i)
    return out


@dataclass(frozen=True)
class FrameRows:
    """One frame's rows, for the samples that found an edge: ``shape`` (S, width) per unit change of x, ``pose``
    (S, P) per unit of each joint's motion (:func:`joint_twists`), the measured ``offset`` (S,), the IRLS
    ``weight`` (S,) and each sample's ``component`` (S,) and ``camera`` (S,)."""

    shape: np.ndarray
    pose: np.ndarray
    offset: np.ndarray
    weight: np.ndarray
    component: np.ndarray
    camera: np.ndarray

    def without(self, drop: np.ndarray) -> FrameRows:
        """These rows less the samples of the components ``drop`` (bool (N,), True to drop) or, given per camera
        (C, N), of those components in those cameras."""
        hidden = drop[self.component] if drop.ndim == 1 else drop[self.camera, self.component]
        return FrameRows(*(getattr(self, field.name)[~hidden] for field in dataclasses.fields(self)))

    def joined(self, other: FrameRows) -> FrameRows:
        """These rows and ``other``'s (of the same frame, e.g. another cue's) together."""
        return FrameRows(
            *(np.concatenate([getattr(self, f.name), getattr(other, f.name)]) for f in dataclasses.fields(self))
        )


def joint_twists(model: Model, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each joint motion's world twist (P, 6), (omega, v) (a world point p of a component it moves goes at
    omega x p + v per unit; :meth:`tracker.seeding.pose_fit.Body.twists` at rest from ``poses``), and which components
    each one moves (P, N) bool: its own and every one below it."""
    body = Body.of(model)
    twists = body.twists(np.zeros(body.offsets[-1]), poses)
    owner = np.searchsorted(body.offsets, np.arange(body.offsets[-1]), side="right") - 1
    below = np.eye(model.size, dtype=bool)
    for i in range(1, model.size):
        below[:, i] |= below[:, model.parent[i]]
    return twists, below[owner]


def frame_rows(
    layout: Layout, model: Model, *, factors: np.ndarray, poses: np.ndarray, inspection: Inspection
) -> FrameRows:
    """The rows (module docstring) of the samples in ``inspection`` that found an edge (or whose line the region cue
    read, :meth:`tracker.tracking.frame_loop.Tracker.inspect_cues`), the model at ``poses``
    (N, 4, 4) with stretch ``factors`` (N, 3)."""
    found = np.isfinite(inspection.offset) & (inspection.weight > 0)
    seen = Inspection(
        **{field.name: getattr(inspection, field.name)[found] for field in dataclasses.fields(inspection)}
    )
    rotation = poses[seen.component, :3, :3]
    world = np.einsum("sij,sj->si", rotation, seen.jacobian[:, :3])
    rows = np.einsum("si,sij->sj", world, chain_maps(layout, model, poses)[seen.component])
    stretch = stretch_rows(model, factors, seen)
    columns = layout.factor[seen.component][:, None] + np.arange(3)
    np.add.at(rows, (np.arange(len(rows))[:, None], columns), stretch)
    twists, moves = joint_twists(model, poses)
    point = np.einsum("sij,sj->si", rotation, seen.point) + poses[seen.component, :3, 3]
    velocity = se3.cross(twists[None, :, 0:3], point[:, None, :]) + twists[None, :, 3:6]
    pose = np.einsum("si,spi->sp", world, velocity) * moves[:, seen.component].T
    return FrameRows(rows, pose, seen.offset, seen.weight, seen.component, seen.camera)


POSE_DAMPING = 1.0
"""Added to the diagonal of each frame's pose block (pixels^2 per unit^2): holds a part that no sample sees."""


def bundle_step(
    frames: list[FrameRows], prior: np.ndarray, x: np.ndarray, *, damping: float = 0.0
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The shape x + dx and each frame's joint motions dp (P,) that minimise the robust cost of the ``frames``'
    rows with the ``prior`` rows (R, width) (module docstring): one Gauss-Newton step of shape and poses together,
    each frame's pose block eliminated (a Schur complement per frame) and recovered after.  ``damping`` lambda
    makes it a Levenberg-Marquardt step: every diagonal entry of the normal equations grows by lambda times
    itself, so the step shortens and turns towards steepest descent."""
    normal = prior.T @ prior
    right = -normal @ x
    blocks = []
    for rows in frames:
        w = rows.weight
        a, b = rows.shape, rows.pose
        ab = (a * w[:, None]).T @ b
        bb = (b * w[:, None]).T @ b
        bb += np.diag(damping * np.diag(bb) + POSE_DAMPING)
        bm = b.T @ (w * rows.offset)
        eliminate = np.linalg.solve(bb, ab.T).T
        normal += (a * w[:, None]).T @ a - eliminate @ ab.T
        right += a.T @ (w * rows.offset) - eliminate @ bm
        blocks.append((bb, ab, bm))
    dx = np.linalg.solve(normal + np.diag(damping * np.diag(normal) + 1e-12), right)
    return x + dx, [np.linalg.solve(bb, bm - ab.T @ dx) for bb, ab, bm in blocks]


def moved(model: Model, poses: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """``poses`` (N, 4, 4) after the joint motions ``motion`` (P,) (:func:`joint_twists`; to first order each
    component turns and moves by the sum of the twists above it), coerced onto ``model``'s joints."""
    twists, moves = joint_twists(model, poses)
    total = (motion[:, None] * twists).T @ moves  # (6, N)
    out = np.empty_like(poses)
    for i in range(model.size):
        omega, v = total[0:3, i], total[3:6, i]
        step = se3.from_rotation(se3.exp_so3(omega), v)
        out[i] = step @ poses[i]
    return model.coerce(out)
