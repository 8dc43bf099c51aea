"""An empty furnished room around the capture area, ray-cast from each camera of a rig as its backdrop.

The room is the axis-aligned box ``low`` .. ``high`` (floor at z = 0) holding every camera and the
capture volume. The ray o + t d of a pixel (d = R^T (x, y, 1), so t is the depth in the camera) leaves
a room it starts in through the face it crosses first,

    t_exit = min_a t_a,   t_a = (high_a - o_a) / d_a  if d_a > 0,   (low_a - o_a) / d_a  if d_a < 0,

the floor, the ceiling or one of four walls. Wall w is painted in its own coordinates (s metres along
it, z up; :func:`wall_frame`): a base coat (paint, plaster, wallpaper stripes or bricks), a skirting
board, and decorations, rectangles of (s, z): one door, a window or two (showing the light outside
instead of reflecting the room's) and framed posters. The floor is planks or tiles, with a rug beside the
capture area at times.

Furniture is built of boxes (:class:`tracker.synthetic.props.Box`, ray-cast by
:func:`tracker.synthetic.props.cast_boxes`) with a finish painted in each box's frame (wood grain, book spines, drawer
fronts, fabric, cardboard): bookshelves, cabinets, desks with a screen and a chair, chairs, sofas, stacked cartons,
floor lamps. Pieces are drawn by seeded rejection sampling, against a wall or free-standing, and kept when they
stand inside the room, clear of each other, of the cameras and of the capture volume, and hide no
point of that volume from any camera (the segments from every camera to a lattice of the volume's
points, slab-tested against every box). So the room never hides the body.

Surfaces are shaded like the body (ambient + key max(0, n.l) + fill |n.v|, :mod:`tracker.synthetic.render`),
darkened near the room's edges and around the furniture's feet (a crude ambient occlusion), and the
image is softened like the body's edges.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.camera import Camera
from tracker.geometry import se3
from tracker.raycast import DEFAULT_LIGHT, pixel_rays
from tracker.synthetic.props import Box, box_corners, cast_boxes
from tracker.synthetic.texture import lattice_hash, value_noise

COATS = ("paint", "plaster", "stripes", "bricks")
"""Base coats of a wall."""

FINISHES = ("plain", "wood", "books", "drawers", "fabric", "cardboard")
"""What is painted on a furniture box, in its own frame."""

PIECES = ("bookshelf", "cabinet", "desk", "sofa", "chair", "cartons", "lamp")
"""The kinds of furniture."""

_TANGENT = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
"""Direction of growing s along walls 0..3 (y = low, x = high, y = high, x = low); the inward normal is
the tangent turned a quarter left."""

_WOODS = np.array([[0.22, 0.38, 0.55], [0.15, 0.26, 0.40], [0.45, 0.62, 0.75], [0.10, 0.16, 0.24]])
_PAINTS = np.array([[0.82, 0.86, 0.88], [0.70, 0.80, 0.84], [0.78, 0.80, 0.74], [0.62, 0.74, 0.70], [0.80, 0.76, 0.70]])
_FABRICS = np.array([[0.45, 0.35, 0.25], [0.30, 0.32, 0.34], [0.25, 0.40, 0.30], [0.50, 0.50, 0.55]])
_COLOURS = np.array(
    [
        [0.20, 0.25, 0.65],
        [0.60, 0.35, 0.15],
        [0.20, 0.55, 0.30],
        [0.15, 0.70, 0.85],
        [0.55, 0.20, 0.45],
        [0.85, 0.85, 0.82],
        [0.12, 0.12, 0.14],
        [0.35, 0.50, 0.70],
    ]
)
"""BGR colours for book spines, posters and rugs."""


@dataclass(frozen=True)
class Decor:
    """A rectangle on wall ``wall`` (0..3, :func:`wall_frame`): ``kind`` (door, window or poster), its lower
    left corner ``s0``, ``z0`` and its ``width`` and ``height`` (metres), colours (K, 3) BGR in [0, 1]
    (door leaf and trim; poster frame, mat and pictures) and a ``salt`` for its pattern."""

    wall: int
    kind: str
    s0: float
    z0: float
    width: float
    height: float
    colours: np.ndarray
    salt: int


@dataclass(frozen=True)
class Part:
    """A furniture box with a finish of :data:`FINISHES` painted in its frame and a ``salt`` for it."""

    box: Box
    finish: str
    salt: int


@dataclass(frozen=True)
class Room:
    """The room: corners ``low`` (x0, y0, 0) and ``high`` (x1, y1, height) metres, per wall (4) an albedo
    (4, 3) BGR and a coat of :data:`COATS`; the ceiling's albedo (3,); the floor's kind (planks or tiles),
    its two albedos (2, 3) and its board or tile size (metres); the rug (x0, y0, x1, y1) (empty: none) and
    its colours (2, 3); the wall decorations, the furniture's boxes, the trim albedo (skirting, frames)
    and a ``salt`` for the room's patterns."""

    low: np.ndarray
    high: np.ndarray
    wall_albedo: np.ndarray
    coats: tuple[str, ...]
    ceiling: np.ndarray
    floor: str
    floor_albedo: np.ndarray
    floor_size: float
    rug: np.ndarray
    rug_albedo: np.ndarray
    decor: tuple[Decor, ...]
    parts: tuple[Part, ...]
    trim: np.ndarray
    salt: int


