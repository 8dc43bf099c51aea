"""Motions for rendered recordings: a BVH clip retargeted onto a body model, or a procedural one.

Both give valid model poses (F, N, 4, 4): every joint exact and within its
limits (:meth:`tracker.model.Model.coerce`).  BVH conventions are in
:mod:`tracker.io.bvh_clip`.
"""

from __future__ import annotations

import numpy as np

from tracker.chain import HINGE
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.bvh_clip import Bvh, bvh_global
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
    *,
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


def _check_human(model: Model, motion: str) -> None:
    """Raise TrackerInputError unless ``model`` has the human model's components that ``motion`` drives."""
    missing = [n for n in RETARGET_MAP if n not in model.names]
    if missing:
        raise TrackerInputError(
            f"model {model.name!r}: {motion} motion needs the components {', '.join(missing)}; use models/human.toml"
        )


def _forward(model: Model, local: dict[str, np.ndarray]) -> np.ndarray:
    """Poses (N, 4, 4) by forward kinematics, E_i = E_parent T0_i R_i, from each component's rotation R_i
    relative to its rest pose (the root's R at the origin)."""
    poses = np.empty((model.size, 4, 4))
    for i, name in enumerate(model.names):
        pose = np.eye(4)
        pose[0:3, 0:3] = local[name]
        poses[i] = pose if model.parent[i] < 0 else poses[model.parent[i]] @ model.rest[i] @ pose
    return poses


def procedural_motion(model: Model, frames: int, *, fps: float = 60.0, seed: int = 0) -> np.ndarray:
    """Smooth model poses (frames, N, 4, 4): turning on the spot, knee bends, arm swings and a wave.

    Built by forward kinematics from per-joint rotations relative to the rest pose
    (E_i = E_parent T0_i R_i), then ``Model.coerce``. The seed varies the phases
    and rates a little. Feet stay near z = 0 when the knees bend (the root drops).
    Needs the human model's component names.
    """
    _check_human(model, "procedural")
    rng = np.random.default_rng(seed)
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
        poses = _forward(model, local)
        # hips above the ankles: (thigh + shin) cos(bend) plus the ankle's height above the sole
        poses[:, 2, 3] += (thigh + shin) * np.cos(bend) + foot_low
        out[f] = model.coerce(poses)
    out[:, :, 2, 3] -= np.median(lowest_points(model, out))
    return out


def _bump(v):
    """sin^2(pi v) on [0, 1], 0 elsewhere: a smooth rise and fall with zero slope at both ends."""
    return float(np.sin(np.pi * v) ** 2) if 0.0 <= v <= 1.0 else 0.0


def _arc(v):
    """sin(pi v) on [0, 1], 0 elsewhere: a flight's height profile (a parabola's close cousin)."""
    return float(np.sin(np.pi * v)) if 0.0 <= v <= 1.0 else 0.0


def _ease(v):
    """3 v^2 - 2 v^3 clipped to [0, 1]: from 0 to 1 with zero slope at both ends."""
    v = min(max(v, 0.0), 1.0)
    return v * v * (3.0 - 2.0 * v)


ATHLETIC_MOVES = ("hop", "kick", "spin")


def athletic_schedule(seconds: float, seed: int = 0) -> list[tuple[str, float, float, float]]:
    """Moves covering ``seconds``: (move, start s, duration s, parameter) in a seeded order.

    Every three moves are a permutation of :data:`ATHLETIC_MOVES`; a hop lasts 0.9-1.2 s, a kick
    0.8-1.0 s (parameter: +1 the left leg, -1 the right, alternating), a spin 1.0-1.3 s (parameter:
    the turn, +-pi..2 pi radians).
    """
    rng = np.random.default_rng([seed, 11])
    schedule: list[tuple[str, float, float, float]] = []
    start, side = 0.0, float(rng.choice([-1.0, 1.0]))
    while start < seconds:
        for move in rng.permutation(ATHLETIC_MOVES):
            if move == "hop":
                duration, parameter = rng.uniform(0.9, 1.2), 0.0
            elif move == "kick":
                duration, parameter, side = rng.uniform(0.8, 1.0), side, -side
            else:
                duration, parameter = (
                    rng.uniform(1.0, 1.3),
                    float(rng.choice([-1.0, 1.0]) * rng.uniform(np.pi, 2 * np.pi)),
                )
            schedule.append((str(move), start, float(duration), float(parameter)))
            start += float(duration)
    return schedule


