"""The paper's 'insect' experiment (Metaxas & Terzopoulos 1993, section VI, Figs 9-10;
docs/method-physics.md, sections 4 and 6): five deformable superquadric parts of 27
nodes each (``superquadric.mesh(5, 5)``) joined by four point-to-point constraints, tracked
from dense data (every node of every part) and from sparse data (7 fixed nodes per part).

The paper's text names a nose pulled forward and two wings flapping by forces at their tips;
the truth here is kinematic instead of simulated, so that the constraints hold exactly:

- part 0, the thorax: long axis (model z) along the direction of travel (world x), model x up;
  it moves forward and rises and pitches a little;
- part 1, the head, joined at its south pole to the thorax's north pole; it nods;
- part 2, the abdomen, tapered towards its tail, joined at its north pole to the thorax's
  south pole; it bends (b1) and swings sideways;
- parts 3 and 4, the left and right wings, thin (a2 = 0.05) and long (a3 = 1), joined at their
  roots to the sides of the thorax, the material points (u, v) = (0, -+pi/2) between nodes
  (their displacement is interpolated); the left wing's root is its south pole, the right
  wing's its north pole, so that both have model z along world +y.  They flap (one cycle of
  +-0.5 rad over 36 frames), sweep (b1) and flex: a local displacement along the wing's normal
  growing with the square of the distance from the root, lagging the flap.

Each part is placed so that its joint point lies on the thorax's, so C = 0 in the truth.  The
poses at frame 0 agree with the sign convention of ``fitting.initial_part`` (model z and x have
a positive largest component), so the tracker's mesh is registered with the truth's and the
node position error is measured node by node (eq 40, 'pos (node RMS)' of docs/method-physics.md, section 6).

Tracking (``run``): frame 0 is fitted from the moment initialisation (``body.initial_body``) by
``body.fit_frame``'s two stages (global, then local); every later frame starts from the
previous frame's fit and takes local steps only.  The data are labelled by part (segmented, as
in the paper's arm experiment).

``run``'s defaults: 36 frames, sigma = 0.1, 200 + 400 steps on frame 0, 60 per later frame,
w0 = 0.1, w1 = 0.5.  It reports the joint violation max |C| and the node position error over
the frames (results, also with noisy data: docs/physics.md).  The insect spans 4.1 (head to
tail) by 4.4 (wing tip to wing tip).  Sparse data leave the local displacements and the
wings' taper and bend underdetermined, which the paper also notes for its Fig. 10.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from tracker.geometry.se3 import exp_so3
from tracker.physics import body as bd
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

MESH = sq.mesh(5, 5)
"""The paper's 27-node part mesh."""

SIDE_LEFT = (0.0, -np.pi / 2)
SIDE_RIGHT = (0.0, np.pi / 2)
"""Material points on the thorax (model -y and +y at its equator; with model x up and z forward,
model -y points to world +y, the insect's left)."""

JOINTS = (
    bd.Joint(0, bd.NORTH, 1, bd.SOUTH),
    bd.Joint(0, bd.SOUTH, 2, bd.NORTH),
    bd.Joint(0, SIDE_LEFT, 3, bd.SOUTH),
    bd.Joint(0, SIDE_RIGHT, 4, bd.NORTH),
)
"""Thorax-head, thorax-abdomen, thorax-left wing, thorax-right wing."""

# a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3
THORAX = np.array([1.0, 0.3, 0.2, 0.9, 0.9, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])
HEAD = np.array([1.0, 0.2, 0.12, 0.35, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])
ABDOMEN = np.array([1.0, 0.25, 0.16, 0.8, 1.0, 1.0, 0.4, 0.4, 0.0, 0.0, 0.5])
WING = np.array([1.0, 0.3, 0.05, 1.0, 0.8, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])

PERIOD = 36
"""Frames per flap cycle (the paper's sequence has 36 frames)."""


