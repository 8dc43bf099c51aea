"""The body model fitted to the landmarks: to their world points, then to their pixels in every view
(docs/keypoints.md, "Automatic first pose").

Both fits are robust least squares over the same joint space (:meth:`Body.posed`): the root's motion (dt, dr) and
every joint's motion from rest, a ball's rotation vector, a hinge's angle, a slide's length.  The model
points of the landmarks are :func:`tracker.landmarks.anchors.anchors`.  Left and right are settled the way
an ICP settles correspondences: fit, label each left/right pair (in 3-D, or per view and frame) the way
round that lies nearer the fitted model, fit again from there, until no label changes.

1. :func:`fit_pose`, to world points (metres): from the root placed on the hips and shoulders
   (:func:`root_from_landmarks`), with the points as labelled and with every pair swapped (a person seen
   from the front and from behind gives the same points but for the labels; the joint limits, knees and
   elbows bending one way, and the face and feet tell them apart): the lower cost wins.
2. :func:`fit_to_views`, to the detections (pixels) of a few frames, the body taken as still over them:
   two views alone triangulate a landmark's depth poorly, while the model's rigid lengths and joint limits
   bound it; a view's detection of someone else falls under the Cauchy loss.

Poses are world_from_component (N, 4, 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from tracker.camera import Camera
from tracker.chain import BALL, FREE, HINGE, SLIDE, twist_angle, twist_gradient
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.landmarks.body_landmarks import LANDMARKS, TRUNK_TURN, anchors, landmark_world, left_right_pairs, trunk
from tracker.landmarks.triangulation import middle
from tracker.model import Model

ROBUST = 0.03
"""Misfit (metres, per coordinate) beyond which a world point's pull grows linearly (soft L1)."""

PIXEL_ROBUST = 0.015
"""Misfit (per coordinate, a share of the image's short side: 7 pixels in 480) beyond which a detection's pull
fades (Cauchy)."""

REST_WEIGHT = 0.001
"""Metres of misfit that one radian (or metre) of a joint away from rest costs: holds the joints that no
landmark sees at rest."""

LIMIT_WEIGHT = 1.0
"""Metres of misfit per radian that a ball joint turns beyond its largest rotation."""

RELABEL_ROUNDS = 5
"""Most times a fit relabels the left/right pairs and goes on."""

HINGE_START = 0.2
"""A hinge's starting angle (radians, within its limits): a straight limb's twist would not move the landmarks."""

PROJECTION_STEP = 1e-5
"""Metres a world point is moved each way to take its pixels' derivatives (:func:`_projection_jacobian`)."""


def root_from_landmarks(model: Model, points: np.ndarray) -> np.ndarray:
    """The root's world pose (4, 4) from the landmarks' world points (33, 3): its left (x) from the right hip to
    the left, up (z) towards the shoulders' midpoint, y = z x x; its origin where the model's hip joints
    (the thighs' origins at rest) then fall on the hips' midpoint."""
    hips = middle(points, "hip")
    left = points[LANDMARKS.index("left_hip")] - points[LANDMARKS.index("right_hip")]
    up = middle(points, "shoulder") - hips
    if not (np.isfinite(left).all() and np.isfinite(up).all()) or np.linalg.norm(np.cross(left, up)) < 1e-6:
        raise TrackerInputError(
            "the keypoints do not show both hips and both shoulders in two views, which place the body; pass --init"
        )
    x = left / np.linalg.norm(left)
    z = up - (up @ x) * x
    z /= np.linalg.norm(z)
    rotation = np.column_stack([x, np.cross(z, x), z])
    thighs = [model.index(name) for name in ("thigh_l", "thigh_r") if name in model.names]
    joint = model.rest[thighs, :3, 3].mean(axis=0) if thighs else np.zeros(3)
    return se3.from_rotation(rotation, hips - rotation @ joint)


