"""BVH export of the body model's skeleton and motion, for Blender and other animation tools.

Format facts (as read by :mod:`tracker.io.bvh_clip` and Blender's importer):

* World: y up, the body faces +z at rest, x is the body's left (the usual BVH
  world).  The tracker's world is z up, so every position ``p`` is written as
  ``C p`` with ``C`` = :data:`Z_UP_TO_Y_UP`, (x, y, z) -> (x, z, -y); the model's
  front (-y) becomes +z.
* Units: metres, so Blender's importer at its default scale 1 gives true size.
* Hierarchy: the model's tree, depth first, children in model order.  ``ROOT``
  is the root component with 6 channels ``Xposition Yposition Zposition
  Zrotation Xrotation Yrotation``; every other component is a ``JOINT`` with the
  3 channels ``Zrotation Xrotation Yrotation`` (a slide joint also gets the 3
  position channels first).  A component without children ends in an ``End
  Site`` at the point opposite its joint through the centre of its farthest
  quadric (twice that centre), which gives the leaf bone a length.
* Joint frames: a joint's local transform is ``T(OFFSET + position channels)
  Rz Rx Ry`` (angles in degrees, intrinsic: the rotation matrix is the product in
  channel order).  With all channels zero the skeleton stands in the model's
  rest pose, with the root component's axes along the (converted) world axes;
  so each joint's frame is its component's frame turned back by the
  component's rest orientation relative to the root, ``A`` (the product of the
  rest rotations from the root down), and ``OFFSET`` is the joint's rest
  position in its parent's frame, ``C A_parent at``.
* MOTION rows: the rotation channels are the component's rotation relative to
  ``parent * rest`` (the joint's own motion), expressed in those rest-aligned
  frames; Euler angles are unwrapped over time (no 360-degree jumps).  The root
  position is the root component's origin.  A lost frame (status 2 or NaN poses)
  repeats the pose of the last frame that was not lost (the first such frame
  for leading lost frames).
"""

from __future__ import annotations

import os

import numpy as np

from tracker.atomic import atomic_write
from tracker.chain import JOINT_TYPES
from tracker.model import Model, rest_poses
from tracker.status import LOST

Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
ROTATION_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")


def euler_zxy(rotation: np.ndarray) -> np.ndarray:
    """Angles (..., 3) in degrees, columns (z, x, y), with ``rotation`` (..., 3, 3) = Rz(z) Rx(x) Ry(y).

    Solved one angle at a time (z, then x and y from Rz(z)^T R), so the angles
    reproduce the rotation to rounding error also at and near gimbal lock
    (x = +-90 degrees), where z is arbitrary and y takes up the rest.
    """
    r = rotation
    z = np.arctan2(-r[..., 0, 1], r[..., 1, 1])
    cz, sz = np.cos(z), np.sin(z)
    # rows 0 and 1 of Rz(z)^T R = Rx(x) Ry(y) = [[cy, 0, sy], [sx sy, cx, -sx cy], [-cx sy, sx, cx cy]]
    row0 = cz[..., None] * r[..., 0, :] + sz[..., None] * r[..., 1, :]
    x = np.arctan2(r[..., 2, 1], -sz * r[..., 0, 1] + cz * r[..., 1, 1])
    y = np.arctan2(row0[..., 2], row0[..., 0])
    return np.degrees(np.stack([z, x, y], axis=-1))


def usable(poses: np.ndarray, status: np.ndarray) -> np.ndarray:
    """(F,) bool: frames that are not lost (status 2) and whose poses (F, N, 4, 4) are all finite."""
    return (status != LOST) & np.isfinite(poses).all(axis=(1, 2, 3))


def hold_lost(poses: np.ndarray, status: np.ndarray) -> np.ndarray:
    """Poses (F, N, 4, 4) with every frame that is not :func:`usable` replaced by the last usable one.

    Leading unusable frames take the first usable frame; ValueError if there is none.
    """
    good = usable(poses, status)
    if not good.any():
        raise ValueError("no frame has a pose")
    source = np.maximum.accumulate(np.where(good, np.arange(len(poses)), -1))
    source[source < 0] = np.flatnonzero(good)[0]
    return poses[source]


