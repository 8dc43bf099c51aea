"""Rendering recordings with ground truth, for tests, demos and benchmarks.

Independent of the tracker's outline code: bodies are drawn by casting one ray
per pixel against every clipped quadric (no conics), so a disagreement between
this renderer and ``outline.py`` points at a bug in one of them.

Pipeline of :func:`synthesize`::

    motion (BVH clip | procedural)  -> model poses (F, N, 4, 4), exact joints (Model.coerce)
    per camera: pixel rays          -> exact lens distortion (undistorted pixel centres)
    per frame and camera:           render_kernel -> component id + shade per pixel
                                    -> colour, soft edges (Gaussian), over a background photo, sensor noise
    writers                         -> <cam>.avi (MJPG), calibration.toml, model.toml, init.toml, truth.npz

BVH conventions (the CMU clips in ``shared/data/cmu-mocap``): a joint's local
transform is ``T(offset + position) R`` with ``R`` the product of its rotation
channels in the listed order (intrinsic, degrees), e.g. ``Zrotation Yrotation
Xrotation`` gives ``Rz Ry Rx``; the world is Y up and the character faces +Z
at rest; a joint's rotation orients the bone towards its child's OFFSET.
"""

from __future__ import annotations

import os
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import tomli_w
from numba import njit, prange

from tracker.camera import Camera, load_calibration, save_calibration
from tracker.chain import HINGE
from tracker.errors import TrackerInputError
from tracker.io.atomic import atomic_write, ensure_writable_folder
from tracker.model import Model, joint_centres, load_model, poses_from_rotations, rest_poses
from tracker.geometry import se3

CMU_UNIT = 0.0564
"""Metres per CMU BVH unit ((1/0.45) inch, http://mocap.cs.cmu.edu/faqs.php)."""

BACKGROUNDS = Path(__file__).resolve().parents[2] / "shared" / "data" / "backgrounds"
"""Folder of background photos (OpenCV samples); used when present, else a procedural backdrop."""

DEFAULT_BACKGROUNDS = ("basketball1.png", "basketball2.png")
"""The room photos used by default (``board.jpg`` is a circuit-board texture, not a room, and
its fine detail makes Motion-JPEG videos about three times larger; pass it explicitly if wanted)."""

# ---------------------------------------------------------------------------------------------
# BVH


@dataclass
class Bvh:
    """A parsed BVH file.

    ``names`` (J,), ``parents`` (J,) int (-1 for the root), ``offsets`` (J, 3)
    in file units, ``channels`` per joint (tuple of channel names such as
    ``"Zrotation"``), ``channel_start`` (J,) int: column of the joint's first
    channel in ``motion`` (F, C), ``frame_time`` in seconds.  End sites are not
    joints.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    channel_start: np.ndarray
    motion: np.ndarray
    frame_time: float

    @property
    def frames(self) -> int:
        return int(self.motion.shape[0])

    def index(self, name: str) -> int:
        return self.names.index(name)


_CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


def load_bvh(path: str | os.PathLike) -> Bvh:
    """Parse a BVH file (HIERARCHY and MOTION sections); TrackerInputError when it is missing or malformed."""
    path = Path(path)
    try:
        text = path.read_text(errors="strict")
    except FileNotFoundError:
        raise TrackerInputError(f"{path}: BVH file not found; give the path of an existing .bvh motion file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrackerInputError(f"{path}: cannot read the BVH file ({exc}); give a readable text .bvh file") from None
    try:
        return _parse_bvh(text)
    except (ValueError, IndexError) as exc:
        raise TrackerInputError(f"{path}: not a valid BVH file ({exc}); give a BVH file with HIERARCHY and MOTION") from None


def _parse_bvh(text: str) -> Bvh:
    head, sep, tail = text.partition("MOTION")
    if not sep:
        raise ValueError("no MOTION section")
    tokens = head.split()
    if not tokens or tokens[0] != "HIERARCHY":
        raise ValueError("no HIERARCHY section")
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    stack: list[int] = []  # joint index per open brace; -2 marks an end site
    pending: int | None = None  # joint whose opening brace is next
    i = 1
    while i < len(tokens):
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            if tok == "ROOT" and names:
                raise ValueError("more than one ROOT")
            parent = -1 if tok == "ROOT" else _open_joint(stack)
            names.append(tokens[i + 1])
            parents.append(parent)
            offsets.append([0.0, 0.0, 0.0])
            channels.append(())
            pending = len(names) - 1
            i += 2
        elif tok == "End":
            pending = -2
            i += 2
        elif tok == "{":
            if pending is None:
                raise ValueError("unexpected '{'")
            stack.append(pending)
            pending = None
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            values = [float(v) for v in tokens[i + 1 : i + 4]]
            if stack[-1] >= 0:
                offsets[stack[-1]] = values
            i += 4
        elif tok == "CHANNELS":
            count = int(tokens[i + 1])
            chans = tuple(tokens[i + 2 : i + 2 + count])
            if any(c not in _CHANNELS for c in chans):
                raise ValueError(f"unknown channel in {chans}")
            channels[stack[-1]] = chans
            i += 2 + count
        else:
            raise ValueError(f"unexpected token {tok!r} in HIERARCHY")
    if not names or stack:
        raise ValueError("empty or unbalanced HIERARCHY")
    lines = tail.strip().splitlines()
    frames = int(lines[0].split(":")[1])
    frame_time = float(lines[1].split(":")[1])
    n_channels = sum(len(c) for c in channels)
    rows = [line.split() for line in lines[2:] if line.strip()]
    motion = np.array(rows, dtype=np.float64)
    if motion.shape != (frames, n_channels):
        raise ValueError(f"MOTION holds {motion.shape} numbers, expected {frames} frames x {n_channels} channels")
    start = np.cumsum([0] + [len(c) for c in channels])[:-1]
    return Bvh(
        names=tuple(names),
        parents=np.asarray(parents, dtype=np.int64),
        offsets=np.asarray(offsets, dtype=np.float64),
        channels=tuple(channels),
        channel_start=np.asarray(start, dtype=np.int64),
        motion=motion,
        frame_time=frame_time,
    )


def _open_joint(stack: list[int]) -> int:
    if not stack or stack[-1] < 0:
        raise ValueError("JOINT outside a joint")
    return stack[-1]


def _axis_rotations(axis: int, degrees: np.ndarray) -> np.ndarray:
    """(F, 3, 3) right-handed rotations about coordinate axis 0/1/2 by angles in degrees."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    j, k = (axis + 1) % 3, (axis + 2) % 3
    out[..., axis, axis] = 1.0
    out[..., j, j] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    out[..., k, k] = c
    return out


def bvh_local(bvh: Bvh, frames: np.ndarray | None = None) -> np.ndarray:
    """Local (parent-from-joint) transforms (F, J, 4, 4): T(offset + position) * R(channels in order)."""
    motion = bvh.motion if frames is None else bvh.motion[frames]
    n_frames, n_joints = motion.shape[0], len(bvh.names)
    local = np.zeros((n_frames, n_joints, 4, 4))
    local[:, :, 3, 3] = 1.0
    for j in range(n_joints):
        rot = np.broadcast_to(np.eye(3), (n_frames, 3, 3)).copy()
        pos = np.broadcast_to(bvh.offsets[j], (n_frames, 3)).copy()
        for k, chan in enumerate(bvh.channels[j]):
            column = motion[:, bvh.channel_start[j] + k]
            axis = "XYZ".index(chan[0])
            if chan.endswith("position"):
                pos[:, axis] += column
            else:
                rot = rot @ _axis_rotations(axis, column)
        local[:, j, 0:3, 0:3] = rot
        local[:, j, 0:3, 3] = pos
    return local


