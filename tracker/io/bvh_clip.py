"""BVH motion-capture clips: parsing and forward kinematics.

Conventions (the CMU motion capture database's clips): a joint's local
transform is ``T(offset + position) R`` with ``R`` the product of its rotation
channels in the listed order (intrinsic, degrees), e.g. ``Zrotation Yrotation
Xrotation`` gives ``Rz Ry Rx``; the world is Y up and the character faces +Z
at rest; a joint's rotation orients the bone towards its child's OFFSET.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError
from tracker.tomlfile import read_text


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
    text = read_text(path, "BVH", "give the path of an existing .bvh motion file")
    try:
        return _parse_bvh(text)
    except (ValueError, IndexError) as exc:
        raise TrackerInputError(
            f"{path}: not a valid BVH file ({exc}); give a BVH file with HIERARCHY and MOTION"
        ) from None


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
