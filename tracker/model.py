"""Body models: a tree of rigid components made of clipped quadrics (formats.md).

A component's frame has its origin at its joint with its parent.  The rest
transform ``T0`` maps child coordinates to parent coordinates,
``p_parent = R(rest) p_child + at``.  Components are stored in breadth-first
order from the root, so ``parent[i] < i``; the flat arrays of
:class:`Model` feed the numba kernels directly.
"""

from __future__ import annotations

import os
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomli_w

from tracker.atomic import atomic_write
from tracker.chain import JOINT_TYPES, coerce_kernel, constraint_rows, pack_constraints, row_projectors
from tracker.errors import TrackerInputError
from tracker.geometry import quadric, se3
from tracker.tomlfile import read_toml

SHAPES = ("sphere", "ellipsoid", "cylinder", "cone")


@dataclass(frozen=True)
class Model:
    """A compiled body model.

    Per component (N): ``names``, ``parent`` (-1 for the root), ``joint_type``
    (codes of :mod:`tracker.chain`), ``rest`` (N,4,4) parent-from-child rest
    transforms ``T0``, ``axis`` (N,3), constraint rows ``constraint`` (N,6,6)
    zero-padded with ``constraint_rows`` (N,) rows each, their row-space projectors
    ``constraint_projector`` (N,6,6) (:func:`tracker.chain.row_projectors`, for coercion), and the joint limits
    ``lower``/``upper`` (N,) of hinges (radians) and slides (metres), the largest
    rotation from rest of a ball joint in ``upper``, and a ball's largest turn about its child's z axis (along
    a limb's bone) in ``twist``; +-inf if none.
    Per quadric (Q): ``quadric`` (Q,4,4) surfaces and ``clip`` (Q,4,4) clipping
    quadrics in their component's frame, ``quadric_component`` (Q,), and
    ``quadric_shape`` names for drawing; ``quadric_params`` keeps the TOML keys.
    """

    name: str
    names: tuple[str, ...]
    parent: np.ndarray
    joint_type: np.ndarray
    rest: np.ndarray
    axis: np.ndarray
    constraint: np.ndarray
    constraint_rows: np.ndarray
    constraint_projector: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    twist: np.ndarray
    quadric: np.ndarray
    clip: np.ndarray
    quadric_component: np.ndarray
    quadric_bound: np.ndarray
    quadric_shape: tuple[str, ...]
    quadric_params: tuple[dict, ...]

    @property
    def size(self) -> int:
        return len(self.names)

    def coerce(self, poses: np.ndarray) -> np.ndarray:
        """The poses with every joint repaired exactly and within its limits (chain.coerce_kernel)."""
        return coerce_kernel(
            np.ascontiguousarray(poses, dtype=np.float64),
            self.parent,
            self.rest,
            self.constraint_projector,
            self.constraint_rows,
            self.joint_type,
            self.axis,
            self.lower,
            self.upper,
            self.twist,
        )

    def index(self, name: str) -> int:
        return self.names.index(name)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joints are named after the child component; the root's origin comes first."""
        return self.names


def _vector(value, length: int, where: str) -> np.ndarray:
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        out = np.zeros(0)
    if out.shape != (length,) or not np.all(np.isfinite(out)):
        raise ValueError(f"{where} must be {length} finite numbers, got {value!r}")
    return out