def bvh_joint_frames(poses: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """(F, N, 4, 4) BVH-world-from-joint transforms: rotation C R_i A_i^T C^T, origin C t_i (metres).

    ``rest`` (N, 4, 4) is the model's rest pose with the root at the identity, ``rest_poses(model, np.eye(4))``,
    whose rotations are the rest orientations ``A_i``.
    """
    out = np.zeros(poses.shape)
    out[..., 3, 3] = 1.0
    out[..., :3, :3] = Z_UP_TO_Y_UP @ poses[..., :3, :3] @ np.swapaxes(rest[:, :3, :3], -1, -2) @ Z_UP_TO_Y_UP.T
    out[..., :3, 3] = poses[..., :3, 3] @ Z_UP_TO_Y_UP.T
    return out


def offsets(model: Model, rest: np.ndarray) -> np.ndarray:
    """(N, 3) BVH OFFSETs in metres: C A_parent at_i, the rest origin relative to the parent's; the root's is zero.

    ``rest`` is ``rest_poses(model, np.eye(4))`` (see :func:`bvh_joint_frames`).
    """
    out = np.zeros((model.size, 3))
    out[1:] = (rest[1:, :3, 3] - rest[model.parent[1:], :3, 3]) @ Z_UP_TO_Y_UP.T
    return out


def end_sites(model: Model, rest: np.ndarray) -> np.ndarray:
    """(N, 3) End Site OFFSETs in metres: C A_i (2 c), c the component's quadric centre farthest from its
    joint (zero without quadrics); ``rest`` as in :func:`bvh_joint_frames`."""
    out = np.zeros((model.size, 3))
    for i in range(model.size):
        centres = model.quadric_bound[model.quadric_component == i, :3]
        if len(centres):
            far = centres[np.argmax(np.linalg.norm(centres, axis=1))]
            out[i] = Z_UP_TO_Y_UP @ rest[i, :3, :3] @ (2.0 * far)
    return out


def has_position(model: Model) -> np.ndarray:
    """(N,) bool: components with position channels, the root and slide joints."""
    out = model.joint_type == JOINT_TYPES["slide"]
    out[0] = True
    return out


def motion(model: Model, poses: np.ndarray, rest: np.ndarray | None = None) -> np.ndarray:
    """(F, N, 6) channel values per component: position (metres) then Z, X, Y rotation (degrees).

    ``poses`` (F, N, 4, 4) world-from-component, every frame finite; ``rest`` as in
    :func:`bvh_joint_frames` (computed when not given).
    """
    rest = rest_poses(model, np.eye(4)) if rest is None else rest
    frames = bvh_joint_frames(poses, rest)
    local = frames.copy()
    parent = model.parent[1:]
    local[:, 1:] = np.linalg.inv(frames[:, parent]) @ frames[:, 1:]
    out = np.empty(poses.shape[:2] + (6,))
    out[..., :3] = local[..., :3, 3] - offsets(model, rest)
    out[..., 3:] = np.unwrap(euler_zxy(local[..., :3, :3]), period=360.0, axis=0)
    return out


def depth_first(model: Model) -> list[int]:
    """Component indices in the order of the BVH hierarchy: depth first from the root, children in model order."""
    order, stack = [], [0]
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(np.flatnonzero(model.parent == i).tolist()))
    return order


def hierarchy_lines(model: Model, rest: np.ndarray) -> list[str]:
    """The HIERARCHY section of the BVH of ``model``; ``rest`` as in :func:`bvh_joint_frames`."""
    offset, end, positional = offsets(model, rest), end_sites(model, rest), has_position(model)

    def vector(values: np.ndarray) -> str:
        return " ".join(f"{v:.8f}" for v in values)

    def joint(i: int, depth: int) -> list[str]:
        pad = "\t" * depth
        channels = (POSITION_CHANNELS if positional[i] else ()) + ROTATION_CHANNELS
        lines = [
            f"{pad}{'ROOT' if i == 0 else 'JOINT'} {model.names[i]}",
            f"{pad}{{",
            f"{pad}\tOFFSET {vector(offset[i])}",
            f"{pad}\tCHANNELS {len(channels)} {' '.join(channels)}",
        ]
        children = np.flatnonzero(model.parent == i)
        for child in children:
            lines += joint(int(child), depth + 1)
        if not len(children):
            lines += [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {vector(end[i])}", f"{pad}\t}}"]
        return lines + [f"{pad}}}"]

    return ["HIERARCHY"] + joint(0, 0)


def bvh_lines(model: Model, poses: np.ndarray, status: np.ndarray, *, rate: float) -> list[str]:
    """The lines (without newlines) of the BVH of ``poses`` (F, N, 4, 4, model order) at ``rate`` frames per second."""
    rest = rest_poses(model, np.eye(4))
    values = motion(model, hold_lost(poses, status), rest)
    positional = has_position(model)
    columns = [values[:, i, 0 if positional[i] else 3 :] for i in depth_first(model)]
    table = np.concatenate(columns, axis=1)
    row_format = " ".join(["%.8f"] * table.shape[1])
    return (
        hierarchy_lines(model, rest)
        + ["MOTION", f"Frames: {len(table)}", f"Frame Time: {1.0 / rate:.10f}"]
        + [row_format % tuple(row) for row in table]
    )


def write_bvh(path: str | os.PathLike, model: Model, poses: np.ndarray, *, status: np.ndarray, rate: float) -> None:
    """Write the BVH file ``path`` (atomically) of ``poses`` (F, N, 4, 4) world-from-component in model order.

    At least one frame must be :func:`usable` and the component names single words (BVH splits on white space).
    """
    text = "\n".join(bvh_lines(model, poses, status, rate=rate)) + "\n"

    atomic_write(path, lambda file: file.write(text.encode()))
