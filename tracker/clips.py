"""Motions for rendered recordings: a BVH clip retargeted onto a body model, or a procedural one.

Both give valid model poses (F, N, 4, 4): every joint exact and within its
limits (:meth:`tracker.model.Model.coerce`).  BVH conventions are in
:mod:`tracker.io.bvh`.
"""

from __future__ import annotations

import numpy as np

from tracker.chain import HINGE
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.bvh import Bvh, bvh_global
from tracker.model import Model, poses_from_rotations, rest_poses

CMU_UNIT = 0.0564
"""Metres per CMU BVH unit ((1/0.45) inch, http://mocap.cs.cmu.edu/faqs.php)."""

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
        w = se3.log_so3_many(np.ascontiguousarray(relative))
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


def retarget(
    bvh: Bvh,
    model: Model,
    start: int = 0,
    frames: int | None = None,
    stride: int = 1,
    centre: bool = True,
    path: object = "<bvh>",
) -> np.ndarray:
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
        samples.append((model.quadric_component[k], surface_samples(model.quadric_shape[k], params)))
    low = np.full(poses.shape[0], np.inf)
    for comp, points in samples:
        if len(points) == 0:
            continue
        z = np.einsum("fj,mj->fm", poses[:, comp, 2, 0:3], points) + poses[:, comp, 2, 3:4]
        low = np.minimum(low, z.min(axis=1))
    return low


def surface_samples(shape: str, params: dict, count: int = 24) -> np.ndarray:
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
    foot_low = -float(lowest_points(model, rest_poses(model, np.eye(4))[None])[0])
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