def _axes(z: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The rotation [x, z x x, z] with model z along z and model x along x (orthogonal)."""
    return np.column_stack([x, np.cross(z, x), z])


_FORWARD = _axes(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]))
_OUTWARD = _axes(np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]))


def _flex(q_s: np.ndarray, root_sign: float, amplitude: float) -> np.ndarray:
    """Wing flex d (n, 3): amplitude * (distance from the root / length)^2 along model y.
    root_sign -1: the root is the south pole (z = -a3), +1: the north pole."""
    z = sq.shape(q_s, MESH.u, MESH.v)[:, 2]
    length = 2.0 * q_s[0] * q_s[3]
    d = np.zeros((len(MESH.u), 3))
    d[:, 1] = amplitude * ((0.5 * length - root_sign * z) / length) ** 2
    return d


def _attached(to: kin.Part, at: tuple[float, float], part: kin.Part, point: tuple[float, float]) -> kin.Part:
    """The part translated so that its material point ``point`` lies on ``to``'s ``at``."""
    gap = bd.material_points(to, MESH, [at])[0] - bd.material_points(part, MESH, [point])[0]
    return replace(part, c=part.c + gap)


def truth(frame: int) -> list[kin.Part]:
    """The five true parts at a frame (module docstring)."""
    phase = 2.0 * np.pi * frame / PERIOD
    zeros = np.zeros((len(MESH.u), 3))
    thorax = kin.Part(
        np.array([0.03 * frame, 0.0, 0.15 * np.sin(phase / 2)]),
        exp_so3(np.array([0.0, 0.1 * np.sin(phase), 0.0])) @ _FORWARD,
        THORAX,
        zeros,
        MESH.u,
        MESH.v,
    )
    head = kin.Part(
        np.zeros(3),
        exp_so3(np.array([0.0, 0.25 * np.sin(phase), 0.0])) @ thorax.rotation,
        HEAD,
        zeros,
        MESH.u,
        MESH.v,
    )
    abdomen_shape = ABDOMEN.copy()
    abdomen_shape[8] = 0.1 * np.sin(phase)
    abdomen = kin.Part(
        np.zeros(3),
        exp_so3(np.array([0.0, 0.0, 0.2 * np.sin(phase)])) @ thorax.rotation,
        abdomen_shape,
        zeros,
        MESH.u,
        MESH.v,
    )
    flap = 0.5 * np.sin(phase)
    wing_shape = WING.copy()
    wing_shape[8] = 0.15 * np.sin(phase)
    lag = 0.15 * np.cos(phase)
    left = kin.Part(
        np.zeros(3),
        exp_so3(np.array([flap, 0.0, 0.0])) @ _OUTWARD,
        wing_shape,
        _flex(wing_shape, -1.0, -lag),
        MESH.u,
        MESH.v,
    )
    right = kin.Part(
        np.zeros(3),
        exp_so3(np.array([-flap, 0.0, 0.0])) @ _OUTWARD,
        wing_shape,
        _flex(wing_shape, 1.0, lag),
        MESH.u,
        MESH.v,
    )
    parts = [thorax]
    for joint, part in zip(JOINTS, (head, abdomen, left, right)):
        parts.append(_attached(thorax, joint.point_a, part, joint.point_b))
    return parts


def true_body(frame: int) -> bd.Body:
    """The truth at a frame as a ``body.Body`` (every part LOCAL)."""
    return bd.assemble(truth(frame), [MESH] * 5, JOINTS)


@dataclass(frozen=True)
class Result:
    """Per frame: max |C| of the fit and the RMS over all nodes of |x_fit - x_true|; the fitted
    bodies; and the means and maxima of both series."""

    violation: np.ndarray
    position_error: np.ndarray
    bodies: list[bd.Body]

    @property
    def summary(self) -> dict[str, float]:
        return {
            "violation_mean": float(self.violation.mean()),
            "violation_max": float(self.violation.max()),
            "position_error_mean": float(self.position_error.mean()),
            "position_error_max": float(self.position_error.max()),
        }


def sparse_nodes(rng: np.random.Generator) -> np.ndarray:
    """The 7 data nodes (the paper's sparse count) of a part: both poles and one node at a random
    longitude on each of the 5 rings, so that the points span the part's length (seven nodes
    drawn uniformly would often miss an end, leaving a wing's length unobserved)."""
    rings = 1 + np.arange(MESH.n_rings) * MESH.n_longitudes + rng.integers(0, MESH.n_longitudes, MESH.n_rings)
    return np.concatenate([[0], rings, [len(MESH.u) - 1]])


def data(sparse: bool, frames: int, *, seed: int = 0, noise: float = 0.0) -> tuple[list[np.ndarray], np.ndarray]:
    """Per frame the data points and their part labels: every node of every part (dense) or the
    same ``sparse_nodes`` of each part in every frame (sparse), plus Gaussian noise of standard
    deviation ``noise`` per coordinate."""
    rng = np.random.default_rng(seed)
    n = len(MESH.u)
    nodes = np.arange(5 * n)
    if sparse:
        nodes = np.concatenate([p * n + sparse_nodes(rng) for p in range(5)])
    frames_points = [
        np.concatenate(bd.all_positions(true_body(f)))[nodes] + noise * rng.normal(size=(len(nodes), 3))
        for f in range(frames)
    ]
    return frames_points, nodes // n


def position_error(fitted: bd.Body, true: bd.Body) -> float:
    """RMS over all nodes of all parts of |x_fit - x_true| (node i of the fit against node i of
    the truth)."""
    difference = np.concatenate(bd.all_positions(fitted)) - np.concatenate(bd.all_positions(true))
    return float(np.sqrt(np.mean(np.sum(difference**2, axis=1))))


def run(
    sparse: bool,
    frames: int = PERIOD,
    *,
    seed: int = 0,
    progress: Callable[[int, float, float], None] | None = None,
    noise: float = 0.0,
    sigma: float = 0.1,
    first_steps: tuple[int, int] = (200, 400),
    steps: int = 60,
) -> Result:
    """Track the insect over ``frames`` frames from dense or sparse data (module docstring).

    Frame 0: ``first_steps`` = (global, local) steps of ``body.fit_frame`` from the moment
    initialisation; later frames: ``steps`` local steps each from the previous fit.  ``progress``
    is called after each frame with (frame, max |C|, position error)."""
    points, labels = data(sparse, frames, seed=seed, noise=noise)
    fitted = bd.initial_body(points[0], labels, meshes=[MESH] * 5, joints=JOINTS)
    violation, error, bodies = [], [], []
    for f, frame_points in enumerate(points):
        n_global, n_local = first_steps if f == 0 else (0, steps)
        fitted, _ = bd.fit_frame(fitted, frame_points, sigma=sigma, n_global=n_global, n_local=n_local, labels=labels)
        violation.append(float(np.abs(bd.violation(fitted)).max()))
        error.append(position_error(fitted, true_body(f)))
        bodies.append(fitted)
        if progress is not None:
            progress(f, violation[-1], error[-1])
    return Result(np.array(violation), np.array(error), bodies)
