"""3-D point data (``tracker points``): a body of deformable superquadric parts fitted to labelled
markers and carried from frame to frame (docs/method-physics.md, sections 3-4;
the paper's human-arm experiment).

A *points model* (TOML) names the parts, the markers on each part and each part's parent::

    name = "right arm"
    mesh = [11, 11]                  # node rings and longitudes of every part (optional)
    [[part]]
    name = "upper_arm"
    markers = ["DELT", "ARMl", "ARMm", "EPICl", "EPICm"]
    [[part]]
    name = "forearm"
    parent = "upper_arm"             # joined to it by a point-to-point constraint
    joint = "elbow"                  # the joint's name in poses.npz (default: the part's name)
    markers = ["LARMm", "LARMl", "STYLr", "STYLu"]

Marker names match a file's full labels or the part after a ``subject:`` prefix
(:meth:`tracker.io.markers.Markers.index`).

The fit (:func:`first_fit`, :func:`track`) is the first-order constrained dynamic fitting of
``body.fit_frame`` with data forces from each marker to the nearest node of its own part (eq 16):

1. the start frame is the first in which every part has at least ``MIN_MARKERS`` markers seen;
2. each part starts from the centroid and central moments of its markers
   (``fitting.initial_part``), its long axis along its z;
3. every joint joins the child's end (pole) nearest to its parent to the parent's node nearest
   to that end (:func:`joint_to_parent`), and the body is fitted (pose and global shape) with
   the joints held by Baumgarte stabilisation (section 4);
4. every later frame starts from the previous fit and moves at the tracking level: ``rigid``
   (pose only, the shapes of step 3 kept), ``global`` (pose and the 10 free global shape
   parameters) or ``local`` (also the nodal displacements, under the membrane), by

   - ``first-order`` fitting (the default), ``steps`` Euler steps of D qdot = f_q + G^T f_c
     per frame (``body.fit_frame``): no momentum, so a part whose markers vanish stops;
   - or ``second-order`` dynamics (section 3, eq 11, and section 4): each part has a
     unit mass lumped on its nodes, M qddot + D qdot = f_q + G^T f_c is integrated over the
     time between the frames by semi-implicit Euler sub-steps below half the stable step
     (``body.second_order_limit``), and the velocities carry over to the next frame, so a part
     whose markers vanish keeps moving and is caught again when they return; D = alpha_p M per
     part with alpha_p = 2 sqrt(n_p / (sigma^2 m)), n_p its markers seen in the frame: critical
     damping of its translation under their pull (stiffness n_p / sigma^2, mass m), so it follows
     them without ringing, and no damping, so pure coasting, for a part with no marker seen.
     It is faster on the real marker files, but lags fast limbs (walking feet at 200 Hz) and
     carries the fit's noisy velocities through gaps, so its residuals are larger
     (measurements: docs/physics.md).

A marker that is not seen in a frame (NaN) exerts no force; a part with no marker seen is
carried by its joints (and its momentum) and reported as uncertain; in a frame with no marker
seen at all the first-order body stays where it was and the second-order one coasts.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError
from tracker.physics import body as bd
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq
from tracker.status import LOST, TRACKED, UNCERTAIN
from tracker.tomlfile import read_toml

MIN_MARKERS = 3
"""Markers a part needs in the start frame: its moments need three non-collinear points."""

LEVELS = {"rigid": bd.RIGID, "global": bd.GLOBAL, "local": bd.LOCAL}
DYNAMICS = ("first-order", "second-order")

MASS = 1.0
"""Mass of every part (second-order tracking), lumped equally on its nodes."""

STEP_FRACTION = 0.5
"""Second-order sub-steps are at most this share of the stable step."""

DECAY = 0.5
"""Second-order Baumgarte rate a = DECAY / dt (stable for a dt < 1, ``body.second_order_limit``):
on a bending arm at 100 Hz the joints hold to 31 micrometres, against 108 with 0.2."""


@dataclass(frozen=True)
class PointsModel:
    """Part names, marker names per part, parent index per part (-1 for none), joint names of the
    parts that have a parent, and the node mesh every part uses."""

    path: Path
    name: str
    parts: tuple[str, ...]
    markers: tuple[tuple[str, ...], ...]
    parents: tuple[int, ...]
    joint_names: tuple[str, ...]
    mesh: sq.Mesh

    @functools.cached_property
    def marker_names(self) -> tuple[str, ...]:
        """Every part's markers, part after part."""
        return tuple(name for names in self.markers for name in names)

    @functools.cached_property
    def labels(self) -> np.ndarray:
        """The part of each of ``marker_names``."""
        return np.repeat(np.arange(len(self.parts)), [len(names) for names in self.markers])

    @property
    def jointed(self) -> tuple[int, ...]:
        """The parts that have a parent, in the order of ``joint_names``."""
        return tuple(i for i, parent in enumerate(self.parents) if parent >= 0)