def _positive(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise ValueError(
            f"{where} must be a positive number, got {float(value) if isinstance(value, float) else value!r}"
        )
    return float(value)


def _build_quadric(spec: dict, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface, clipping quadric and bounding sphere of one ``[[component.quadric]]`` table."""
    shape = spec.get("shape")
    if shape not in SHAPES:
        raise ValueError(f"{where}: shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    if shape in ("sphere", "ellipsoid"):
        center = _vector(spec.get("center", [0.0, 0.0, 0.0]), 3, f"{where}.center")
        if shape == "sphere":
            radii = np.full(3, _positive(spec.get("radius"), f"{where}.radius"))
        else:
            radii = np.array([_positive(r, f"{where}.radii") for r in _vector(spec.get("radii"), 3, f"{where}.radii")])
        surface = quadric.ellipsoid(center, radii)
        bound = np.append(center, radii.max())
        if "clip" in spec:
            zmin, zmax = _vector(spec["clip"], 2, f"{where}.clip")
            if zmin >= zmax:
                raise ValueError(f"{where}.clip must be [zmin, zmax] with zmin < zmax")
            return surface, quadric.slab([0.0, 0.0, 1.0], center[2] + zmin, center[2] + zmax), bound
        return surface, quadric.KEEP_ALL.copy(), bound
    start = _vector(spec.get("from"), 3, f"{where}.from")
    end = _vector(spec.get("to"), 3, f"{where}.to")
    axis = end - start
    if np.linalg.norm(axis) < 1e-9:
        raise ValueError(f"{where}: `from` and `to` must differ")
    if shape == "cylinder":
        r0 = r1 = _positive(spec.get("radius"), f"{where}.radius")
    else:
        radii = _vector(spec.get("radii"), 2, f"{where}.radii")
        r0, r1 = (_positive(r, f"{where}.radii") for r in radii)
    direction = axis / np.linalg.norm(axis)
    bound = np.append(0.5 * (start + end), np.hypot(0.5 * np.linalg.norm(axis), max(r0, r1)))
    return (
        quadric.cone(start, end, radius_start=r0, radius_end=r1),
        quadric.slab(direction, direction @ start, direction @ end),
        bound,
    )


def _breadth_first(names: list[str], parents: list[str], path: Path) -> list[int]:
    """Order components root first so that parent[i] < i; reject cycles and strays."""
    roots = [i for i, p in enumerate(parents) if p == ""]
    if len(roots) != 1:
        raise TrackerInputError(
            f'{path}: a model needs exactly one root component (parent = ""), found {len(roots)}; fix the `parent` keys'
        )
    for name, p in zip(names, parents):
        if p and p not in names:
            raise TrackerInputError(f"{path}: component {name!r} names an unknown parent {p!r}; fix its `parent` key")
    children: dict[str, list[int]] = {n: [] for n in names}
    for i, p in enumerate(parents):
        if p:
            children[p].append(i)
    order, queue = [], deque(roots)
    while queue:
        i = queue.popleft()
        order.append(i)
        queue.extend(children[names[i]])
    if len(order) != len(names):
        stray = sorted(set(names) - {names[i] for i in order})
        raise TrackerInputError(
            f"{path}: components {', '.join(stray)} form a cycle (each is its own ancestor); fix their `parent` keys"
        )
    return order


def load_model(path: str | os.PathLike) -> Model:
    """Load and validate a body model TOML (formats.md, "Body model")."""
    path = Path(path)
    return model_from_dict(read_toml(path, "model", "pass --model with an existing models/*.toml"), path)


def save_model(path: str | os.PathLike, document: dict, comment: str = "") -> None:
    """Write a model TOML document (parsed) to ``path`` atomically, after ``comment`` (lines, each written as a
    ``#`` comment): an ordinary model file that :func:`load_model` reads back."""
    header = "".join(f"# {line}\n" if line else "#\n" for line in comment.splitlines())
    text = (header + ("\n" if header else "") + tomli_w.dumps(document)).encode()
    atomic_write(path, lambda file: file.write(text))


def model_from_dict(data: dict, path: str | Path = "<model>") -> Model:
    """Compile a parsed model TOML into a :class:`Model`."""
    path = Path(path)
    specs = data.get("component")
    if not isinstance(specs, list) or not specs:
        raise TrackerInputError(f"{path}: no [[component]] tables; a model needs at least a root component")
    if not all(isinstance(c, dict) for c in specs):
        raise TrackerInputError(f"{path}: every `component` entry must be a [[component]] table; fix the file")
    names = [str(c.get("name", "")) for c in specs]
    if any(not n for n in names) or len(set(names)) != len(names):
        raise TrackerInputError(f"{path}: every component needs a unique non-empty `name`; fix the names")
    parents = [str(c.get("parent", "")) for c in specs]
    order = _breadth_first(names, parents, path)
    ordered_names = tuple(names[i] for i in order)
    parent, joint_type, rest, axis, rows, limits, twists = [], [], [], [], [], [], []
    quadrics, clips, bounds, owners, shapes, params = [], [], [], [], [], []
    for new_index, i in enumerate(order):
        spec = specs[i]
        where = f"component {names[i]!r}"
        try:
            is_root = parents[i] == ""
            joint = spec.get("joint", "free" if is_root else "ball")
            if joint not in JOINT_TYPES:
                raise ValueError(f"joint must be one of {', '.join(JOINT_TYPES)}, got {joint!r}")
            if is_root and joint != "free":
                raise ValueError("the root's joint must be `free`")
            at = _vector(spec.get("at", [0.0, 0.0, 0.0]), 3, f"{where}.at")
            rest_rot = _vector(spec.get("rest", [0.0, 0.0, 0.0]), 3, f"{where}.rest")
            direction = _vector(spec.get("axis", [1.0, 0.0, 0.0]), 3, f"{where}.axis")
            if np.linalg.norm(direction) < 1e-9:
                raise ValueError(f"{where}.axis must not be zero")
            direction = direction / np.linalg.norm(direction)
            limit = (-np.inf, np.inf)
            if "max_angle" in spec:
                if joint != "ball":
                    raise ValueError(f"{where}.max_angle applies to ball joints only")
                limit = (0.0, _positive(spec["max_angle"], f"{where}.max_angle"))
            twist = np.inf
            if "max_twist" in spec:
                if joint != "ball":
                    raise ValueError(f"{where}.max_twist applies to ball joints only")
                twist = _positive(spec["max_twist"], f"{where}.max_twist")
            if "limits" in spec:
                if joint not in ("hinge", "slide"):
                    raise ValueError(f"{where}.limits apply to hinge and slide joints only")
                limit = tuple(_vector(spec["limits"], 2, f"{where}.limits"))
                if limit[0] > limit[1]:
                    raise ValueError(f"{where}.limits must be [lower, upper] with lower <= upper")
            q_specs = spec.get("quadric", [])
            if not isinstance(q_specs, list) or not all(isinstance(q, dict) for q in q_specs):
                raise ValueError(f"{where}.quadric must be an array of tables")
            for k, q_spec in enumerate(q_specs):
                surface, clip, bound = _build_quadric(q_spec, f"{where}.quadric[{k}]")
                quadrics.append(surface)
                clips.append(clip)
                bounds.append(bound)
                owners.append(new_index)
                shapes.append(q_spec["shape"])
                params.append(dict(q_spec))
        except ValueError as exc:
            raise TrackerInputError(f"{path}: {exc}; fix the model file") from None
        parent.append(-1 if is_root else ordered_names.index(parents[i]))
        joint_type.append(JOINT_TYPES[joint])
        rest.append(se3.from_rotvec(rest_rot, at))
        axis.append(direction)
        limits.append(limit)
        twists.append(twist)
        rows.append(constraint_rows(JOINT_TYPES[joint], np.zeros(3), direction))
    if not quadrics:
        raise TrackerInputError(
            f"{path}: the model has no quadrics, so nothing can be seen; add [[component.quadric]] tables"
        )
    constraint, n_rows = pack_constraints(rows)
    return Model(
        name=str(data.get("name", path.stem)),
        names=ordered_names,
        parent=np.asarray(parent, dtype=np.int64),
        joint_type=np.asarray(joint_type, dtype=np.int64),
        rest=np.asarray(rest),
        axis=np.asarray(axis),
        constraint=constraint,
        constraint_rows=n_rows,
        constraint_projector=row_projectors(constraint, n_rows),
        lower=np.array([lo for lo, _ in limits]),
        upper=np.array([hi for _, hi in limits]),
        twist=np.array(twists, dtype=float),
        quadric=np.asarray(quadrics),
        clip=np.asarray(clips),
        quadric_component=np.asarray(owners, dtype=np.int64),
        quadric_bound=np.asarray(bounds),
        quadric_shape=tuple(shapes),
        quadric_params=tuple(params),
    )


def with_descendants(parent: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """The components (N,) bool ``chosen`` and every one below them, in a tree of ``parent`` indices (N,) in
    breadth-first order (a parent comes before its children, the root's parent is -1)."""
    out = np.array(chosen, bool)
    for i in range(len(parent)):
        if parent[i] >= 0 and out[parent[i]]:
            out[i] = True
    return out


def rest_poses(model: Model, root: np.ndarray) -> np.ndarray:
    """World poses with every joint at rest: E_i = E_parent T0_i, E_root = ``root``."""
    poses = np.empty((model.size, 4, 4))
    poses[0] = root
    for i in range(1, model.size):
        poses[i] = poses[model.parent[i]] @ model.rest[i]
    return poses


def poses_from_rotations(model: Model, root_translation: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """World poses from world-from-component rotations (N,3,3) and the root's position.

    Each non-root origin hangs on its parent's joint: t_i = E_parent (at_i; 1).
    """
    poses = np.zeros((model.size, 4, 4))
    poses[:, 3, 3] = 1.0
    poses[:, 0:3, 0:3] = rotations
    poses[0, 0:3, 3] = root_translation
    for i in range(1, model.size):
        p = model.parent[i]
        poses[i, 0:3, 3] = poses[p, 0:3, 0:3] @ model.rest[i, 0:3, 3] + poses[p, 0:3, 3]
    return poses


def joint_centres(poses: np.ndarray) -> np.ndarray:
    """Joint centres in world (..., N, 3): each component's origin (joints are named after children)."""
    return poses[..., 0:3, 3].copy()