def wall_frame(room: Room, wall: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Wall ``wall``'s origin (3,) (s = 0 on the floor), its tangent (3,) (growing s), its inward unit
    normal (3,) and its length in metres."""
    tangent = _TANGENT[wall]
    corners = ((0, 0), (1, 0), (1, 1), (0, 1))[wall]
    origin = np.array([(room.low, room.high)[corners[0]][0], (room.low, room.high)[corners[1]][1], 0.0])
    size = room.high[0:2] - room.low[0:2]
    return (
        origin,
        np.array([tangent[0], tangent[1], 0.0]),
        np.array([-tangent[1], tangent[0], 0.0]),
        float(size[wall % 2]),
    )


# ---------------------------------------------------------------------------------------------
# Making a room


def make_room(cameras: list[Camera], clear_low, clear_high, *, seed: int = 0) -> Room:
    """A seeded room holding ``cameras`` and the capture volume ``clear_low`` .. ``clear_high`` (3,) metres,
    with walls 0.7-1.9 m behind the outermost camera or the volume, decorations and furniture that
    stands clear of that volume and hides none of it from any camera (see the module)."""
    rng = np.random.default_rng([seed, 11])
    clear_low, clear_high = np.asarray(clear_low, float), np.asarray(clear_high, float)
    centres = np.array([camera.center for camera in cameras])
    xy = np.concatenate([centres[:, 0:2], clear_low[None, 0:2], clear_high[None, 0:2]])
    margin = rng.uniform(0.7, 1.9, 4)
    height = max(rng.uniform(2.5, 3.0), float(centres[:, 2].max()) + 0.3, float(clear_high[2]) + 0.3)
    low = np.array([xy[:, 0].min() - margin[0], xy[:, 1].min() - margin[1], 0.0])
    high = np.array([xy[:, 0].max() + margin[2], xy[:, 1].max() + margin[3], height])
    coats = ["paint", "plaster", "stripes", "paint"]
    rng.shuffle(coats)
    if rng.uniform() < 0.5:
        coats[int(rng.integers(4))] = "bricks"
    paints = _PAINTS[rng.integers(len(_PAINTS), size=2)]
    walls = np.array([paints[w % 2] for w in range(4)])
    walls[[c == "bricks" for c in coats]] = (0.30, 0.38, 0.62)
    floor = "planks" if rng.uniform() < 0.6 else "tiles"
    wood = _WOODS[int(rng.integers(len(_WOODS)))]
    floor_albedo = np.array([wood, wood * 0.8]) if floor == "planks" else np.array([[0.75, 0.74, 0.72], [0.35] * 3])
    rug = np.zeros(0)
    clear = np.concatenate([clear_low[0:2], clear_high[0:2]])
    for _ in range(20 if rng.uniform() < 0.7 else 0):  # a rug beside the capture area, not under the body
        half = rng.uniform([0.7, 0.5], [1.2, 0.8])
        centre = rng.uniform(low[0:2] + half + 0.2, np.maximum(high[0:2] - half - 0.2, low[0:2] + half + 0.21))
        if not _overlap(np.concatenate([centre - half, centre + half]), clear, 0.2):
            rug = np.concatenate([centre - half, centre + half])
            break
    room = Room(
        low=low,
        high=high,
        wall_albedo=walls,
        coats=tuple(coats),
        ceiling=np.array([0.88, 0.90, 0.90]),
        floor=floor,
        floor_albedo=floor_albedo,
        floor_size=float(rng.uniform(0.12, 0.2) if floor == "planks" else rng.uniform(0.3, 0.5)),
        rug=rug,
        rug_albedo=_COLOURS[rng.choice(len(_COLOURS), 2, replace=False)],
        decor=(),
        parts=(),
        trim=np.array([0.90, 0.92, 0.92]) if rng.uniform() < 0.7 else _WOODS[1],
        salt=int(rng.integers(1, 2**62)),
    )
    room = dataclasses.replace(room, decor=_decorate(room, rng))
    return dataclasses.replace(room, parts=_furnish(room, cameras, clear_low, clear_high, rng))


def _decorate(room: Room, rng: np.random.Generator) -> tuple[Decor, ...]:
    """One door, one or two windows and four to eight posters on the walls, none overlapping along a wall."""
    wanted = ["door"] + ["window"] * int(rng.integers(1, 3)) + ["poster"] * int(rng.integers(4, 9))
    placed: list[Decor] = []
    for kind in wanted:
        for _ in range(40):
            wall = int(rng.integers(4))
            length = wall_frame(room, wall)[3]
            if kind == "door":
                width, height, z0 = 0.9 + 0.14, 2.05 + 0.07, 0.0
            elif kind == "window":
                width, height = rng.uniform(0.9, 1.6), rng.uniform(1.0, 1.4)
                z0 = rng.uniform(0.85, max(0.86, room.high[2] - height - 0.25))
            else:
                width, height = rng.uniform(0.35, 1.0), rng.uniform(0.45, 0.9)
                z0 = rng.uniform(1.0, max(1.01, min(1.7, room.high[2] - height - 0.2)))
            if length < width + 0.6:
                continue
            s0 = rng.uniform(0.3, length - 0.3 - width)
            if any(d.wall == wall and s0 < d.s0 + d.width + 0.15 and d.s0 < s0 + width + 0.15 for d in placed):
                continue
            if kind == "door":
                colours = np.array([_WOODS[int(rng.integers(len(_WOODS)))], room.trim])
            elif kind == "window":
                colours = np.array([[0.92, 0.93, 0.93]])
            else:
                frame = [[0.1, 0.1, 0.1], _WOODS[0], [0.9, 0.9, 0.9]][int(rng.integers(3))]
                colours = np.array([frame, [0.93, 0.93, 0.9], *_COLOURS[rng.choice(len(_COLOURS), 4, replace=False)]])
            placed.append(Decor(wall, kind, float(s0), float(z0), float(width), float(height), colours, _salt(rng)))
            break
    return tuple(placed)


def _salt(rng: np.random.Generator) -> int:
    """A salt for a pattern's hash."""
    return int(rng.integers(1, 2**62))


def _bgr(albedo: np.ndarray) -> tuple[float, float, float]:
    """A box's albedo as a tuple, clipped to [0, 1]."""
    b, g, r = np.clip(albedo, 0.0, 1.0)
    return float(b), float(g), float(r)


def _furnish(
    room: Room, cameras: list[Camera], clear_low: np.ndarray, clear_high: np.ndarray, rng: np.random.Generator
) -> tuple[Part, ...]:
    """Seven to eleven pieces of furniture placed by rejection (see the module); fewer when the rig leaves
    no room for them."""
    wanted = int(rng.integers(7, 12))
    kinds = [PIECES[i % len(PIECES)] for i in rng.permutation(4 * len(PIECES))]
    targets = _lattice(clear_low, clear_high)
    centres = np.array([camera.center for camera in cameras])
    taken: list[np.ndarray] = []  # xy boxes (x0, y0, x1, y1) of the pieces kept
    parts: list[Part] = []
    for kind in kinds:
        if len(taken) == wanted:
            break
        for _ in range(60):
            local = _build(kind, rng)
            world_from_piece, wall, span = _place(room, kind, local, rng)
            if wall >= 0 and not _free_span(room, wall, span, tall=max(p[0][2, 3] + p[1][2] for p in local) > 0.85):
                continue
            boxes = [
                Part(Box(world_from_piece @ piece_from_box, half, _bgr(albedo)), finish, _salt(rng))
                for piece_from_box, half, albedo, finish in local
            ]
            footprint = _footprint([p.box for p in boxes])
            if not (np.all(footprint[0:2] >= room.low[0:2]) and np.all(footprint[2:4] <= room.high[0:2])) or _overlap(
                footprint, np.concatenate([clear_low[0:2], clear_high[0:2]]), 0.1
            ):
                continue
            if any(_overlap(footprint, other, 0.1) for other in taken):
                continue
            if any(_overlap(footprint, np.concatenate([c[0:2], c[0:2]]), 0.6) for c in centres):
                continue
            if _hides(boxes, centres, targets):
                continue
            taken.append(footprint)
            parts += boxes
            break
    return tuple(parts)


def _lattice(low: np.ndarray, high: np.ndarray, count: int = 5) -> np.ndarray:
    """A lattice of count^3 points (M, 3) filling the box low .. high, its corners included."""
    axes = [np.linspace(low[a], high[a], count) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _footprint(boxes: list[Box]) -> np.ndarray:
    """The xy bounding box (x0, y0, x1, y1) of ``boxes``' corners."""
    corners = np.concatenate([box_corners(box) for box in boxes])
    return np.concatenate([corners[:, 0:2].min(axis=0), corners[:, 0:2].max(axis=0)])


def _overlap(a: np.ndarray, b: np.ndarray, gap: float) -> bool:
    """Whether xy boxes a and b (x0, y0, x1, y1) come within ``gap`` metres of each other."""
    return bool(np.all(a[0:2] < b[2:4] + gap) and np.all(b[0:2] < a[2:4] + gap))


def _hides(parts: list[Part], eyes: np.ndarray, targets: np.ndarray) -> bool:
    """Whether a box of ``parts`` meets a segment from an eye (E, 3) to a target (M, 3) (slab test, the
    segment's parameter in [0, 1])."""
    start = np.repeat(eyes, len(targets), axis=0)
    end = np.tile(targets, (len(eyes), 1))
    for part in parts:
        box_from_world = np.linalg.inv(part.box.world_from_box)
        origin = start @ box_from_world[0:3, 0:3].T + box_from_world[0:3, 3]
        direction = (end - start) @ box_from_world[0:3, 0:3].T
        with np.errstate(divide="ignore", invalid="ignore"):
            low = (-part.box.half - origin) / direction
            high = (part.box.half - origin) / direction
        near = np.where(np.isnan(low), -np.inf, np.minimum(low, high)).max(axis=1)
        far = np.where(np.isnan(high), np.inf, np.maximum(low, high)).min(axis=1)
        if np.any((near <= far) & (far >= 0.0) & (near <= 1.0)):
            return True
    return False


_Local = tuple[np.ndarray, np.ndarray, np.ndarray, str]
"""A box of a piece: piece_from_box (4, 4), half extents (3,), BGR albedo (3,), finish."""


def _box(centre, half, albedo, finish: str = "plain", yaw: float = 0.0) -> _Local:
    """A box of a piece (origin on the floor under its middle, x across, y backwards, z up)."""
    return se3.from_rotvec((0.0, 0.0, yaw), centre), np.asarray(half, float), np.asarray(albedo, float), finish


def _build(kind: str, rng: np.random.Generator) -> list[_Local]:
    """The boxes of a piece of furniture of ``kind``, sizes drawn from ``rng``; its front faces -y."""
    wood = _WOODS[int(rng.integers(len(_WOODS)))]
    if kind == "bookshelf":
        w, d, h, t = rng.uniform(0.7, 1.2), rng.uniform(0.28, 0.4), rng.uniform(1.5, 2.0), 0.02
        boxes = [
            _box((-w / 2 + t / 2, 0, h / 2), (t / 2, d / 2, h / 2), wood, "wood"),
            _box((w / 2 - t / 2, 0, h / 2), (t / 2, d / 2, h / 2), wood, "wood"),
            _box((0, 0, h - t / 2), (w / 2, d / 2, t / 2), wood, "wood"),
            _box((0, 0, 0.04), (w / 2 - t, d / 2, 0.04), wood, "wood"),
            _box((0, d / 2 - 0.005, h / 2), (w / 2 - t, 0.005, h / 2 - t), wood * 0.7, "plain"),
        ]
        levels = np.linspace(0.08, h - t, int(rng.integers(3, 6)) + 1)
        for bottom, top in zip(levels[:-1], levels[1:]):
            boxes.append(_box((0, 0, bottom + t / 2), (w / 2 - t, d / 2, t / 2), wood, "wood"))
            books = rng.uniform(0.6, 0.9) * (top - bottom - t)
            boxes.append(
                _box((0, 0.01, bottom + t + books / 2), (w / 2 - t - 0.005, d / 2 - 0.03, books / 2), wood, "books")
            )
        return boxes
    if kind == "cabinet":
        w, d, h = rng.uniform(0.7, 1.6), rng.uniform(0.4, 0.5), rng.uniform(0.7, 1.0)
        colour = _WOODS[int(rng.integers(len(_WOODS)))] if rng.uniform() < 0.6 else _PAINTS[int(rng.integers(5))]
        boxes = [
            _box((0, 0, h / 2 - 0.015), (w / 2, d / 2, h / 2 - 0.015), colour, "drawers"),
            _box((0, 0, h - 0.015), (w / 2 + 0.015, d / 2 + 0.015, 0.015), wood, "wood"),
        ]
        if rng.uniform() < 0.7:  # a vase or a box of things on it
            size = rng.uniform([0.08, 0.08, 0.12], [0.15, 0.15, 0.35])
            boxes.append(_box((rng.uniform(-w / 3, w / 3), 0, h + size[2]), size, _COLOURS[int(rng.integers(8))]))
        return boxes
    if kind == "desk":
        w, d, h = rng.uniform(1.1, 1.6), rng.uniform(0.6, 0.75), 0.74
        leg = (0.02, 0.02, (h - 0.03) / 2)
        boxes = [_box((0, 0, h - 0.015), (w / 2, d / 2, 0.015), wood, "wood")]
        boxes += [
            _box((sx * (w / 2 - 0.04), sy * (d / 2 - 0.04), leg[2]), leg, (0.2, 0.2, 0.2))
            for sx in (-1, 1)
            for sy in (-1, 1)
        ]
        boxes += [
            _box((0, d / 2 - 0.12, h + 0.04), (0.03, 0.03, 0.04), (0.1, 0.1, 0.1)),
            _box((0, d / 2 - 0.12, h + 0.25), (rng.uniform(0.22, 0.32), 0.015, 0.17), (0.07, 0.07, 0.08)),
            _box((0, -0.05, h + 0.01), (0.22, 0.07, 0.01), (0.75, 0.75, 0.75)),
        ]
        return boxes + [(se3.from_rotvec((0, 0, np.pi), (0, -d / 2 - 0.15, 0)) @ b[0], *b[1:]) for b in _chair(rng)]
    if kind == "sofa":
        w, d = rng.uniform(1.5, 2.1), rng.uniform(0.8, 0.95)
        fabric = _FABRICS[int(rng.integers(len(_FABRICS)))]
        return [
            _box((0, 0, 0.21), (w / 2, d / 2, 0.21), fabric, "fabric"),
            _box((0, d / 2 - 0.1, 0.45), (w / 2, 0.1, 0.35), fabric, "fabric"),
            _box((-w / 2 + 0.09, 0, 0.31), (0.09, d / 2, 0.31), fabric * 0.9, "fabric"),
            _box((w / 2 - 0.09, 0, 0.31), (0.09, d / 2, 0.31), fabric * 0.9, "fabric"),
            _box((-(w - 0.36) / 4, -0.1, 0.48), ((w - 0.36) / 4 - 0.01, d / 2 - 0.1, 0.06), fabric * 1.1, "fabric"),
            _box(((w - 0.36) / 4, -0.1, 0.48), ((w - 0.36) / 4 - 0.01, d / 2 - 0.1, 0.06), fabric * 1.1, "fabric"),
        ]
    if kind == "chair":
        return _chair(rng)
    if kind == "cartons":
        boxes, z = [], 0.0
        for _ in range(int(rng.integers(1, 4))):
            half = rng.uniform([0.15, 0.15, 0.12], [0.3, 0.25, 0.25])
            boxes.append(_box((0, 0, z + half[2]), half, (0.35, 0.55, 0.68), "cardboard", rng.uniform(-0.3, 0.3)))
            z += 2 * half[2]
        return boxes
    shade = rng.uniform(0.14, 0.22)
    return [
        _box((0, 0, 0.015), (0.15, 0.15, 0.015), (0.15, 0.15, 0.15)),
        _box((0, 0, 0.8), (0.015, 0.015, 0.78), (0.6, 0.6, 0.6)),
        _box((0, 0, 1.55 + shade), (shade, shade, shade), (0.75, 0.88, 0.95), "fabric"),
    ]


def _chair(rng: np.random.Generator) -> list[_Local]:
    """A chair facing -y: four legs, a seat and a backrest."""
    colour = _WOODS[int(rng.integers(len(_WOODS)))] if rng.uniform() < 0.5 else _FABRICS[int(rng.integers(4))]
    legs = [_box((sx * 0.19, sy * 0.18, 0.22), (0.015, 0.015, 0.22), colour) for sx in (-1, 1) for sy in (-1, 1)]
    return legs + [
        _box((0, 0, 0.465), (0.22, 0.21, 0.025), colour, "fabric"),
        _box((0, 0.19, 0.72), (0.22, 0.02, 0.23), colour, "fabric"),
    ]


def _place(room: Room, kind: str, local: list[_Local], rng: np.random.Generator) -> tuple[np.ndarray, int, tuple]:
    """world_from_piece (4, 4) for a piece: its back against a random wall (bookshelves, cabinets, desks,
    sofas; cartons and lamps at times) or free-standing at a random place and heading (chairs), with the
    wall used (-1: none) and the s range it takes there."""
    width = max(abs(p[0][0, 3]) + p[1][0] for p in local)
    depth = max(p[0][1, 3] + p[1][1] for p in local)
    against = kind in ("bookshelf", "cabinet", "desk", "sofa") or (kind != "chair" and rng.uniform() < 0.5)
    if not against:
        at = rng.uniform(room.low[0:2] + 0.3, room.high[0:2] - 0.3)
        return se3.from_rotvec((0.0, 0.0, rng.uniform(-np.pi, np.pi)), (*at, 0.0)), -1, ()
    wall = int(rng.integers(4))
    origin, tangent, normal, length = wall_frame(room, wall)
    s = rng.uniform(width + 0.05, max(width + 0.06, length - width - 0.05))
    rotation = np.stack([tangent, -normal, (0.0, 0.0, 1.0)], axis=1)
    place = origin + s * tangent + (depth + rng.uniform(0.01, 0.06)) * normal
    return se3.from_rotation(rotation, place), wall, (s - width, s + width)


def _free_span(room: Room, wall: int, span: tuple, tall: bool) -> bool:
    """Whether the s range ``span`` of ``wall`` is clear of its door (and of its windows, for a tall piece)."""
    return not any(
        d.wall == wall
        and (d.kind == "door" or (tall and d.kind == "window"))
        and span[0] < d.s0 + d.width + 0.1
        and d.s0 - 0.1 < span[1]
        for d in room.decor
    )


# ---------------------------------------------------------------------------------------------
# Rendering a room


def room_backdrop(
    room: Room,
    camera: Camera,
    *,
    light=DEFAULT_LIGHT,
    ambient: float = 0.35,
    key: float = 0.45,
    fill: float = 0.3,
    blur: float = 0.7,
) -> np.ndarray:
    """The room seen by ``camera`` from inside it: a BGR image (H, W, 3) uint8 (see the module); ``light``
    the direction towards the key light in world, the shading's weights as the body's, ``blur`` px."""
    w, h = camera.size
    xy = pixel_rays(camera).reshape(-1, 2)
    direction = np.concatenate([xy, np.ones((len(xy), 1))], axis=1) @ camera.rotation  # world, camera depth 1
    origin = camera.center
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(direction > 0.0, room.high, room.low)
        steps = np.where(direction != 0.0, (bound - origin) / direction, np.inf)
    axis = steps.argmin(axis=1)
    depth = steps[np.arange(len(xy)), axis]
    point = origin + depth[:, None] * direction
    normal = np.zeros_like(point)
    normal[np.arange(len(xy)), axis] = -np.sign(direction[np.arange(len(xy)), axis])
    albedo, glow = _shell_colours(room, point, axis, direction)
    ceiling = (axis == 2) & (direction[:, 2] > 0.0)
    occlusion = _shell_occlusion(room, point, axis)
    if room.parts:
        near, index, box_normal = cast_boxes([p.box for p in room.parts], camera, xy)
        inside = index >= 0
        albedo[inside] = _part_colours(room, index[inside], point=origin + near[inside, None] * direction[inside])
        normal[inside] = box_normal[inside] @ camera.rotation
        glow[inside] = ceiling[inside] = False
        occlusion[inside] = 1.0
    light = np.asarray(light, float) / np.linalg.norm(light)
    view = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    shade = ambient + key * np.maximum(normal @ light, 0.0) + fill * np.abs(np.sum(normal * view, axis=1))
    shade = np.where(glow, 1.0, shade * occlusion)
    shade[ceiling] = np.maximum(shade[ceiling], 0.8)  # lit from below by the room's lamps
    image: np.ndarray = (255.0 * albedo * shade[:, None]).reshape(h, w, 3).astype(np.float32)
    if blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur, borderType=cv2.BORDER_REPLICATE)
    return np.clip(image + 0.5, 0.0, 255.0).astype(np.uint8)


def _salts(salt: int, count: int) -> np.ndarray:
    """``salt`` (M,) uint64 for ``count`` points."""
    return np.full(count, salt % 2**64, dtype=np.uint64)


def _noise(points: np.ndarray, cell, salt: int) -> np.ndarray:
    """Value noise in [0, 1] (M,) at points (M, 3) metres, lattice ``cell`` metres (scalar or per axis (3,))."""
    return value_noise(points / np.asarray(cell, float), _salts(salt, len(points)))


def _cell_hash(cells: np.ndarray, salt: int, lane: int = 0) -> np.ndarray:
    """Uniform numbers (M,) per integer cell (M, 2) or (M, 3)."""
    cells = np.concatenate([cells, np.zeros((len(cells), 3 - cells.shape[1]))], axis=1) if cells.shape[1] < 3 else cells
    return lattice_hash(np.floor(cells), _salts(salt, len(cells)), lane)


def _shell_colours(
    room: Room, point: np.ndarray, axis: np.ndarray, direction: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """BGR albedo (M, 3) of the room's shell at ``point`` (M, 3) on the face of ``axis`` (M,) crossed along
    ``direction`` (M, 3), and whether each point shows the light outside a window (M,) bool."""
    albedo = np.zeros_like(point)
    glow = np.zeros(len(point), bool)
    floor = (axis == 2) & (direction[:, 2] < 0.0)
    albedo[floor] = _floor_colours(room, point[floor])
    albedo[(axis == 2) & ~floor] = room.ceiling
    for wall in range(4):
        across = 1 - wall % 2  # the axis the wall stops: y for walls 0 and 2, x for 1 and 3
        on = (axis == across) & ((direction[:, across] < 0.0) == (wall in (0, 3)))
        origin, tangent, _, length = wall_frame(room, wall)
        s = (point[on] - origin) @ tangent
        albedo[on], glow[on] = _wall_colours(room, wall, s, point[on, 2], length)
    return albedo, glow


def _floor_colours(room: Room, point: np.ndarray) -> np.ndarray:
    """BGR albedo (M, 3) of the floor at ``point`` (M, 3): planks with seams and grain, or tiles with
    grout; the rug over them."""
    size, salt = room.floor_size, room.salt
    if room.floor == "planks":
        row = np.floor(point[:, 1] / size)
        along = point[:, 0] + 3.0 * _cell_hash(row[:, None], salt, 1)
        plank = np.floor(along / 1.6)
        tone = 0.8 + 0.35 * _cell_hash(np.stack([row, plank], axis=1), salt, 2)
        grain = _noise(point, (0.4, 0.012, 1.0), salt)
        seam = (np.abs(point[:, 1] / size - np.round(point[:, 1] / size)) * size < 0.005) | (
            np.abs(along / 1.6 - np.round(along / 1.6)) * 1.6 < 0.005
        )
        colour = room.floor_albedo[0] * (tone * (0.85 + 0.3 * grain))[:, None]
        colour[seam] = room.floor_albedo[1] * 0.5
    else:
        tile = np.floor(point[:, 0:2] / size)
        tone = 0.9 + 0.15 * _cell_hash(tile, salt, 3)
        colour = room.floor_albedo[0] * (tone * (0.95 + 0.1 * _noise(point, 0.05, salt)))[:, None]
        grout = np.any(np.abs(point[:, 0:2] / size - np.round(point[:, 0:2] / size)) * size < 0.006, axis=1)
        colour[grout] = room.floor_albedo[1]
    if len(room.rug):
        lo, hi = room.rug[0:2], room.rug[2:4]
        on = np.all((point[:, 0:2] >= lo) & (point[:, 0:2] <= hi), axis=1)
        edge = np.minimum(point[on, 0:2] - lo, hi - point[on, 0:2]).min(axis=1)
        band = (edge < 0.12) | ((edge > 0.2) & (edge < 0.24))
        pattern = np.any((point[on, 0:2] % 0.3) < 0.04, axis=1)  # a plaid of bands 4 cm wide
        rug = np.where((band | pattern)[:, None], room.rug_albedo[1], room.rug_albedo[0])
        colour[on] = rug * (0.9 + 0.2 * _noise(point[on], 0.02, salt + 1))[:, None]
    return colour


def _wall_colours(room: Room, wall: int, s: np.ndarray, z: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """BGR albedo (M, 3) of wall ``wall`` at (s, z) (M,) metres, and whether each point is a window's glass."""
    salt = room.salt + 17 * (wall + 1)
    at = np.stack([s, z, np.zeros_like(s)], axis=1)
    base = room.wall_albedo[wall]
    coat = room.coats[wall]
    if coat == "bricks":
        row = np.floor(z / 0.075)
        brick = np.floor(s / 0.225 + 0.5 * (row % 2))
        tone = 0.8 + 0.35 * _cell_hash(np.stack([row, brick], axis=1), salt)
        colour = base * tone[:, None]
        mortar = (z - 0.075 * row < 0.01) | ((s / 0.225 + 0.5 * (row % 2) - brick) * 0.225 < 0.01)
        colour[mortar] = (0.70, 0.72, 0.74)
    elif coat == "stripes":
        period = 0.08 + 0.15 * _cell_hash(np.zeros((1, 3)), salt)[0]
        colour = base * np.where(np.sin(2.0 * np.pi * s / period) > 0.0, 1.0, 0.86)[:, None]
    else:
        amount = 0.12 if coat == "plaster" else 0.04
        colour = base * (1.0 - amount + 2.0 * amount * _noise(at, 0.25, salt))[:, None]
    colour[z < 0.08] = room.trim
    glow = np.zeros(len(s), bool)
    for decor in room.decor:
        if decor.wall != wall:
            continue
        u, v = s - decor.s0, z - decor.z0
        on = (u >= 0.0) & (u <= decor.width) & (v >= 0.0) & (v <= decor.height)
        if on.any():
            colour[on], glow[on] = _decor_colours(decor, u[on], v[on])
    return colour, glow


def _decor_colours(decor: Decor, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """BGR albedo (M, 3) of a decoration at (u, v) (M,) metres from its lower left corner, and whether
    each point glows (a window's glass)."""
    w, h = decor.width, decor.height
    edge = np.minimum(np.minimum(u, w - u), np.minimum(v, h - v))
    glow = np.zeros(len(u), bool)
    if decor.kind == "door":
        leaf, trim = decor.colours
        side = np.minimum(u, w - u)  # from the nearer side of the frame
        colour = np.where(((side < 0.07) | (v > h - 0.07))[:, None], trim, leaf)
        for bottom, top in ((0.22, 0.95), (1.15, 1.9)):  # two recessed panels, outlined in shadow
            ring = np.minimum(np.minimum(side - 0.19, v - bottom), top - v)
            colour[(ring >= 0.0) & (ring < 0.015)] = leaf * 0.55
        handle = (np.abs(u - (w - 0.2)) < 0.06) & (np.abs(v - 1.0) < 0.015)
        colour[handle] = (0.65, 0.65, 0.65)
        return colour, glow
    if decor.kind == "window":
        glass = edge >= 0.06
        bars = (np.abs(u - w / 2) < 0.025) | (np.abs(v - 0.6 * h) < 0.025)
        glass &= ~bars
        colour = np.tile(decor.colours[0], (len(u), 1))
        horizon = 0.3 * h + 0.12 * h * _noise(np.stack([u, np.zeros_like(u), np.zeros_like(u)], 1), 0.15, decor.salt)
        height = np.clip((v - horizon) / h, 0.0, 1.0)[:, None]
        sky = (1.0 - height) * np.array([0.98, 0.95, 0.90]) + height * np.array([0.95, 0.80, 0.60])
        trees = (
            np.array([0.30, 0.45, 0.35])
            * (0.8 + 0.4 * _noise(np.stack([u, v, np.zeros_like(u)], 1), 0.05, decor.salt))[:, None]
        )
        colour[glass] = np.where((v < horizon)[glass, None], trees[glass], sky[glass])
        glow[glass] = True
        return colour, glow
    frame, mat, *paint = decor.colours
    colour = np.tile(mat, (len(u), 1))
    colour[edge < 0.025] = frame
    picture = edge >= 0.025 + 0.04
    pu, pv = u[picture] - 0.065, v[picture] - 0.065
    style = decor.salt % 3
    if style == 0:  # blocks of colour with dark lines between them
        cells = np.stack([np.floor(pu / 0.15), np.floor(pv / 0.12)], axis=1)
        pick = np.floor(len(paint) * _cell_hash(cells, decor.salt)).astype(int)
        colour[picture] = np.asarray(paint)[pick]
        line = ((pu % 0.15) < 0.008) | ((pv % 0.12) < 0.008)
        colour[np.flatnonzero(picture)[line]] = (0.08, 0.08, 0.08)
    elif style == 1:  # bands under a wavy line: a landscape
        ridge = 0.4 * (h - 0.13) * (1.0 + 0.3 * np.sin(9.0 * pu + decor.salt % 7))
        colour[picture] = np.where(
            (pv < ridge)[:, None], paint[0], np.where((pv < 1.5 * ridge)[:, None], paint[1], paint[2])
        )
    else:  # a notice: rows of dark strokes on the mat
        rows = (pv % 0.035) < 0.012
        strokes = _cell_hash(np.stack([np.floor(pu / 0.06), np.floor(pv / 0.035)], axis=1), decor.salt) < 0.75
        ink = np.flatnonzero(picture)[rows & strokes & (pv < (h - 0.13) * 0.85)]
        colour[ink] = (0.15, 0.15, 0.15)
        colour[np.flatnonzero(picture)[pv >= (h - 0.13) * 0.85]] = paint[0]
    return colour, glow


def _shell_occlusion(room: Room, point: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """A factor (M,) in (0, 1] darkening the shell near the room's edges and around furniture on the floor."""
    gaps = np.minimum(point - room.low, room.high - point)
    gaps[np.arange(len(point)), axis] = np.inf  # the distance to the face itself
    factor = 1.0 - 0.3 * np.exp(-gaps.min(axis=1) / 0.25)
    floor = (axis == 2) & (point[:, 2] < 0.5 * room.high[2])
    for part in room.parts:
        box = part.box
        if box.world_from_box[2, 3] - box.half[2] > 0.02:  # not standing on the floor
            continue
        inverse = np.linalg.inv(box.world_from_box)
        local = point[floor] @ inverse[0:3, 0:3].T + inverse[0:3, 3]
        reach = np.linalg.norm(np.maximum(np.abs(local[:, 0:2]) - box.half[0:2], 0.0), axis=1)
        factor[floor] *= 1.0 - 0.45 * np.exp(-reach / 0.08)
    return factor


def _part_colours(room: Room, index: np.ndarray, point: np.ndarray) -> np.ndarray:
    """BGR albedo (M, 3) of the furniture boxes ``index`` (M,) at world points (M, 3), by their finish."""
    colour = np.zeros((len(index), 3))
    for k in np.unique(index):
        part = room.parts[k]
        sel = index == k
        inverse = np.linalg.inv(part.box.world_from_box)
        local = point[sel] @ inverse[0:3, 0:3].T + inverse[0:3, 3]
        colour[sel] = _finish(part, local)
    return colour


def _finish(part: Part, local: np.ndarray) -> np.ndarray:
    """BGR albedo (M, 3) of a furniture box at points (M, 3) in its frame (its centre at the origin)."""
    albedo, half, salt = np.asarray(part.box.albedo), part.box.half, part.salt
    if part.finish == "wood":
        long = int(np.argmax(half))
        cell = np.full(3, 0.01)
        cell[long] = 0.3
        return albedo * (0.85 + 0.3 * _noise(local, cell, salt))[:, None]
    if part.finish == "fabric":
        return albedo * (0.9 + 0.2 * _noise(local, 0.03, salt))[:, None]
    if part.finish == "books":
        spine = (local[:, 0] + half[0]) / 0.03
        tone = _cell_hash(np.floor(spine)[:, None], salt, 1)
        colour = _COLOURS[np.floor(len(_COLOURS) * tone).astype(int)] * 0.8
        tall = 0.6 + 0.4 * _cell_hash(np.floor(spine)[:, None], salt, 2)
        colour[(spine - np.floor(spine)) < 0.1] *= 0.5
        gap = (local[:, 2] + half[2] > tall * 2.0 * half[2]) | (_cell_hash(np.floor(spine)[:, None], salt, 3) < 0.08)
        colour[gap] = albedo * 0.25
        return colour
    if part.finish == "drawers":
        colour = np.tile(albedo, (len(local), 1))
        rows = 3 if half[2] > 0.3 else 2
        level = (local[:, 2] + half[2]) / (2.0 * half[2]) * rows
        split = np.abs(level - np.round(level)) * 2.0 * half[2] / rows < 0.006
        split |= (half[0] > 0.5) & (np.abs(local[:, 0]) < 0.006)
        middle = (np.floor(level) + 0.5) * 2.0 * half[2] / rows - half[2]
        columns = np.where(half[0] > 0.5, np.sign(local[:, 0]) * half[0] / 2, 0.0)
        handle = (np.abs(local[:, 0] - columns) < 0.07) & (np.abs(local[:, 2] - middle) < 0.012)
        colour[split] = albedo * 0.4
        colour[handle] = (0.2, 0.2, 0.2)
        return colour
    if part.finish == "cardboard":
        colour = np.tile(albedo, (len(local), 1)) * (0.92 + 0.16 * _noise(local, 0.05, salt))[:, None]
        colour[(np.abs(local[:, 0]) < 0.025) & (local[:, 2] > half[2] - 0.1)] = (0.55, 0.65, 0.72)
        return colour
    return np.tile(albedo, (len(local), 1))