def load_points_model(path: str | os.PathLike) -> PointsModel:
    """Read and check a points model TOML (module docstring); one-line errors name the file."""
    path = Path(path)
    data = read_toml(path, "points model", "pass --model with a points model such as models/vicon_arm.points.toml")
    try:
        return _points_model(path, data)
    except (TypeError, ValueError) as error:
        raise TrackerInputError(f"{path}: {error}; fix the points model") from None


def _points_model(path: Path, data: dict) -> PointsModel:
    entries = data.get("part")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ValueError("no [[part]] tables")
    names = [str(e.get("name", "")) for e in entries]
    if not all(names):
        raise ValueError("every [[part]] needs a name")
    if len(set(names)) != len(names):
        raise ValueError(f"part {next(n for n in names if names.count(n) > 1)!r} is defined twice")
    markers, parents, joint_names, seen = [], [], [], set()
    for entry, name in zip(entries, names):
        listed = entry.get("markers")
        if not isinstance(listed, list) or not all(isinstance(m, str) and m for m in listed):
            raise ValueError(f'part {name!r} needs markers = ["label", ...]')
        if len(listed) < MIN_MARKERS:
            raise ValueError(f"part {name!r} has {len(listed)} markers; a part needs at least {MIN_MARKERS}")
        for marker in listed:
            if marker in seen:
                raise ValueError(f"marker {marker!r} is listed on two parts; give each marker to one part")
            seen.add(marker)
        markers.append(tuple(listed))
        parent = entry.get("parent", "")
        if parent and parent not in names:
            raise ValueError(f"part {name!r} has parent {parent!r}, which is not a part")
        if parent == name:
            raise ValueError(f"part {name!r} is its own parent")
        parents.append(names.index(parent) if parent else -1)
        if parent:
            joint_names.append(str(entry.get("joint", name)))
    _check_acyclic(names, parents)
    repeated = sorted({joint for joint in joint_names if joint_names.count(joint) > 1})
    if repeated:
        raise ValueError(f"joint {repeated[0]!r} is named twice; give every joint its own name")
    mesh = data.get("mesh", [11, 11])
    if not (
        isinstance(mesh, list)
        and len(mesh) == 2
        and all(isinstance(n, int) for n in mesh)
        and mesh[0] >= 1
        and mesh[1] >= 3
    ):
        raise ValueError(f"mesh = {mesh} must be [rings, longitudes] with rings >= 1 and longitudes >= 3")
    rings, longitudes = mesh
    return PointsModel(
        path,
        str(data.get("name", path.stem)),
        tuple(names),
        tuple(markers),
        tuple(parents),
        tuple(joint_names),
        sq.mesh(rings, longitudes),
    )


def _check_acyclic(names: Sequence[str], parents: Sequence[int]) -> None:
    for start in range(len(names)):
        visited, part = set(), start
        while part >= 0:
            if part in visited:
                raise ValueError(f"the parents of part {names[start]!r} form a loop")
            visited.add(part)
            part = parents[part]


@dataclass(frozen=True)
class PointsSettings:
    """``sigma``: the data's standard deviation V = sigma^2 I, metres (it sets the stiffness of the
    markers' pull, the time steps and how much the membrane weighs against the data);
    ``first_steps``: steps of the start-frame fit; ``level``: ``rigid``, ``global`` or ``local``;
    ``dynamics``: ``second-order`` or ``first-order``; ``steps``: first-order steps per later
    frame (module docstring); ``w0``, ``w1``: the membrane (section 3)."""

    sigma: float = 0.01
    first_steps: int = 300
    steps: int = 40
    level: str = "rigid"
    dynamics: str = "first-order"
    w0: float = 0.1
    w1: float = 0.5

    def __post_init__(self) -> None:
        if self.level not in LEVELS:
            raise ValueError(f"level must be one of {', '.join(LEVELS)}, got {self.level!r}")
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {', '.join(DYNAMICS)}, got {self.dynamics!r}")