def athletic_motion(model: Model, frames: int, *, fps: float = 30.0, seed: int = 0) -> np.ndarray:
    """Fast model poses (frames, N, 4, 4): hops, front kicks and jump spins (:func:`athletic_schedule`).

    With u in [0, 1] the progress through a move and b(v) = sin^2(pi v) on [0, 1]:
    a hop crouches (knees 0.55 b(u / 0.3)), flies 0.28 m high for 0.35 of the move, lands
    (0.45 b((u - 0.65) / 0.35)) with both arms swung forward and up; a kick lifts one thigh by
    1.35 b(u) rad with the knee chambered and snapped straight at u = 0.5, the torso leaning back and
    the arms countering; a spin crouches, turns by its angle in the air (eased over u in 0.2..0.75)
    and lands with the arms out. The heading carries over from one spin to the next move, and the body
    sways a little about the origin. Built by forward kinematics like :func:`procedural_motion`, then
    ``Model.coerce``; the feet stand on z = 0 when on the ground. Needs the human model's component names.
    """
    _check_human(model, "athletic")
    rng = np.random.default_rng([seed, 13])
    idx = {name: model.index(name) for name in model.names}
    thigh = float(np.linalg.norm(model.rest[idx["shin_l"], 0:3, 3]))
    shin = float(np.linalg.norm(model.rest[idx["foot_l"], 0:3, 3]))
    foot_low = -float(lowest_points(model, rest_poses(model, np.eye(4))[None])[0])
    heading0, sway = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(0.0, 2.0 * np.pi, 2)
    schedule = athletic_schedule(frames / fps, seed)
    out = np.empty((frames, model.size, 4, 4))
    for f in range(frames):
        t = f / fps
        heading = heading0 + sum(p for move, s, d, p in schedule if move == "spin" and s + d <= t)
        move, begin, duration, parameter = next(m for m in schedule if m[1] <= t < m[1] + m[2])
        u = (t - begin) / duration
        bend = height = turn = hip = knee = lean = 0.0
        arm_forward = arm_side = 0.0
        if move == "hop":
            bend = 0.55 * _bump(u / 0.3) + 0.45 * _bump((u - 0.65) / 0.35)
            height = 0.28 * _arc((u - 0.3) / 0.35)
            arm_forward = 2.0 * _bump((u - 0.15) / 0.7)
        elif move == "kick":
            hip = 1.35 * _bump(u)
            knee = 1.5 * _bump(u) * (1.0 - 0.92 * np.exp(-(((u - 0.5) / 0.12) ** 2)))
            bend = 0.12 * _bump(u)
            lean = 0.3 * _bump(u)
        else:
            bend = 0.4 * _bump(u / 0.25) + 0.35 * _bump((u - 0.7) / 0.3)
            height = 0.15 * _arc((u - 0.3) / 0.4)
            turn = parameter * _ease((u - 0.2) / 0.55)
            arm_side = 0.3 + 0.9 * _bump(u)
        local = {name: np.eye(3) for name in model.names}
        local["pelvis"] = _rz(heading + turn) @ _rx(0.15 * bend)
        local["torso"] = _rx(-lean - 0.1 * bend)
        local["head"] = _rx(0.2 * lean) @ _rz(0.2 * np.sin(2.0 * np.pi * 0.4 * t))
        for side, sign in (("l", 1.0), ("r", -1.0)):
            kicking = move == "kick" and parameter == sign
            local[f"thigh_{side}"] = _rx(-(hip if kicking else 1.15 * bend))
            local[f"shin_{side}"] = _rx(knee if kicking else 2.0 * bend)
            local[f"foot_{side}"] = _rx(0.3 * hip if kicking else -bend)
            counter = move == "kick" and parameter != sign  # the arm opposite the kicking leg swings forward
            swing = arm_forward + (0.9 * _bump(u) if counter else -0.4 * _bump(u) if move == "kick" else 0.0)
            local[f"upperarm_{side}"] = _rx(-swing) @ _ry(-sign * arm_side)
            local[f"forearm_{side}"] = _rx(-(0.3 + 0.8 * _bump(u) if move == "kick" else 0.3 + 0.4 * arm_forward))
        poses = _forward(model, local)
        poses[:, 0, 3] += 0.15 * np.sin(0.5 * t + sway[0])
        poses[:, 1, 3] += 0.15 * np.sin(0.4 * t + sway[1])
        poses[:, 2, 3] += (thigh + shin) * np.cos(bend) + foot_low + height
        out[f] = model.coerce(poses)
    out[:, :, 2, 3] -= np.median(lowest_points(model, out))
    return out