def bvh_global(bvh: Bvh, frames: np.ndarray | None = None) -> np.ndarray:
    """Forward kinematics: world-from-joint transforms (F, J, 4, 4) in BVH world units (Y up).

    ``frames`` optionally selects motion rows (an index array); default all.
    """
    local = bvh_local(bvh, frames)
    out = np.empty_like(local)
    for j, p in enumerate(bvh.parents):
        out[:, j] = local[:, j] if p < 0 else out[:, p] @ local[:, j]
    return out


# ---------------------------------------------------------------------------------------------
# Retargeting a BVH clip onto a body model

BVH_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""C: BVH world (Y up, facing +Z at rest) -> our world (z up, the model faces -y at rest).

Column j is BVH axis j in our world: X -> x (the body's left), Y -> z (up), Z -> -y (forward).
The model-to-BVH axis map M used by the alignments is its transpose."""

_FOOT_SLOPE = np.radians(10.4)  # the CMU ankle -> toe bone descends about 10 degrees at rest

RETARGET_MAP = {
    # component: (BVH joint whose world rotation drives it, BVH joint the bone points to or None,
    #             the bone direction in the component's frame)
    "pelvis": ("Hips", None, None),
    "torso": ("Chest2", "Neck", (0.0, 0.0, 1.0)),
    "head": ("Head", None, None),
    "upperarm_l": ("LeftShoulder", "LeftElbow", (0.0, 0.0, -1.0)),
    "forearm_l": ("LeftElbow", "LeftWrist", (0.0, 0.0, -1.0)),
    "hand_l": ("LeftWrist", "LFingers", (0.0, 0.0, -1.0)),
    "upperarm_r": ("RightShoulder", "RightElbow", (0.0, 0.0, -1.0)),
    "forearm_r": ("RightElbow", "RightWrist", (0.0, 0.0, -1.0)),
    "hand_r": ("RightWrist", "RFingers", (0.0, 0.0, -1.0)),
    "thigh_l": ("LeftHip", "LeftKnee", (0.0, 0.0, -1.0)),
    "shin_l": ("LeftKnee", "LeftAnkle", (0.0, 0.0, -1.0)),
    "foot_l": ("LeftAnkle", "LeftToe", (0.0, -np.cos(_FOOT_SLOPE), -np.sin(_FOOT_SLOPE))),
    "thigh_r": ("RightHip", "RightKnee", (0.0, 0.0, -1.0)),
    "shin_r": ("RightKnee", "RightAnkle", (0.0, 0.0, -1.0)),
    "foot_r": ("RightAnkle", "RightToe", (0.0, -np.cos(_FOOT_SLOPE), -np.sin(_FOOT_SLOPE))),
}
"""Model component -> BVH joint; the hip joints' midpoint places the root."""


def minimal_rotation(a, b) -> np.ndarray:
    """The smallest rotation taking direction ``a`` to direction ``b`` (3x3)."""
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    b = np.asarray(b, dtype=np.float64) / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        other = np.eye(3)[np.argmin(np.abs(a))]
        axis = np.cross(a, other)
        return se3.exp_so3(np.pi * axis / np.linalg.norm(axis))
    return se3.exp_so3(axis / s * np.arctan2(s, c))


def _rest_positions(bvh: Bvh) -> np.ndarray:
    """Joint positions (J, 3) at the BVH rest pose (all channels zero), BVH units."""
    out = np.zeros((len(bvh.names), 3))
    for j, p in enumerate(bvh.parents):
        out[j] = bvh.offsets[j] + (out[p] if p >= 0 else 0.0)
    return out


def _bvh_joint(bvh: Bvh, name: str, path: object) -> int:
    try:
        return bvh.index(name)
    except ValueError:
        raise TrackerInputError(
            f"{path}: the BVH has no joint {name!r} needed for the model; use a CMU-style skeleton "
            f"(joints {', '.join(sorted({j for j, _, _ in RETARGET_MAP.values()}))})"
        ) from None


def alignments(bvh: Bvh, model: Model, path: object = "<bvh>") -> tuple[np.ndarray, np.ndarray]:
    """Per component the driving BVH joint (N,) and the constant alignment A_i (N, 3, 3).

    A_i maps the component's frame into the BVH joint's frame: the axes map
    M = C^T (x -> X, y -> -Z, z -> Y) followed by the minimal rotation taking the
    model's rest bone direction onto the BVH's rest bone direction, so that
    R_i = C R_bvh(joint) A_i reproduces the model's rest pose at the BVH rest pose
    up to the bones' rest directions.  For a hinge child (knee, elbow) the child's
    and the parent's A get one extra twist about the child's bone, chosen so that
    the BVH's flexion axis (principal axis of the joint's relative rotation over
    the whole clip) lands on the model's hinge axis; twists about a bone do not
    move it, and coercion then removes next to nothing (the CMU elbows flex about
    an axis 30 degrees off X; without the twist coercion would bend the forearms
    by up to 70 degrees).
    """
    rest = _rest_positions(bvh)
    axes = BVH_TO_WORLD.T
    joints = np.zeros(model.size, dtype=np.int64)
    align = np.zeros((model.size, 3, 3))
    for i, name in enumerate(model.names):
        if name not in RETARGET_MAP:
            raise TrackerInputError(
                f"{path}: the model component {name!r} has no BVH joint to follow; "
                f"retargeting knows {', '.join(RETARGET_MAP)}"
            )
        joint, tip, direction = RETARGET_MAP[name]
        joints[i] = _bvh_joint(bvh, joint, path)
        align[i] = axes
        if tip is not None:
            bone = rest[_bvh_joint(bvh, tip, path)] - rest[joints[i]]
            align[i] = minimal_rotation(axes @ np.asarray(direction), bone) @ axes
    # Hinges: twist child and parent about the child's bone so that the BVH's flexion axis
    # (the principal axis of the relative rotation over the clip) lands on the model's axis.
    world = None
    for i in range(1, model.size):
        if model.joint_type[i] != HINGE or RETARGET_MAP[model.names[i]][2] is None:
            continue
        if world is None:
            world = bvh_global(bvh)[:, :, 0:3, 0:3]
        p = model.parent[i]
        relative = np.einsum("fba,fbc->fac", world[:, joints[p]], world[:, joints[i]])
        w = np.array([se3.log_so3(np.ascontiguousarray(r)) for r in relative])
        w = w[np.linalg.norm(w, axis=1) > np.radians(5.0)]
        if len(w) < 3:
            continue
        flexion = align[i].T @ np.linalg.svd(w, full_matrices=False)[2][0]
        bone = np.asarray(RETARGET_MAP[model.names[i]][2], dtype=np.float64)
        bone /= np.linalg.norm(bone)
        have = flexion - (flexion @ bone) * bone
        want = model.axis[i] - (model.axis[i] @ bone) * bone
        if np.linalg.norm(have) < 1e-6 or np.linalg.norm(want) < 1e-6:
            continue
        if have @ want < 0:
            have = -have
        angle = np.arctan2(np.cross(want, have) @ bone, want @ have)
        twist = se3.exp_so3(bone * angle)
        align[i] = align[i] @ twist
        align[p] = align[p] @ twist
    return joints, align


def retarget(bvh: Bvh, model: Model, start: int = 0, frames: int | None = None, stride: int = 1,
             centre: bool = True, path: object = "<bvh>") -> np.ndarray:
    """Model poses (frames, N, 4, 4) following BVH frames start, start+stride, ...

    R_i = C R_bvh(joint_i) A_i (see :func:`alignments`); the root sits at the
    midpoint of the BVH hip joints (scaled by :data:`CMU_UNIT`). With ``centre``
    the clip's root path is centred on the world origin in x, y (middle of its
    bounding box) and lifted so that the lower foot touches z = 0 (median over
    frames). Poses are projected onto the model's joints with ``Model.coerce``,
    so hinge joints keep only their rotation about the axis.
    """
    if frames is None:
        frames = (bvh.frames - start + stride - 1) // stride
    index = start + stride * np.arange(frames)
    if frames <= 0 or start < 0 or index[-1] >= bvh.frames:
        raise TrackerInputError(
            f"{path}: frames {start}..{index[-1] if frames > 0 else start} (stride {stride}) are outside the "
            f"clip's {bvh.frames} frames; choose a smaller start, frame count or stride"
        )
    joints, align = alignments(bvh, model, path)
    world = bvh_global(bvh, index)
    c = BVH_TO_WORLD
    rotations = np.einsum("ab,fnbc,ncd->fnad", c, world[:, joints, 0:3, 0:3], align)
    hips = [_bvh_joint(bvh, name, path) for name in ("LeftHip", "RightHip")]
    root = 0.5 * (world[:, hips[0], 0:3, 3] + world[:, hips[1], 0:3, 3]) * CMU_UNIT @ c.T
    poses = np.stack([poses_from_rotations(model, root[f], rotations[f]) for f in range(frames)])
    poses = np.stack([model.coerce(p) for p in poses])
    if centre:
        shift = np.zeros(3)
        xy = poses[:, 0, 0:2, 3]
        shift[0:2] = -0.5 * (xy.min(axis=0) + xy.max(axis=0))
        shift[2] = -float(np.median(lowest_points(model, poses)))
        poses[:, :, 0:3, 3] += shift
    return poses


def lowest_points(model: Model, poses: np.ndarray) -> np.ndarray:
    """The lowest z of the body's surface per frame (F,), from sampled quadric surfaces."""
    samples = []
    for k, params in enumerate(model.quadric_params):
        samples.append((model.quadric_component[k], _surface_samples(model.quadric_shape[k], params)))
    low = np.full(poses.shape[0], np.inf)
    for comp, points in samples:
        if len(points) == 0:
            continue
        z = np.einsum("fj,mj->fm", poses[:, comp, 2, 0:3], points) + poses[:, comp, 2, 3:4]
        low = np.minimum(low, z.min(axis=1))
    return low


def _surface_samples(shape: str, params: dict, count: int = 24) -> np.ndarray:
    """Points on one quadric's kept surface in its component's frame (for extents, not rendering)."""
    u = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    if shape in ("sphere", "ellipsoid"):
        centre = np.asarray(params.get("center", [0.0, 0.0, 0.0]), dtype=np.float64)
        radii = np.full(3, float(params["radius"])) if shape == "sphere" else np.asarray(params["radii"], float)
        v = np.linspace(-np.pi / 2, np.pi / 2, count // 2 + 1)
        uu, vv = np.meshgrid(u, v)
        unit = np.stack([np.cos(vv) * np.cos(uu), np.cos(vv) * np.sin(uu), np.sin(vv)], axis=-1).reshape(-1, 3)
        points = centre + unit * radii
        if "clip" in params:
            lo, hi = params["clip"]
            points = points[(points[:, 2] >= centre[2] + lo) & (points[:, 2] <= centre[2] + hi)]
        return points
    if shape not in ("cylinder", "cone"):
        return np.zeros((0, 3))
    start = np.asarray(params["from"], dtype=np.float64)
    end = np.asarray(params["to"], dtype=np.float64)
    r0, r1 = (params["radius"],) * 2 if shape == "cylinder" else params["radii"]
    axis = end - start
    z = axis / np.linalg.norm(axis)
    x = np.cross(z, np.eye(3)[np.argmin(np.abs(z))])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    ring = np.cos(u)[:, None] * x + np.sin(u)[:, None] * y
    return np.concatenate([start + r0 * ring, end + r1 * ring])


def bounding_spheres(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Per quadric a sphere (centre in its component's frame (Q, 3), radius (Q,)) holding its kept surface."""
    centres, radii = [], []
    for shape, params in zip(model.quadric_shape, model.quadric_params):
        if shape in ("sphere", "ellipsoid"):
            centres.append(np.asarray(params.get("center", [0.0, 0.0, 0.0]), dtype=np.float64))
            radii.append(float(params["radius"]) if shape == "sphere" else float(np.max(params["radii"])))
        elif shape in ("cylinder", "cone"):
            start = np.asarray(params["from"], dtype=np.float64)
            end = np.asarray(params["to"], dtype=np.float64)
            r = float(params["radius"]) if shape == "cylinder" else float(np.max(params["radii"]))
            centres.append(0.5 * (start + end))
            radii.append(float(np.hypot(0.5 * np.linalg.norm(end - start), r)))
        else:  # an unknown shape: no bound, cast every pixel
            centres.append(np.zeros(3))
            radii.append(np.inf)
    return np.asarray(centres), np.asarray(radii) * 1.001 + 1e-6


# ---------------------------------------------------------------------------------------------
# Procedural motion


def _rx(a):
    return se3.exp_so3(np.array([a, 0.0, 0.0]))


def _ry(a):
    return se3.exp_so3(np.array([0.0, a, 0.0]))


def _rz(a):
    return se3.exp_so3(np.array([0.0, 0.0, a]))


def procedural_motion(model: Model, frames: int, fps: float = 60.0, seed: int = 0) -> np.ndarray:
    """Smooth model poses (frames, N, 4, 4): turning on the spot, knee bends, arm swings and a wave.

    Built by forward kinematics from per-joint rotations relative to the rest pose
    (E_i = E_parent T0_i R_i), then ``Model.coerce``. The seed varies the phases
    and rates a little. Feet stay near z = 0 when the knees bend (the root drops).
    Needs the human model's component names.
    """
    rng = np.random.default_rng(seed)
    missing = [n for n in RETARGET_MAP if n not in model.names]
    if missing:
        raise TrackerInputError(
            f"model {model.name!r}: procedural motion needs the components {', '.join(missing)}; use models/human.toml"
        )
    idx = {name: model.index(name) for name in model.names}
    thigh = float(np.linalg.norm(model.rest[idx["shin_l"], 0:3, 3]))
    shin = float(np.linalg.norm(model.rest[idx["foot_l"], 0:3, 3]))
    foot_low = -float(lowest_points(model, _rest_stack(model, 1))[0])
    phase = rng.uniform(0.0, 2.0 * np.pi, size=6)
    rate = rng.uniform(0.85, 1.15, size=4)
    out = np.empty((frames, model.size, 4, 4))
    for f in range(frames):
        t = f / fps
        yaw = 0.9 * np.sin(0.35 * rate[0] * t + phase[0]) + 0.25 * t
        bend = 0.35 * (1.0 - np.cos(2.0 * np.pi * 0.4 * rate[1] * t + phase[1]))  # 0 .. 0.7 rad
        swing = 0.45 * np.sin(2.0 * np.pi * 0.7 * rate[2] * t + phase[2])
        wave = np.sin(2.0 * np.pi * 1.1 * rate[3] * t + phase[3])
        local = {name: np.eye(3) for name in model.names}
        local["pelvis"] = _rz(yaw) @ _rx(0.15 * bend)
        local["torso"] = _rz(0.25 * np.sin(2.0 * np.pi * 0.3 * t + phase[4])) @ _rx(-0.1 * bend)
        local["head"] = _rz(0.4 * np.sin(2.0 * np.pi * 0.25 * t + phase[5])) @ _rx(0.15 * np.sin(2.0 * np.pi * 0.5 * t))
        for side in ("l", "r"):  # world pitch: thigh -bend (forward), shin +bend, foot 0 (flat)
            local[f"thigh_{side}"] = _rx(-1.15 * bend)
            local[f"shin_{side}"] = _rx(2.0 * bend)
            local[f"foot_{side}"] = _rx(-bend)
        # right arm swings forward and back with the elbow bending; left arm raised sideways, waving
        local["upperarm_r"] = _rx(-swing) @ _ry(0.15)
        local["forearm_r"] = _rx(-(0.5 + 0.4 * np.sin(2.0 * np.pi * 0.7 * rate[2] * t + phase[2] + 1.0)))
        local["hand_r"] = _rx(0.2 * swing)
        raise_l = 1.6 + 0.5 * (1.0 + np.sin(2.0 * np.pi * 0.2 * t))  # 1.6 .. 2.6 rad from hanging
        local["upperarm_l"] = _ry(-raise_l) @ _rz(np.pi / 2)
        local["forearm_l"] = _rx(-(0.7 + 0.5 * wave))
        local["hand_l"] = _ry(0.3 * wave)
        root = np.array([0.0, 0.0, 0.0])
        poses = np.empty((model.size, 4, 4))
        for i, name in enumerate(model.names):
            pose = np.eye(4)
            pose[0:3, 0:3] = local[name]
            poses[i] = pose if model.parent[i] < 0 else poses[model.parent[i]] @ model.rest[i] @ pose
        # hips above the ankles: (thigh + shin) cos(bend) plus the ankle's height above the sole
        root[2] = (thigh + shin) * np.cos(bend) + foot_low
        poses[:, 0:3, 3] += root
        out[f] = model.coerce(poses)
    out[:, :, 2, 3] -= np.median(lowest_points(model, out))
    return out


def _rest_stack(model: Model, frames: int) -> np.ndarray:
    return np.stack([rest_poses(model, np.eye(4))] * frames)


# ---------------------------------------------------------------------------------------------
# Cameras


def look_at_camera(name: str, eye, target=(0.0, 0.0, 1.0), size=(640, 480), focal: float = 560.0,
                   distortions=(0.0, 0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)) -> Camera:
    """A camera at ``eye`` looking at ``target`` with ``up`` pointing up in the image.

    OpenCV axes (x right, y down, z forward); fx = fy = ``focal``; principal point
    at the image centre ((w - 1)/2, (h - 1)/2 with pixel centres at integers).
    """
    eye = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look_at_camera: the viewing direction is parallel to `up`; choose another up vector")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward])
    w, h = int(size[0]), int(size[1])
    matrix = np.array([[focal, 0.0, (w - 1) / 2.0], [0.0, focal, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return Camera(name, (w, h), matrix, np.asarray(distortions, dtype=np.float64), rotation, -rotation @ eye)


def demo3_rig() -> list[Camera]:
    """calib/demo3.toml: three 640x480 cameras around the CMU 131_01 walk (along -y through the origin).

    cam0 frontal-oblique (the subject walks towards it), cam1 from the body's left side,
    cam2 from behind on the other side; fx = fy = 560, mild barrel distortion.
    """
    dist = (-0.08, 0.02, 0.0, 0.0)
    return [
        look_at_camera("cam0", (1.7, -3.7, 1.55), (0.0, 0.0, 0.85), focal=560.0, distortions=dist),
        look_at_camera("cam1", (4.1, 0.4, 1.25), (0.0, 0.0, 0.9), focal=565.0, distortions=(-0.075, 0.018, 0.0, 0.0)),
        look_at_camera("cam2", (-2.7, 3.0, 1.95), (0.0, 0.0, 0.8), focal=555.0, distortions=(-0.085, 0.022, 0.0, 0.0)),
    ]


def ring4_rig() -> list[Camera]:
    """calib/ring4.toml: four undistorted 640x480 cameras at other heights and angles, one wide (f = 420)."""
    return [
        look_at_camera("cam0", (0.4, -4.3, 1.0), (0.0, 0.0, 0.9), focal=560.0),
        look_at_camera("cam1", (3.0, 3.0, 2.5), (0.0, 0.0, 0.8), focal=600.0),
        look_at_camera("cam2", (-3.4, -0.6, 1.6), (0.0, 0.0, 0.9), focal=420.0),
        look_at_camera("cam3", (-1.8, 3.9, 0.7), (0.0, 0.0, 1.0), focal=540.0),
    ]


def write_rigs(folder: str | os.PathLike = Path(__file__).resolve().parents[1] / "calib") -> list[Path]:
    """Write calib/demo3.toml and calib/ring4.toml from :func:`demo3_rig` and :func:`ring4_rig`."""
    folder = Path(folder)
    paths = [folder / "demo3.toml", folder / "ring4.toml"]
    save_calibration(demo3_rig(), paths[0])
    save_calibration(ring4_rig(), paths[1])
    return paths


def pixel_rays(camera: Camera) -> np.ndarray:
    """Normalised undistorted coordinates (H, W, 2) of every pixel centre: the ray (x, y, 1) in the camera frame.

    Exact inverse of the camera's lens model (``undistort_pixels`` to 1e-14), so
    the rendered images carry the rig's distortion.
    """
    w, h = camera.size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    return np.ascontiguousarray(camera.undistort_pixels(pixels).reshape(h, w, 2))


# ---------------------------------------------------------------------------------------------
# Ray casting


def view_quadrics(model: Model, poses: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Surfaces and clips of every quadric in the camera frame (Q, 4, 4): T^-T Q T^-1 with T = P_cam E_c."""
    transforms = camera.pose @ poses[model.quadric_component]
    inverse = np.linalg.inv(transforms)
    inverse_t = np.transpose(inverse, (0, 2, 1))
    surfaces = inverse_t @ model.quadric @ inverse
    clips = inverse_t @ model.clip @ inverse
    return (np.ascontiguousarray(0.5 * (surfaces + np.transpose(surfaces, (0, 2, 1)))),
            np.ascontiguousarray(0.5 * (clips + np.transpose(clips, (0, 2, 1)))))


def view_boxes(model: Model, poses: np.ndarray, camera: Camera, spheres=None) -> np.ndarray:
    """Per quadric a box (Q, 4) [x0, y0, x1, y1] in normalised coordinates holding its image.

    From the bounding sphere's cube (an overestimate); the whole plane when the
    sphere reaches behind the camera, an empty box when it is wholly behind.
    """
    centres, radii = bounding_spheres(model) if spheres is None else spheres
    comp = model.quadric_component
    world = np.einsum("qab,qb->qa", poses[comp, 0:3, 0:3], centres) + poses[comp, 0:3, 3]
    cam = world @ camera.rotation.T + camera.translation
    boxes = np.empty((len(radii), 4))
    for k, (s, r) in enumerate(zip(cam, radii)):
        if not np.isfinite(r) or s[2] - r <= 1e-6:
            boxes[k] = (-np.inf, -np.inf, np.inf, np.inf) if s[2] + r > 0 else (1.0, 1.0, -1.0, -1.0)
            continue
        near, far = s[2] - r, s[2] + r
        boxes[k] = (min((s[0] - r) / near, (s[0] - r) / far), min((s[1] - r) / near, (s[1] - r) / far),
                    max((s[0] + r) / near, (s[0] + r) / far), max((s[1] + r) / near, (s[1] + r) / far))
    return boxes


@njit(cache=True, inline="always")
def _form(m, x, y, z, w):
    """X~^T M X~ for X~ = (x, y, z, w) and symmetric M."""
    return (m[0, 0] * x * x + m[1, 1] * y * y + m[2, 2] * z * z + m[3, 3] * w * w
            + 2.0 * (m[0, 1] * x * y + m[0, 2] * x * z + m[0, 3] * x * w
                     + m[1, 2] * y * z + m[1, 3] * y * w + m[2, 3] * z * w))


@njit(cache=True)
def _nearest_hit(q, clip, x, y):
    """Smallest depth t > 0 at which the ray t (x, y, 1) meets the kept part of quadric ``q``; inf if none.

    Roots of a t^2 + b t + c = 0 (a = d^T Q d, b = 2 d^T q, c = Q_44 with the ray
    from the origin); the near root when it passes the clip, else the far one
    (no end caps: the inside of a tube shows through its open end).
    """
    a = _form(q, x, y, 1.0, 0.0)
    b = 2.0 * (q[0, 3] * x + q[1, 3] * y + q[2, 3])
    c = q[3, 3]
    scale = abs(a) + abs(b) + abs(c)
    if abs(a) <= 1e-12 * scale:
        if abs(b) <= 1e-300:
            return np.inf
        t1 = -c / b
        t2 = np.inf
    else:
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return np.inf
        root = np.sqrt(disc)
        h = -0.5 * (b + root) if b >= 0.0 else -0.5 * (b - root)
        if h == 0.0:
            t1 = t2 = 0.0
        else:
            t1 = h / a
            t2 = c / h
        if t1 > t2:
            t1, t2 = t2, t1
    for t in (t1, t2):
        if t > 1e-9 and t < np.inf and _form(clip, t * x, t * y, t, 1.0) <= 0.0:
            return t
    return np.inf


@njit(cache=True, parallel=True)
def render_kernel(rays, surfaces, clips, boxes, owner, light, ambient, key, fill, comp_out, shade_out, depth_out):
    """Ray-cast every pixel against every clipped quadric (numba; see :func:`render`).

    ``rays`` (H, W, 2) normalised coordinates of the pixel centres, ``surfaces``/
    ``clips`` (Q, 4, 4) in the camera frame, ``boxes`` (Q, 4) normalised bounds,
    ``owner`` (Q,) component per quadric, ``light`` (3,) unit direction towards
    the key light in the camera frame.  Writes per pixel the nearest hit's
    component (-1: none), shade ``ambient + key max(0, n.l) + fill |n.v|`` with n
    the unit surface normal turned towards the camera, and its depth z (inf: none).
    """
    h, w = rays.shape[0], rays.shape[1]
    nq = surfaces.shape[0]
    for v in prange(h):
        for u in range(w):
            x = rays[v, u, 0]
            y = rays[v, u, 1]
            best = np.inf
            hit = -1
            for k in range(nq):
                if x < boxes[k, 0] or x > boxes[k, 2] or y < boxes[k, 1] or y > boxes[k, 3]:
                    continue
                t = _nearest_hit(surfaces[k], clips[k], x, y)
                if t < best:
                    best = t
                    hit = k
            depth_out[v, u] = best
            if hit < 0:
                comp_out[v, u] = -1
                shade_out[v, u] = 0.0
                continue
            q = surfaces[hit]
            px, py, pz = best * x, best * y, best
            nx = q[0, 0] * px + q[0, 1] * py + q[0, 2] * pz + q[0, 3]
            ny = q[1, 0] * px + q[1, 1] * py + q[1, 2] * pz + q[1, 3]
            nz = q[2, 0] * px + q[2, 1] * py + q[2, 2] * pz + q[2, 3]
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            vn = np.sqrt(x * x + y * y + 1.0)
            facing = (nx * x + ny * y + nz) / (norm * vn)  # n . (ray direction)
            sign = -1.0 if facing > 0.0 else 1.0
            lambert = sign * (nx * light[0] + ny * light[1] + nz * light[2]) / norm
            comp_out[v, u] = owner[hit]
            shade_out[v, u] = ambient + key * max(lambert, 0.0) + fill * abs(facing)


def _forms(m, x, y, z, w):
    """Vectorised X~^T M X~ over arrays x, y, z, w."""
    return (m[0, 0] * x * x + m[1, 1] * y * y + m[2, 2] * z * z + m[3, 3] * w * w
            + 2.0 * (m[0, 1] * x * y + m[0, 2] * x * z + m[0, 3] * x * w
                     + m[1, 2] * y * z + m[1, 3] * y * w + m[2, 3] * z * w))


def render(rays, surfaces, clips, owner, light, ambient=0.35, key=0.45, fill=0.3):
    """Pure-numpy reference of :func:`render_kernel` (no boxes): (component, shade, depth) per pixel.

    Same mathematics, vectorised over pixels one quadric at a time; slow, for tests.
    """
    x, y = rays[..., 0], rays[..., 1]
    one = np.ones_like(x)
    best = np.full(x.shape, np.inf)
    hit = np.full(x.shape, -1, dtype=np.int64)
    for k, (q, clip) in enumerate(zip(surfaces, clips)):
        a = _forms(q, x, y, one, 0.0 * one)
        b = 2.0 * (q[0, 3] * x + q[1, 3] * y + q[2, 3])
        c = q[3, 3] * one
        with np.errstate(invalid="ignore", divide="ignore"):
            disc = b * b - 4.0 * a * c
            root = np.sqrt(np.maximum(disc, 0.0))
            linear = np.abs(a) <= 1e-12 * (np.abs(a) + np.abs(b) + np.abs(c))
            t_a = np.where(linear, -c / b, (-b - root) / (2.0 * a))
            t_b = np.where(linear, np.inf, (-b + root) / (2.0 * a))
        t1, t2 = np.minimum(t_a, t_b), np.maximum(t_a, t_b)
        valid = linear | (disc >= 0.0)
        t = np.full(x.shape, np.inf)
        for root_t in (t2, t1):  # the near root wins when both pass
            with np.errstate(invalid="ignore"):
                ok = valid & np.isfinite(root_t) & (root_t > 1e-9)
                ok &= _forms(clip, root_t * x, root_t * y, root_t, one) <= 0.0
            t = np.where(ok, root_t, t)
        closer = t < best
        best = np.where(closer, t, best)
        hit = np.where(closer, k, hit)
    comp = np.where(hit >= 0, np.asarray(owner)[np.maximum(hit, 0)], -1)
    shade = np.zeros(x.shape)
    for k, q in enumerate(surfaces):
        sel = hit == k
        if not sel.any():
            continue
        points = np.stack([best[sel] * x[sel], best[sel] * y[sel], best[sel], np.ones(sel.sum())], axis=1)
        normals = points @ q[:, 0:3]
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        view = np.stack([x[sel], y[sel], np.ones(sel.sum())], axis=1)
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        facing = np.sum(normals * view, axis=1)
        normals[facing > 0] *= -1.0
        shade[sel] = ambient + key * np.maximum(normals @ light, 0.0) + fill * np.abs(facing)
    return comp, shade, best


DEFAULT_LIGHT = np.array([0.35, -0.45, 0.82])
"""Direction towards the key light in world (above, in front of the walking subject, to its left)."""

ALBEDO = {
    # BGR reflectances: limbs differ from each other, left from right, and from typical backgrounds
    "pelvis": (0.42, 0.22, 0.16),      # dark blue shorts
    "torso": (0.80, 0.88, 0.92),       # light shirt
    "head": (0.50, 0.62, 0.82),        # skin
    "upperarm_l": (0.25, 0.55, 0.90),  # orange sleeve
    "upperarm_r": (0.20, 0.22, 0.48),  # dark red sleeve
    "forearm_l": (0.70, 0.80, 0.86),   # light
    "forearm_r": (0.20, 0.24, 0.30),   # dark
    "hand_l": (0.45, 0.56, 0.78),
    "hand_r": (0.38, 0.48, 0.70),
    "thigh_l": (0.62, 0.38, 0.22),     # blue
    "thigh_r": (0.26, 0.42, 0.28),     # dark green
    "shin_l": (0.92, 0.90, 0.86),      # white
    "shin_r": (0.14, 0.14, 0.16),      # black
    "foot_l": (0.10, 0.10, 0.12),
    "foot_r": (0.90, 0.92, 0.95),
}


def albedos(model: Model) -> np.ndarray:
    """BGR reflectance per component (N, 3): :data:`ALBEDO` by name, else alternating light and dark."""
    fallback = [(0.85, 0.85, 0.80), (0.20, 0.25, 0.35), (0.55, 0.70, 0.85), (0.60, 0.35, 0.20)]
    return np.array([ALBEDO.get(n, fallback[i % len(fallback)]) for i, n in enumerate(model.names)])


def load_backgrounds(cameras: list[Camera], paths=None, seed: int = 0) -> tuple[list[np.ndarray], list[Path]]:
    """One BGR background (H, W, 3) uint8 per camera and the photo files used.

    ``paths``: image files, or None for :data:`DEFAULT_BACKGROUNDS` in
    :data:`BACKGROUNDS` (those present). Camera k takes photo k mod n, mirrored on every second pass round the
    list, resized to cover the image and centre-cropped. Without photos, a
    smooth procedural backdrop with a few blurred blocks.
    """
    if paths is None:
        paths = [BACKGROUNDS / name for name in DEFAULT_BACKGROUNDS if (BACKGROUNDS / name).is_file()]
    paths = [Path(p) for p in paths]
    photos = []
    for p in paths:
        image = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if image is None:
            raise TrackerInputError(f"{p}: cannot read the background image; give a readable .png or .jpg")
        photos.append(image)
    out, used = [], []
    rng = np.random.default_rng(seed)
    for k, cam in enumerate(cameras):
        w, h = cam.size
        if photos:
            image = photos[k % len(photos)]
            if (k // len(photos)) % 2 == 1:
                image = image[:, ::-1]
            used.append(paths[k % len(photos)])
            scale = max(w / image.shape[1], h / image.shape[0])
            size = (max(w, round(image.shape[1] * scale)), max(h, round(image.shape[0] * scale)))
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
            x0, y0 = (image.shape[1] - w) // 2, (image.shape[0] - h) // 2
            out.append(np.ascontiguousarray(image[y0 : y0 + h, x0 : x0 + w]))
        else:
            yy, xx = np.mgrid[0:h, 0:w] / max(w, h)
            base = 90 + 60 * xx + 30 * yy + rng.uniform(-20, 20)
            image = np.repeat(base[..., None], 3, axis=2)
            for _ in range(12):
                x0, y0 = rng.integers(0, w), rng.integers(0, h)
                image[y0 : y0 + rng.integers(10, h // 3), x0 : x0 + rng.integers(10, w // 3)] = rng.uniform(30, 220, 3)
            out.append(np.clip(cv2.GaussianBlur(image, (0, 0), 3.0), 0, 255).astype(np.uint8))
    return out, sorted(set(used))


class Renderer:
    """Renders one camera: pixel rays precomputed once, then :meth:`render` per frame."""

    def __init__(self, model: Model, camera: Camera, background: np.ndarray | None = None,
                 light=DEFAULT_LIGHT, ambient: float = 0.35, key: float = 0.45, fill: float = 0.3,
                 blur: float = 0.7, noise: float = 3.0):
        self.model, self.camera = model, camera
        self.rays = pixel_rays(camera)
        self.spheres = bounding_spheres(model)
        w, h = camera.size
        self.background = np.full((h, w, 3), 128, np.uint8) if background is None else background
        if self.background.shape != (h, w, 3):
            raise ValueError(f"background shape {self.background.shape} does not match camera {camera.name} ({h}, {w}, 3)")
        self._background_f32 = self.background.astype(np.float32)
        light = np.asarray(light, dtype=np.float64)
        self.light_world = light / np.linalg.norm(light)
        self.ambient, self.key, self.fill = ambient, key, fill
        self.blur, self.noise = blur, noise
        self.albedo = albedos(model).astype(np.float32) * 255.0
        self.comp = np.empty((h, w), np.int64)
        self.shade = np.empty((h, w), np.float64)
        self.depth = np.empty((h, w), np.float64)

    def cast(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Component id (-1: background), shade and depth per pixel for model poses (N, 4, 4)."""
        surfaces, clips = view_quadrics(self.model, poses, self.camera)
        boxes = view_boxes(self.model, poses, self.camera, self.spheres)
        light = self.camera.rotation @ self.light_world
        render_kernel(self.rays, surfaces, clips, boxes, self.model.quadric_component, light,
                      self.ambient, self.key, self.fill, self.comp, self.shade, self.depth)
        return self.comp, self.shade, self.depth

    def render(self, poses: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """BGR uint8 image of the body at ``poses`` over the background, soft edges, sensor noise.

        The body layer (albedo x shade) and its coverage are blurred with a Gaussian
        of ``blur`` px (premultiplied alpha, so edges mix body and background like a
        lens does), composited over the background, then Gaussian noise of ``noise``
        grey levels (the same in the three channels) is added.
        """
        comp, shade, _ = self.cast(poses)
        image = self._background_f32.copy()
        rows = np.flatnonzero((comp >= 0).any(axis=1))
        if len(rows):
            cols = np.flatnonzero((comp[rows[0] : rows[-1] + 1] >= 0).any(axis=0))
            pad = int(np.ceil(4.0 * self.blur)) + 1
            h, w = comp.shape
            y0, y1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, h)
            x0, x1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)
            c = comp[y0:y1, x0:x1]
            mask = (c >= 0).astype(np.float32)
            body = self.albedo[np.maximum(c, 0)] * (shade[y0:y1, x0:x1].astype(np.float32) * mask)[..., None]
            if self.blur > 0:
                body = cv2.GaussianBlur(body, (0, 0), self.blur, borderType=cv2.BORDER_REPLICATE)
                mask = cv2.GaussianBlur(mask, (0, 0), self.blur, borderType=cv2.BORDER_REPLICATE)
            image[y0:y1, x0:x1] = body + (1.0 - mask)[..., None] * image[y0:y1, x0:x1]
        if self.noise > 0:
            rng = np.random.default_rng() if rng is None else rng
            image += (rng.standard_normal(comp.shape, dtype=np.float32) * np.float32(self.noise))[..., None]
        np.clip(image, 0.0, 255.0, out=image)
        return (image + 0.5).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# Motion-JPEG AVI writer


class MjpegAviWriter:
    """A minimal AVI 1.0 (RIFF) writer of Motion-JPEG frames encoded by libjpeg (``cv2.imencode``).

    OpenCV's built-in MJPEG writer compresses poorly (about twice the bytes at
    equal quality) and its FFMPEG writer ignores the quality property; this one
    writes baseline JPEGs with 4:2:0 chroma and optimised Huffman tables at
    ``quality`` (0..100), plus an ``idx1`` index, which OpenCV and ffmpeg read.
    Frames are written to ``path`` as they come; :meth:`close` patches the sizes.
    """

    _MAX_BYTES = 1 << 30  # AVI 1.0 RIFF limit (no OpenDML extension here)

    def __init__(self, path: str | os.PathLike, fps: float, size: tuple[int, int], quality: int = 70):
        self.path = Path(path)
        self.width, self.height = int(size[0]), int(size[1])
        self.rate, self.scale = (round(fps), 1) if abs(fps - round(fps)) < 1e-3 else (round(fps * 1000), 1000)
        self.params = [cv2.IMWRITE_JPEG_QUALITY, int(quality), cv2.IMWRITE_JPEG_OPTIMIZE, 1,
                       cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
        self.index: list[tuple[int, int]] = []  # (offset from 'movi', size) per frame
        self.max_frame = 0
        self.file = open(self.path, "wb")
        self._write_headers()

    def _write_headers(self) -> None:
        w, h = self.width, self.height
        avih = struct.pack("<14I", round(1e6 * self.scale / self.rate), 0, 0, 0x10, 0, 0, 1, 0, w, h, 0, 0, 0, 0)
        strh = struct.pack("<4s4sIHHIIIIIIIIhhhh", b"vids", b"MJPG", 0, 0, 0, 0, self.scale, self.rate, 0, 0, 0,
                           0xFFFFFFFF, 0, 0, 0, w, h)
        strf = struct.pack("<IiiHH4sIiiII", 40, w, h, 1, 24, b"MJPG", w * h * 3, 0, 0, 0, 0)
        strl = b"strl" + _chunk(b"strh", strh) + _chunk(b"strf", strf)
        hdrl = b"hdrl" + _chunk(b"avih", avih) + _chunk(b"LIST", strl)
        self.file.write(b"RIFF\0\0\0\0AVI " + _chunk(b"LIST", hdrl))
        self.movi_at = self.file.tell()  # position of the movi LIST header
        self.file.write(b"LIST\0\0\0\0movi")

    def write(self, image: np.ndarray) -> None:
        """Append one BGR (or grey) uint8 frame of the writer's size."""
        if image.shape[0] != self.height or image.shape[1] != self.width:
            raise ValueError(f"frame {image.shape} does not match the video size {self.width}x{self.height}")
        ok, buffer = cv2.imencode(".jpg", image, self.params)
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        data = buffer.tobytes()
        offset = self.file.tell() - (self.movi_at + 8)
        self.file.write(_chunk(b"00dc", data))
        if self.file.tell() > self._MAX_BYTES:
            raise TrackerInputError(f"{self.path}: the video passed 1 GiB (AVI 1.0 limit); render fewer frames")
        self.index.append((offset, len(data)))
        self.max_frame = max(self.max_frame, len(data))

    def close(self) -> None:
        """Write the index and patch the header sizes and frame counts."""
        if self.file.closed:
            return
        f = self.file
        movi_end = f.tell()
        f.write(b"idx1" + struct.pack("<I", 16 * len(self.index)))
        for offset, size in self.index:
            f.write(struct.pack("<4sIII", b"00dc", 0x10, offset, size))
        end = f.tell()
        frames = len(self.index)
        f.seek(4)
        f.write(struct.pack("<I", end - 8))
        f.seek(self.movi_at + 4)
        f.write(struct.pack("<I", movi_end - self.movi_at - 8))
        # avih: RIFF(12) + LIST hdrl header(8) + 'hdrl'(4) + 'avih' chunk header(8) = 32
        f.seek(32 + 4 * 4)
        f.write(struct.pack("<I", frames))
        f.seek(32 + 4 * 7)
        f.write(struct.pack("<I", self.max_frame + 8))
        # strh: after avih (56) + LIST strl header (8) + 'strl' (4) + 'strh' chunk header (8)
        strh = 32 + 56 + 8 + 4 + 8
        f.seek(strh + 32)
        f.write(struct.pack("<II", frames, self.max_frame + 8))
        f.close()

    def __enter__(self) -> "MjpegAviWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _chunk(fourcc: bytes, data: bytes) -> bytes:
    """A RIFF chunk: fourcc, little-endian size, data, padded to an even length."""
    return fourcc + struct.pack("<I", len(data)) + data + (b"\0" if len(data) % 2 else b"")


# ---------------------------------------------------------------------------------------------
# Recording folders

_CONTAINERS = {"MJPG": ".avi", "XVID": ".avi", "mp4v": ".mp4", "avc1": ".mp4", "FFV1": ".mkv", "png": ""}
DEFAULT_QUALITY = 70
"""MJPG quality (cv2.VIDEOWRITER_PROP_QUALITY, 0..100) of :func:`synthesize`."""


def motion_poses(model: Model, motion: str, frames: int, start: int = 0, stride: int = 2, fps: float = 60.0,
                 seed: int = 0) -> tuple[np.ndarray, float, Path | None]:
    """Poses (F, N, 4, 4), frame rate and the BVH path (or None) for a motion spec.

    ``motion`` is ``"bvh:PATH"`` (retargeted frames start, start + stride, ...;
    rate = BVH rate / stride) or ``"procedural"`` (at ``fps``).
    """
    if motion.startswith("bvh:"):
        path = Path(motion[4:])
        bvh = load_bvh(path)
        poses = retarget(bvh, model, start, frames, stride, path=path)
        rate = 1.0 / (bvh.frame_time * stride)
        return poses, float(round(rate)) if abs(rate - round(rate)) < 0.01 else rate, path
    if motion == "procedural":
        return procedural_motion(model, frames, fps, seed), float(fps), None
    raise TrackerInputError(f"motion {motion!r} is not known; use --motion bvh:PATH/TO/CLIP.bvh or --motion procedural")


def init_document(model: Model, poses: np.ndarray) -> dict:
    """The init.toml table of one frame's poses (N, 4, 4): world rotations for all, translation for the root."""
    document: dict = {"pose": {}}
    for i, name in enumerate(model.names):
        entry = {"rotation": [float(v) for v in se3.log_so3(np.ascontiguousarray(poses[i, 0:3, 0:3]))]}
        if model.parent[i] < 0:
            entry = {"translation": [float(v) for v in poses[i, 0:3, 3]], **entry}
        document["pose"][name] = entry
    return document


def write_truth(path: str | os.PathLike, model: Model, poses: np.ndarray, frame: np.ndarray | None = None) -> None:
    """truth.npz (formats.md): frame, component_names, poses, joint_names, joints; unicode strings, atomic."""
    frame = np.arange(len(poses)) if frame is None else np.asarray(frame)
    arrays = {
        "frame": frame.astype(np.int64),
        "component_names": np.array(model.names, dtype=str),
        "poses": np.asarray(poses, dtype=np.float64),
        "joint_names": np.array(model.joint_names, dtype=str),
        "joints": joint_centres(np.asarray(poses, dtype=np.float64)),
    }
    atomic_write(path, lambda file: np.savez(file, **arrays))


def _readme(name: str, motion: str, bvh: Path | None, backgrounds: list[Path], frames: int, fps: float,
            cameras: list[Camera], model_path: Path, start: int, stride: int) -> str:
    lines = [
        f"# Synthetic recording `{name}`",
        "",
        "Rendered by `tracker.synth` (ray-cast clipped quadrics of the body model, composited over",
        "background photos, Gaussian edge blur and sensor noise). Ground truth in `truth.npz`.",
        "",
        f"- model: `{model_path.name}` (copied as `model.toml`)",
        f"- cameras: {', '.join(c.name for c in cameras)} (`calibration.toml`)",
        f"- frames: {frames} at {fps:g} fps",
        f"- motion: `{motion}`" if bvh is None else
        f"- motion: `{bvh.name}` frames {start}, {start + stride}, ... {start + stride * (frames - 1)} (every {stride}),"
        " retargeted onto the model",
        "",
        "## Credits and licences",
        "",
    ]
    if bvh is not None:
        lines += [
            f"- Motion `{bvh.name}`: CMU Graphics Lab Motion Capture Database, http://mocap.cs.cmu.edu/ .",
            "  \"The data used in this project was obtained from mocap.cs.cmu.edu. The database was created",
            "  with funding from NSF EIA-0196217.\" Free for research and commercial use.",
        ]
    if backgrounds:
        lines += [
            f"- Background photos ({', '.join(p.name for p in backgrounds)}): OpenCV samples, https://opencv.org ,",
            "  Apache-2.0 / BSD-3-Clause (Copyright OpenCV contributors).",
        ]
    if bvh is None and not backgrounds:
        lines += ["- Everything here was generated by the tracker project (procedural motion and backdrop)."]
    lines += ["- The rendering itself was generated by the tracker project.", ""]
    return "\n".join(lines)


def synthesize(model_path: str | os.PathLike, calib_path: str | os.PathLike, out_dir: str | os.PathLike,
               motion: str = "procedural", frames: int = 160, start: int = 0, stride: int = 2, seed: int = 0,
               codec: str = "MJPG", quality: int = DEFAULT_QUALITY, fps: float = 60.0, backgrounds=None,
               noise: float = 3.0, blur: float = 0.7, progress: bool = True) -> dict:
    """Render a recording folder with ground truth (formats.md, "Recording folder").

    Writes ``calibration.toml``, one video per camera ``<cam>.avi`` (``codec``
    MJPG at ``quality``; ``"png"`` writes ``<cam>/000000.png ...`` instead),
    ``model.toml``, ``init.toml`` (the first frame's truth), ``truth.npz`` and a
    ``README.md`` with credits.  ``motion``: ``"bvh:PATH"`` (frames start,
    start + stride, ... of the clip, at the clip's rate / stride) or
    ``"procedural"`` (at ``fps``, varied by ``seed``).  ``quality`` applies to
    MJPG (libjpeg quality, 4:2:0); other OpenCV fourccs (``mp4v``, ``XVID``,
    ``FFV1``) go through ``cv2.VideoWriter``.  ``backgrounds``: image paths (see
    :func:`load_backgrounds`); ``noise`` sigma in grey levels; ``blur`` edge
    sigma in pixels.  Returns a summary dict: out, frames, fps, cameras, files
    (name -> bytes), seconds (render, total), render_ms_per_image and in_view
    (camera -> fraction of frames with the whole body inside the image).
    Raises TrackerInputError for bad inputs (missing BVH or joints, unreadable
    files, unwritable folder).
    """
    from tqdm import tqdm

    started = time.perf_counter()
    model_path, calib_path, out = Path(model_path), Path(calib_path), Path(out_dir)
    if codec not in _CONTAINERS:
        raise TrackerInputError(f"codec {codec!r} is not supported; use one of {', '.join(_CONTAINERS)}")
    if frames < 1:
        raise TrackerInputError(f"frames = {frames}: render at least one frame")
    model = load_model(model_path)
    cameras = load_calibration(calib_path)
    poses, rate, bvh_path = motion_poses(model, motion, frames, start, stride, fps, seed)
    ensure_writable_folder(out)
    photos, used = load_backgrounds(cameras, backgrounds, seed)
    renderers = [Renderer(model, cam, bg, noise=noise, blur=blur) for cam, bg in zip(cameras, photos)]
    rng = np.random.default_rng(seed)

    writers, temps, finals = [], [], []
    for cam in cameras:
        if codec == "png":
            folder = out / cam.name
            folder.mkdir(parents=True, exist_ok=True)
            writers.append(folder)
            continue
        final = out / f"{cam.name}{_CONTAINERS[codec]}"
        temp = out / f".{cam.name}.partial{_CONTAINERS[codec]}"
        if codec == "MJPG":
            writer = MjpegAviWriter(temp, rate, cam.size, quality)
        else:
            writer = cv2.VideoWriter(str(temp), cv2.VideoWriter_fourcc(*codec), rate, cam.size)
            if not writer.isOpened():
                raise TrackerInputError(f"{temp}: OpenCV cannot write {codec} video here; use codec='MJPG' or 'png'")
        writers.append(writer)
        temps.append(temp)
        finals.append(final)
    render_seconds = 0.0
    done = False
    try:
        for f in tqdm(range(frames), desc=f"synth {out.name}", unit="frame", disable=not progress):
            for renderer, writer in zip(renderers, writers):
                tick = time.perf_counter()
                image = renderer.render(poses[f], rng)
                render_seconds += time.perf_counter() - tick
                if codec == "png":
                    cv2.imwrite(str(writer / f"{f:06d}.png"), image)
                else:
                    writer.write(image)
        done = True
    finally:
        for writer in writers:
            if isinstance(writer, MjpegAviWriter):
                writer.close()
            elif not isinstance(writer, Path):
                writer.release()
        if not done:
            for temp in temps:
                temp.unlink(missing_ok=True)
    for temp, final in zip(temps, finals):
        os.replace(temp, final)

    save_calibration(cameras, out / "calibration.toml")
    model_bytes = model_path.read_bytes()
    atomic_write(out / "model.toml", lambda file: file.write(model_bytes))
    document = init_document(model, poses[0])
    atomic_write(out / "init.toml", lambda file: tomli_w.dump(document, file))
    write_truth(out / "truth.npz", model, poses)
    text = _readme(out.name, motion, bvh_path, used, frames, rate, cameras, model_path, start, stride).encode()
    atomic_write(out / "README.md", lambda file: file.write(text))
    files = {p.name: p.stat().st_size for p in sorted(out.iterdir()) if p.is_file() and not p.name.startswith(".")}
    in_view = visibility(model, poses, cameras).mean(axis=0)
    return {
        "out": out,
        "frames": frames,
        "fps": rate,
        "cameras": [c.name for c in cameras],
        "files": files,
        "seconds": {"render": render_seconds, "total": time.perf_counter() - started},
        "render_ms_per_image": 1e3 * render_seconds / (frames * len(cameras)),
        "in_view": {cam.name: float(v) for cam, v in zip(cameras, in_view)},
    }


def visibility(model: Model, poses: np.ndarray, cameras: list[Camera], margin: float = 2.0) -> np.ndarray:
    """(F, C) bool: every sampled surface point of the body projects inside camera c's image (with ``margin`` px)."""
    out = np.zeros((len(poses), len(cameras)), dtype=bool)
    pieces = [(model.quadric_component[k], _surface_samples(model.quadric_shape[k], p))
              for k, p in enumerate(model.quadric_params)]
    for f, pose in enumerate(poses):
        points = np.concatenate([pts @ pose[c, 0:3, 0:3].T + pose[c, 0:3, 3] for c, pts in pieces])
        for j, cam in enumerate(cameras):
            depth = (points @ cam.rotation.T + cam.translation)[:, 2]
            pix = cam.project(points)
            w, h = cam.size
            out[f, j] = bool(np.all(depth > 0) and np.all(pix >= margin - 0.5)
                             and np.all(pix[:, 0] <= w - 0.5 - margin) and np.all(pix[:, 1] <= h - 0.5 - margin))
    return out