def seen_per_part(points: np.ndarray, model: PointsModel) -> np.ndarray:
    """Markers seen (finite) per part: points (M, 3) -> (P,), or (F, M, 3) -> (F, P)."""
    seen = np.isfinite(points).all(axis=-1)
    return np.stack([seen[..., model.labels == p].sum(axis=-1) for p in range(len(model.parts))], axis=-1)


def start_frame(points: np.ndarray, model: PointsModel, start: int | None = None) -> int:
    """The frame to start from (points (F, M, 3)): ``start`` if every part has at least MIN_MARKERS
    markers seen there, else a one-line error; by default the first such frame."""
    counts = seen_per_part(points, model)
    if start is not None:
        if not 0 <= start < len(points):
            raise TrackerInputError(
                f"{model.path}: --start {start} is outside the marker file's frames "
                f"0..{len(points) - 1}; pick a frame inside them"
            )
        short = np.nonzero(counts[start] < MIN_MARKERS)[0]
        if len(short):
            raise TrackerInputError(
                f"{model.path}: part {model.parts[short[0]]!r} has {counts[start, short[0]]} markers seen in frame "
                f"{start}, fewer than {MIN_MARKERS}; start from another frame "
                "(without --start: the first that has them)"
            )
        return start
    ready = np.nonzero((counts >= MIN_MARKERS).all(axis=1))[0]
    if not len(ready):
        worst = int(np.argmin(counts.max(axis=0)))
        raise TrackerInputError(
            f"{model.path}: part {model.parts[worst]!r} never has {MIN_MARKERS} of its markers seen in one frame "
            f"(at most {counts[:, worst].max()}); give it markers the file records"
        )
    return int(ready[0])


def joint_to_parent(body: bd.Body, child: int, parent: int) -> bd.Joint:
    """The joint holding the child's pole nearest to the parent on the parent's node nearest to
    that pole: an elbow between the ends of two limb segments, a shoulder between the upper arm's
    end and the side of the thorax."""
    poles = (bd.SOUTH, bd.NORTH)
    ends = bd.material_points(body.parts[child], body.meshes[child], poles)
    nodes = kin.positions(body.parts[parent])
    gaps = np.linalg.norm(ends[:, None] - nodes[None], axis=2)
    end, node = np.unravel_index(np.argmin(gaps), gaps.shape)
    return bd.Joint(parent, bd.node_point(body.meshes[parent], int(node)), child, poles[end])


def first_fit(points: np.ndarray, model: PointsModel, settings: PointsSettings) -> bd.Body:
    """Steps 2-3 of the module docstring on one frame of points (M, 3): the jointed body at the
    start frame, its parts at the GLOBAL level.  The joints are chosen on the moment
    initialisation, whose long axis is every part's z, so its poles are a limb's ends; a free fit
    first could turn a short axis into the long one and move the ends off the poles."""
    meshes = [model.mesh] * len(model.parts)
    start = bd.initial_body(points, model.labels, meshes=meshes, joints=[], levels=bd.GLOBAL)
    joints = [joint_to_parent(start, child, model.parents[child]) for child in model.jointed]
    body = bd.assemble(start.parts, meshes, joints, levels=bd.GLOBAL)
    body, _ = bd.fit_frame(
        body,
        points,
        sigma=settings.sigma,
        n_global=settings.first_steps,
        n_local=0,
        labels=model.labels,
        w0=settings.w0,
        w1=settings.w1,
    )
    return body