@dataclass(frozen=True)
class Body:
    """A model's joint space, once: where each component's parameters start (N + 1,) (6 for the root and for a
    free joint, 3 for a ball, 1 for a hinge or slide, 0 when fixed), their ``lower`` and ``upper`` bounds (a
    hinge's or slide's limits, unbounded otherwise), the ``balls`` (B,) with a largest rotation and that rotation,
    ``turns`` (B,) (:data:`TRUNK_TURN` at most for the trunk's), the balls ``twisted`` (T,) with a largest turn
    about their bone, ``twist_limits`` (T,) (:func:`tracker.chain.twist_angle`), the landmarks' ``component`` (33,)
    and ``anchor`` (33, 3) points (:func:`tracker.landmarks.anchors.anchors`), and for the Jacobians ``drives``
    (33, P), whether a parameter moves a landmark: it turns or slides the joint of the landmark's component or of one
    above it."""

    model: Model
    offsets: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    balls: np.ndarray
    component: np.ndarray
    anchor: np.ndarray
    drives: np.ndarray
    turns: np.ndarray
    twisted: np.ndarray
    twist_limits: np.ndarray

    @staticmethod
    def of(model: Model) -> Body:
        sizes = {FREE: 6, BALL: 3, HINGE: 1, SLIDE: 1}
        counts = [sizes.get(int(kind), 0) for kind in model.joint_type]
        offsets = np.concatenate([[0], np.cumsum(counts)])
        lower, upper = np.full(offsets[-1], -np.inf), np.full(offsets[-1], np.inf)
        for i in np.flatnonzero(np.isin(model.joint_type, (HINGE, SLIDE))):
            lower[offsets[i]], upper[offsets[i]] = model.lower[i], model.upper[i]
        component, anchor = anchors(model)
        held = np.isin(np.arange(model.size), trunk(model, component))
        balls = np.flatnonzero((model.joint_type == BALL) & (np.isfinite(model.upper) | held))
        turns = np.where(held[balls], np.minimum(model.upper[balls], TRUNK_TURN), model.upper[balls])
        moves = np.eye(model.size, dtype=bool)  # moves[j, i]: component j's joint moves component i
        for below in range(model.size):
            j = int(model.parent[below])
            while j >= 0:
                moves[j, below], j = True, int(model.parent[j])
        owner = np.repeat(np.arange(model.size), counts)  # the component whose joint each parameter moves
        drives = moves[owner][:, np.maximum(component, 0)].T & (component >= 0)[:, None]
        twisted = np.flatnonzero(np.isfinite(model.twist))  # balls only (tracker.model)
        return Body(
            model, offsets, lower, upper, balls, component, anchor, drives, turns, twisted, model.twist[twisted]
        )

    def posed(self, root: np.ndarray, parameters: np.ndarray) -> np.ndarray:
        """World poses (N, 4, 4) of joint-space ``parameters``: the root at ``root`` moved by (dt, dr),
        E_0 = [exp(dr) R_root, t_root + dt]; every other E_i = E_parent T0_i M_i with M_i the joint's motion
        from rest (docs/method-tracking.md, section 5): a ball's rotation exp(w), a hinge's exp(theta axis),
        a slide's translation s axis, a free joint's [exp(w), v]."""
        model, offsets = self.model, self.offsets
        poses = np.empty((model.size, 4, 4))
        poses[0] = se3.from_rotation(se3.exp_so3(parameters[3:6]) @ root[:3, :3], root[:3, 3] + parameters[0:3])
        for i in range(1, model.size):
            value = parameters[offsets[i] : offsets[i + 1]]
            kind, motion = model.joint_type[i], np.eye(4)
            if kind == BALL:
                motion[:3, :3] = se3.exp_so3(value)
            elif kind == HINGE:
                motion[:3, :3] = se3.exp_so3(value[0] * model.axis[i])
            elif kind == SLIDE:
                motion[:3, 3] = value[0] * model.axis[i]
            elif kind == FREE:
                motion = se3.from_rotvec(value[3:6], value[0:3])
            poses[i] = poses[model.parent[i]] @ model.rest[i] @ motion
        return poses

    def parameters_of(self, root: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """The joint-space parameters whose :meth:`posed` about ``root`` are ``poses`` (N, 4, 4), joints exact."""
        model, offsets = self.model, self.offsets
        parameters = np.zeros(offsets[-1])
        parameters[0:3] = poses[0, :3, 3] - root[:3, 3]
        parameters[3:6] = se3.log_so3(np.ascontiguousarray(poses[0, :3, :3] @ root[:3, :3].T))
        for i in range(1, model.size):
            motion = se3.inverse(poses[model.parent[i]] @ model.rest[i]) @ poses[i]
            turn = se3.log_so3(np.ascontiguousarray(motion[:3, :3]))
            kind, at = model.joint_type[i], offsets[i]
            if kind == BALL:
                parameters[at : at + 3] = turn
            elif kind == HINGE:
                parameters[at] = turn @ model.axis[i]
            elif kind == SLIDE:
                parameters[at] = motion[:3, 3] @ model.axis[i]
            elif kind == FREE:
                parameters[at : at + 3], parameters[at + 3 : at + 6] = motion[:3, 3], turn
        return parameters

    def penalties(self, parameters: np.ndarray) -> np.ndarray:
        """The residuals (metres) that hold the joints: every joint parameter's pull to rest, :data:`REST_WEIGHT`
        times it, and every ball's turn beyond its largest rotation (``turns``) and its twist beyond its largest
        (``twist_limits``), :data:`LIMIT_WEIGHT` times each."""
        offsets = self.offsets
        beyond = [
            max(0.0, float(np.linalg.norm(parameters[offsets[i] : offsets[i + 1]])) - turn)
            for i, turn in zip(self.balls, self.turns)
        ]
        twisted = [
            max(0.0, abs(twist_angle(parameters[offsets[i] : offsets[i + 1]])) - limit)
            for i, limit in zip(self.twisted, self.twist_limits)
        ]
        return np.concatenate([REST_WEIGHT * parameters[6:], LIMIT_WEIGHT * np.array(beyond + twisted)])

    def landmark_points(self, poses: np.ndarray) -> np.ndarray:
        """World points (33, 3) of the landmarks' model points at ``poses`` (NaN where the model has none)."""
        return landmark_world(poses, self.component, self.anchor)

    def twists(self, parameters: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """Each parameter's world twist (P, 6), (omega, v): a world point p fixed in a component that the parameter
        moves goes at omega x p + v per unit of it, at ``poses`` = :meth:`posed` of ``parameters``.  A turn about an
        axis a through a point c is (a, c x a): the root's dr about its origin, with axes the columns of the left
        Jacobian J_l(dr) (exp(dr + d) = exp(J_l d) exp(dr)); a ball's or free joint's w about the component's
        origin, axes R J_r(w) (exp(w + d) = exp(w) exp(J_r d)); a hinge's angle about R axis.  A slide along R axis,
        the root's dt and a free joint's translation along the frame before its turn are (0, direction)."""
        model, offsets = self.model, self.offsets
        out = np.zeros((offsets[-1], 6))
        out[0:3, 3:6] = np.eye(3)
        axes = se3.right_jacobian_so3(-parameters[3:6])  # its columns: J_l(dr) = J_r(-dr)
        out[3:6, 0:3] = axes.T
        out[3:6, 3:6] = se3.cross(poses[0, :3, 3], axes.T)
        for i in range(1, model.size):
            at, kind = offsets[i], model.joint_type[i]
            rotation, centre = poses[i, :3, :3], poses[i, :3, 3]
            if kind == SLIDE:
                out[at, 3:6] = rotation @ model.axis[i]
                continue
            if kind == BALL:
                rows, axes = slice(at, at + 3), rotation @ se3.right_jacobian_so3(parameters[at : at + 3])
            elif kind == HINGE:
                rows, axes = slice(at, at + 1), (rotation @ model.axis[i])[:, None]
            elif kind == FREE:
                before = (poses[model.parent[i]] @ model.rest[i])[:3, :3]
                out[at : at + 3, 3:6] = before.T
                rows, axes = slice(at + 3, at + 6), rotation @ se3.right_jacobian_so3(parameters[at + 3 : at + 6])
            else:
                continue
            out[rows, 0:3] = axes.T
            out[rows, 3:6] = se3.cross(centre, axes.T)
        return out

    def landmark_jacobian(self, parameters: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """d(landmark world points)/d(parameters) (33, 3, P) at ``poses`` = :meth:`posed` of ``parameters``; zero
        for landmarks the model has no point for."""
        twists = self.twists(parameters, poses)
        points = np.nan_to_num(self.landmark_points(poses))
        velocity = se3.cross(twists[None, :, 0:3], points[:, None, :]) + twists[None, :, 3:6]  # (33, P, 3)
        return np.where(self.drives[..., None], velocity, 0.0).transpose(0, 2, 1)

    def penalty_jacobian(self, parameters: np.ndarray) -> np.ndarray:
        """d(:meth:`penalties`)/d(parameters) (R, P)."""
        offsets = self.offsets
        rest = np.zeros((offsets[-1] - 6, offsets[-1]))
        rest[:, 6:] = REST_WEIGHT * np.eye(offsets[-1] - 6)
        limits = np.zeros((len(self.balls), offsets[-1]))
        for row, (i, turn) in enumerate(zip(self.balls, self.turns)):
            value = parameters[offsets[i] : offsets[i + 1]]
            size = float(np.linalg.norm(value))
            if size > turn:
                limits[row, offsets[i] : offsets[i + 1]] = LIMIT_WEIGHT * value / size
        twisted = np.zeros((len(self.twisted), offsets[-1]))
        for row, (i, limit) in enumerate(zip(self.twisted, self.twist_limits)):
            value = parameters[offsets[i] : offsets[i + 1]]
            tau = twist_angle(value)
            if abs(tau) > limit:
                twisted[row, offsets[i] : offsets[i + 1]] = LIMIT_WEIGHT * np.sign(tau) * twist_gradient(value)
        return np.concatenate([rest, limits, twisted])


def _nearer(observed: np.ndarray, model_points: np.ndarray) -> np.ndarray:
    """``observed`` (..., 33, D) with each left/right pair swapped where the other way round lies nearer
    (summed distance over the known points) to ``model_points`` (..., 33, D)."""
    out = observed.copy()
    for pair in left_right_pairs(LANDMARKS):
        target = model_points[..., pair, :]
        straight = np.nansum(np.linalg.norm(observed[..., pair, :] - target, axis=-1), axis=-1)
        crossed = np.nansum(np.linalg.norm(observed[..., pair[::-1], :] - target, axis=-1), axis=-1)
        swap = (crossed < straight)[..., None, None]
        out[..., pair, :] = np.where(swap, observed[..., pair[::-1], :], observed[..., pair, :])
    return out


def _relabelled_fit(residuals, jacobian, parameters, bounds, observed, model_points, loss: str, scale: float):
    """Fit (``residuals`` and their ``jacobian``, both of the parameters and ``observed``), relabel ``observed``
    nearer the fitted model (``model_points(parameters)``), fit again, until no label changes or
    :data:`RELABEL_ROUNDS`; returns the final least-squares result."""
    for _ in range(RELABEL_ROUNDS):
        result = least_squares(
            residuals, parameters, jac=jacobian, bounds=bounds, loss=loss, f_scale=scale, args=(observed,)
        )
        parameters = result.x
        relabelled = _nearer(observed, model_points(parameters))
        if np.array_equal(relabelled, observed, equal_nan=True):
            break
        observed = relabelled
    return result


def _projection_jacobian(camera: Camera, points: np.ndarray) -> np.ndarray:
    """d(pixels)/d(world point) (M, 2, 3) of ``points`` (M, 3) in ``camera``, lens included: central differences
    of :meth:`tracker.camera.Camera.project` over :data:`PROJECTION_STEP`."""
    columns = [
        camera.project(points + PROJECTION_STEP * axis) - camera.project(points - PROJECTION_STEP * axis)
        for axis in np.eye(3)
    ]
    return np.stack(columns, axis=2) / (2 * PROJECTION_STEP)


def fit_pose(model: Model, points: np.ndarray) -> np.ndarray:
    """The model's world poses (N, 4, 4) that best fit world ``points`` (33, 3) (NaN: unknown) of the landmarks,
    taken as labelled or with every left/right pair swapped: whichever :func:`fitted` explains at the lower
    cost (module docstring)."""
    pairs = left_right_pairs(LANDMARKS)
    mirrored = points.copy()
    mirrored[pairs] = points[pairs[:, ::-1]]
    return min((fitted(model, points), fitted(model, mirrored)), key=lambda fit: fit[1])[0]


def fitted(model: Model, points: np.ndarray) -> tuple[np.ndarray, float]:
    """The model's world poses (N, 4, 4) whose landmark points best fit world ``points`` (33, 3) (NaN: unknown),
    and the fit's cost: from the root of :func:`root_from_landmarks`, every joint at rest and every hinge at
    :data:`HINGE_START`, the residuals each known landmark's model point minus its world point under a soft L1
    loss of scale :data:`ROBUST` (so a model whose lengths differ from the person's lands at the least misfit,
    and a wrong point pulls little) and the joints' :meth:`Body.penalties`; the pairs relabelled as the fit goes
    (module docstring); the result coerced."""
    body = Body.of(model)
    if not (body.component >= 0).any():
        raise TrackerInputError(
            f"model {model.name!r} has no component that a keypoint marks (e.g. upperarm_l, thigh_r); pass --init"
        )
    root = root_from_landmarks(model, points)
    start = np.zeros(body.offsets[-1])
    hinges = np.flatnonzero(model.joint_type == HINGE)
    start[body.offsets[hinges]] = np.clip(HINGE_START, model.lower[hinges], model.upper[hinges])

    def model_points(parameters: np.ndarray) -> np.ndarray:
        return body.landmark_points(body.posed(root, parameters))

    def residuals(parameters: np.ndarray, targets: np.ndarray) -> np.ndarray:
        misfit = model_points(parameters) - targets
        return np.concatenate([misfit[np.isfinite(misfit).all(axis=1)].ravel(), body.penalties(parameters)])

    def jacobian(parameters: np.ndarray, targets: np.ndarray) -> np.ndarray:
        poses = body.posed(root, parameters)
        known = np.isfinite(body.landmark_points(poses) - targets).all(axis=1)
        rows = body.landmark_jacobian(parameters, poses)[known].reshape(-1, len(parameters))
        return np.concatenate([rows, body.penalty_jacobian(parameters)])

    bounds = (body.lower, body.upper)
    result = _relabelled_fit(residuals, jacobian, start, bounds, points, model_points, "soft_l1", ROBUST)
    return model.coerce(body.posed(root, result.x)), float(result.cost)


def fit_to_views(
    model: Model,
    poses: np.ndarray,
    cameras: list[Camera],
    *,
    pixels: np.ndarray,
    confidence: np.ndarray,
    min_confidence: float = 0.5,
) -> np.ndarray:
    """``poses`` (N, 4, 4) refined so that the model's landmark points project onto their detections, ``pixels``
    (F, C, 33, 2) with ``confidence`` (F, C, 33) in ``cameras`` over F frames (the body taken as still over
    them): residuals in pixels under a Cauchy loss of scale :data:`PIXEL_ROBUST` of the image, beside the joints'
    :meth:`Body.penalties` in pixels at the body's distance; each view's pairs relabelled as the fit goes per
    frame (module docstring); the result coerced."""
    body, root = Body.of(model), poses[0]
    start = np.clip(body.parameters_of(root, poses), body.lower, body.upper)
    seen = (confidence >= min_confidence) & np.isfinite(pixels).all(axis=3) & (body.component >= 0)
    detections = np.where(seen[..., None], pixels, np.nan)
    per_metre = np.median([camera.matrix[0, 0] / np.linalg.norm(camera.center - root[:3, 3]) for camera in cameras])
    scale = PIXEL_ROBUST * np.median([min(camera.size) for camera in cameras])

    def model_pixels(parameters: np.ndarray) -> np.ndarray:
        world = body.landmark_points(body.posed(root, parameters))
        known = np.isfinite(world).all(axis=1)
        projected = np.full((len(cameras), len(LANDMARKS), 2), np.nan)
        for k, camera in enumerate(cameras):
            projected[k, known] = camera.project(world[known])
        return np.broadcast_to(projected, detections.shape)

    def residuals(parameters: np.ndarray, observed: np.ndarray) -> np.ndarray:
        misfit = model_pixels(parameters) - observed
        held = per_metre * body.penalties(parameters)
        return np.concatenate([misfit[np.isfinite(observed).all(axis=3)].ravel(), held])

    def jacobian(parameters: np.ndarray, observed: np.ndarray) -> np.ndarray:
        poses = body.posed(root, parameters)
        world = body.landmark_points(poses)
        known = np.isfinite(world).all(axis=1)
        moved = body.landmark_jacobian(parameters, poses)  # (33, 3, P)
        rows = np.zeros((len(cameras), len(LANDMARKS), 2, len(parameters)))
        for k, camera in enumerate(cameras):
            rows[k, known] = np.einsum("kij,kjp->kip", _projection_jacobian(camera, world[known]), moved[known])
        rows = np.broadcast_to(rows, (*detections.shape, len(parameters)))
        held = per_metre * body.penalty_jacobian(parameters)
        return np.concatenate([rows[np.isfinite(observed).all(axis=3)].reshape(-1, len(parameters)), held])

    bounds = (body.lower, body.upper)
    result = _relabelled_fit(residuals, jacobian, start, bounds, detections, model_pixels, "cauchy", scale)
    return model.coerce(body.posed(root, result.x))