def seated_motion(model: Model, frames: int, *, fps: float = 60.0, seed: int = 0) -> np.ndarray:
    """Model poses (frames, N, 4, 4) of a person seated at a desk: thighs level, shins upright, feet flat.

    The seat is as high as the shin plus the foot; the legs hardly move (a slow knee sway of 0.1 rad).
    The upper body works at the desk: the trunk leans forward 0.05-0.45 rad and twists, the head
    turns and nods, and each arm reaches forward 0.3-1.5 rad and out to the side 0.1-0.7 rad with the
    elbow bending 0.3-1.7 rad, the two arms out of phase. The heading is random (seeded) and then
    sways by 0.2 rad. Built by forward kinematics like :func:`procedural_motion`, then ``Model.coerce``;
    the soles rest on z = 0. Needs the human model's component names.
    """
    _check_human(model, "seated")
    rng = np.random.default_rng([seed, 29])
    idx = {name: model.index(name) for name in model.names}
    shin = float(np.linalg.norm(model.rest[idx["foot_l"], 0:3, 3]))
    foot_low = -float(lowest_points(model, rest_poses(model, np.eye(4))[None])[0])
    heading = rng.uniform(0.0, 2.0 * np.pi)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=8)
    rate = rng.uniform(0.85, 1.15, size=4)
    out = np.empty((frames, model.size, 4, 4))
    for f in range(frames):
        t = f / fps
        wave = np.sin(2.0 * np.pi * np.array([0.3, 0.45, 0.6, 0.25]) * rate * t + phase[:4])
        local = {name: np.eye(3) for name in model.names}
        local["pelvis"] = _rz(heading + 0.2 * np.sin(0.4 * t + phase[4]))
        local["torso"] = _rz(0.3 * wave[3]) @ _rx(-(0.25 + 0.2 * wave[0]))
        local["head"] = _rz(0.5 * np.sin(0.5 * t + phase[5])) @ _rx(0.2 * np.sin(0.7 * t + phase[6]))
        for k, (side, sign) in enumerate((("l", 1.0), ("r", -1.0))):
            sway = 0.1 * np.sin(0.3 * t + phase[7] + np.pi * k)
            local[f"thigh_{side}"] = _rx(-np.pi / 2 + sway) @ _ry(-sign * 0.15)
            local[f"shin_{side}"] = _rx(np.pi / 2 - sway)
            reach, out_side = wave[1 + k], wave[2 - k]
            local[f"upperarm_{side}"] = _rx(-(0.9 + 0.6 * reach)) @ _ry(-sign * (0.4 + 0.3 * out_side))
            local[f"forearm_{side}"] = _rx(-(1.0 - 0.7 * reach))
            local[f"hand_{side}"] = _rx(0.3 * out_side)
        poses = _forward(model, local)
        poses[:, 2, 3] += shin + foot_low
        out[f] = model.coerce(poses)
    out[:, :, 2, 3] -= np.median(lowest_points(model, out))
    return out


def exposure_poses(model: Model, poses: np.ndarray, *, samples: int, shutter: float, shift: float = 0.0) -> np.ndarray:
    """Sub-frame poses (F, S, N, 4, 4) of an exposure of ``shutter`` frame intervals centred on each frame, each
    exposure ``shift`` frames late (a camera whose clock runs behind).

    Sub-frame k of frame f is at time f + shift + shutter (k / (S - 1) - 1/2) (f + shift alone when S = 1)
    (:func:`poses_at`)."""
    offsets = np.zeros(1) if samples == 1 else shutter * (np.arange(samples) / (samples - 1) - 0.5)
    times = np.arange(len(poses))[:, None] + shift + offsets[None]
    return poses_at(model, poses, times.ravel()).reshape(*times.shape, *poses.shape[1:])


def poses_at(model: Model, poses: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The poses (T, N, 4, 4) of the clip ``poses`` (F, N, 4, 4) at the times ``times`` (T,), in frames.

    A whole frame's time gives that frame's poses.  Otherwise, with a and a + 1 the frames about the time t
    (extrapolated past the first and last frames) and s = t - a the fraction of the way from pose a to pose b
    = a + 1, every component turns by R_a exp(s log(R_a^T R_b)), the root moves along the straight line, and the
    others hang on their parents' joints."""
    frames = len(poses)
    out = np.empty((len(times), *poses.shape[1:]))
    for k, time in enumerate(np.asarray(times, float)):
        whole = round(time)
        if frames == 1 or (time == whole and 0 <= whole < frames):
            out[k] = poses[min(max(whole, 0), frames - 1)]
            continue
        a = min(max(int(np.floor(time)), 0), frames - 2)
        s = time - a
        relative = np.einsum("nba,nbc->nac", poses[a, :, 0:3, 0:3], poses[a + 1, :, 0:3, 0:3])
        turn = se3.exp_so3_many(s * se3.log_so3_many(np.ascontiguousarray(relative)))
        rotations = np.einsum("nab,nbc->nac", poses[a, :, 0:3, 0:3], turn)
        root = (1.0 - s) * poses[a, 0, 0:3, 3] + s * poses[a + 1, 0, 0:3, 3]
        out[k] = poses_from_rotations(model, root, rotations)
    return out