@dataclass(frozen=True)
class FrameFit:
    """One frame's fit: the body, each part's RMS marker-to-node distance (P,) in metres (NaN for a
    part with no marker seen), the markers seen per part (P,) and the largest joint violation |C|
    in metres."""

    body: bd.Body
    residual: np.ndarray
    seen: np.ndarray
    violation: float

    @property
    def rms(self) -> float:
        """RMS marker-to-node distance over every marker seen, metres (NaN when none is seen)."""
        seen = self.seen > 0
        if not seen.any():
            return float("nan")
        return float(np.sqrt(np.sum(self.residual[seen] ** 2 * self.seen[seen]) / self.seen.sum()))

    @property
    def status(self) -> int:
        """The frame's poses.npz status: lost when a pose or joint is not finite, uncertain when a part
        had no marker seen, else tracked."""
        if not (np.isfinite(self.poses).all() and np.isfinite(self.joints).all()):
            return LOST
        return UNCERTAIN if np.isnan(self.residual).any() else TRACKED

    @functools.cached_property
    def poses(self) -> np.ndarray:
        """world_from_part (P, 4, 4): the part frame's rotation R and origin c."""
        out = np.zeros((len(self.body.parts), 4, 4))
        out[:, :3, :3] = [part.rotation for part in self.body.parts]
        out[:, :3, 3] = [part.c for part in self.body.parts]
        out[:, 3, 3] = 1.0
        return out

    @functools.cached_property
    def joints(self) -> np.ndarray:
        """Joint centres (J, 3): the midpoint of each joint's two material points."""
        a, b = bd.joint_positions(self.body)
        return (a + b) / 2.0

    @property
    def shapes(self) -> np.ndarray:
        """Global shape parameters q_s (P, 11)."""
        return np.stack([part.q_s for part in self.body.parts])

    @property
    def displacements(self) -> np.ndarray:
        """Nodal displacements d (P, n, 3) in each part's frame."""
        return np.stack([part.d for part in self.body.parts])


def measure(body: bd.Body, points: np.ndarray, model: PointsModel) -> FrameFit:
    """The residual and joint violation of ``body`` on one frame of points (M, 3)."""
    return FrameFit(
        body,
        bd.residuals(body, points, model.labels),
        seen_per_part(points, model),
        float(np.abs(bd.violation(body)).max(initial=0.0)),
    )


def damping(seen: np.ndarray, settings: PointsSettings) -> bd.Damping:
    """D = alpha_p M with alpha_p = 2 sqrt(n_p / (sigma^2 m)) for ``seen`` = n_p markers seen per part:
    critical damping of each part's translation under its markers' pull, none without markers
    (module docstring)."""
    return bd.Damping(alpha=2.0 * np.sqrt(np.asarray(seen, dtype=np.float64) / (settings.sigma**2 * MASS)))


def second_order_frame(
    body: bd.Body,
    velocities: list[np.ndarray],
    points: np.ndarray,
    *,
    model: PointsModel,
    settings: PointsSettings,
    seconds: float,
) -> tuple[bd.Body, list[np.ndarray]]:
    """Move the body and its velocities (on each part's active coordinates) ``seconds`` ahead
    under the pull of one frame of points (M, 3), attached to their parts' nearest nodes at the
    start (module docstring, step 4)."""
    attachments = bd.attach(body, points, model.labels)
    k_nodes = bd.stiffnesses(body, settings.w0, settings.w1)  # None for parts below LOCAL
    d = damping(seen_per_part(points, model), settings)
    limit = bd.second_order_limit(body, attachments, sigma=settings.sigma, k_nodes=k_nodes, damping=d, mass=MASS)
    substeps = max(1, int(np.ceil(seconds / (STEP_FRACTION * limit))))
    dt = seconds / substeps
    for _ in range(substeps):
        body, velocities = bd.second_order_step(
            body,
            velocities,
            attachments,
            sigma=settings.sigma,
            k_nodes=k_nodes,
            dt=dt,
            a=DECAY / dt,
            damping=d,
            mass=MASS,
        )
    return body, velocities


def track(
    frames: Iterable[np.ndarray], model: PointsModel, *, settings: PointsSettings, interval: float
) -> Iterator[FrameFit]:
    """Fit ``frames`` (each (M, 3), the first the start frame, ``interval`` seconds apart) one after
    another (module docstring)."""
    level = LEVELS[settings.level]
    body = velocities = None
    for points in frames:
        if body is None:
            body = first_fit(points, model, settings)
            body = replace(body, levels=(level,) * len(body.parts))
            velocities = [np.zeros(len(index)) for index in bd.active(body)]
        elif settings.dynamics == "second-order":
            assert velocities is not None  # set with body on the first frame
            body, velocities = second_order_frame(
                body, velocities, points, model=model, settings=settings, seconds=interval
            )
        elif np.isfinite(points).all(axis=1).any():  # first order: without any marker nothing moves
            body, _ = bd.fit_frame(
                body,
                points,
                sigma=settings.sigma,
                n_global=0,
                n_local=settings.steps,
                labels=model.labels,
                w0=settings.w0,
                w1=settings.w1,
            )  # every part at its own level
        yield measure(body, points, model)
