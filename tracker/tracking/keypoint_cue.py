"""The keypoint cue: 2-D landmarks pulling on model points, summed into the edges' information.

A detected landmark ``d`` (recorded pixels, in camera k) is the image of a point ``X`` fixed in
component i's frame.  With ``u(E_i)`` its predicted image (camera_from_world P_k, the camera's calibrated
lens model, :func:`tracker.geometry.lens.distort`) and ``J = du/dalpha`` (2 x 6) its Jacobian with respect to the
component's body twist, the same chain as an outline sample's row (docs/method-tracking.md, section 3),

    J = J_d (1/Z) [K2 | -(p - c0)] R D(X),   D(X) = [I3 | -[X]x],

the residual ``r = d - u`` adds, per component, summed over landmarks and cameras,

    C_i += w J^T J,   eta_i += w J^T r,   w = s q (e / |r|) / ((c + e) (1 + (e / a)^2)),   e = |r| - t

where ``q`` is the detection's confidence, ``c`` the robust constant (IRLS, as the edges), ``s``
the cue's weight against the edges and ``t`` the detector's noise in that image (a share of the
predicted body's size there): a landmark within ``t`` of its prediction is not used (e <= 0), so a
detector's scatter and bias never pull against the edges, while a body that has drifted off is
pulled back by the excess.  So one tree solve fuses both cues.  The noise is learnt per landmark
(:mod:`tracker.tracking.landmark_noise`): how far the detector's landmark lies from the tracked body's while the
edges hold it, for this detector on this subject.  Where the edges do not hold a limb (the component that places a
joint landmark, :func:`placers`, fitted its outline's edges worse than ``Settings.keypoint_edge_misfit`` in the last
frame's last iteration, :func:`tracker.tracking.measure.component_misfits`: it follows clutter, or nothing), the
landmarks it places pull from the floor zone with no fade (``reach`` inf) until they bring it back (docs/keypoints.md,
"Fusion with the edges"); near that limit the zone and the fade pass from one to the other over a span
(:meth:`tracker.tracking.landmark_noise.LandmarkNoise.held`).  Left/right swaps are rejected, not fused: for each
left/right pair seen in a camera, when the two detections fit the predicted images better the other way round (summed
distance), neither is used in that camera, and a pair that fits barely better as detected counts in part
(:data:`SWAP_MARGIN`).  Every one of these choices is continuous in the poses, so that a last-bit change of a pose
changes the solve by about as much (docs/keypoints.md, "The same result on every machine").
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.geometry.lens import distort
from tracker.model import Model, with_descendants
from tracker.tracking.outline import component_row

LANDMARKS = (
    "nose",
    "left_eye_inner",
    "left_eye",
    "left_eye_outer",
    "right_eye_inner",
    "right_eye",
    "right_eye_outer",
    "left_ear",
    "right_ear",
    "mouth_left",
    "mouth_right",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_pinky",
    "right_pinky",
    "left_index",
    "right_index",
    "left_thumb",
    "right_thumb",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_heel",
    "right_heel",
    "left_foot_index",
    "right_foot_index",
)
"""BlazePose's landmarks, in its order; 'left' is the person's left."""

SIDES = {
    "shoulder": "upperarm",
    "elbow": "forearm",
    "wrist": "hand",
    "hip": "thigh",
    "knee": "shin",
    "ankle": "foot",
}
"""BlazePose landmark -> the component whose origin (its joint with its parent) it marks, in the naming
of models/human.toml (``<part>_l`` / ``<part>_r`` for the person's left and right)."""


SURFACE = {
    "nose": ("head", (0.0, -1.0, 0.0)),
    "left_ear": ("head", (1.0, 0.0, 0.0)),
    "right_ear": ("head", (-1.0, 0.0, 0.0)),
    "left_index": ("hand_l", (0.0, -1.0, 0.0)),
    "right_index": ("hand_r", (0.0, -1.0, 0.0)),
    "left_pinky": ("hand_l", (0.0, 1.0, 0.0)),
    "right_pinky": ("hand_r", (0.0, 1.0, 0.0)),
    "left_heel": ("foot_l", (0.0, 1.0, 0.0)),
    "right_heel": ("foot_r", (0.0, 1.0, 0.0)),
    "left_foot_index": ("foot_l", (0.0, -1.0, 0.0)),
    "right_foot_index": ("foot_r", (0.0, -1.0, 0.0)),
}
"""Landmark -> (component, direction d): the nose in front of the head, the ears at its sides, the index
knuckle at the front of the hand and the little finger's at its back (the palm faces the thigh at rest),
the heel behind the foot and the toes in front."""


def anchors(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Each landmark's component (33,) int (-1 when the model has none) and its point (33, 3) in that
    component's frame: the joint centres of :data:`tracker.tracking.keypoint_cue.SIDES` and the :data:`SURFACE`
    points (where the component's first quadric is an ellipsoid or a sphere).

    A shoulder, elbow, wrist, hip, knee or ankle marks the joint centre of a :data:`SIDES` component (its
    origin).  The nose and ears, the index and little-finger knuckles, the heel and the toes mark points on
    the surface of the head, hand and foot: ``c + d * r`` on the component's first ellipsoid (centre c,
    radii r) in the direction d of :data:`SURFACE`, with the component frames of models/human.toml (x to
    the body's left, y backwards, z up at rest)."""
    component, point, _ = landmark_points(model, LANDMARKS)
    for name, (part, direction) in SURFACE.items():
        if part not in model.names:
            continue
        index = model.index(part)
        owned = np.flatnonzero(model.quadric_component == index)
        if len(owned) == 0 or model.quadric_shape[owned[0]] not in ("ellipsoid", "sphere"):
            continue
        params = model.quadric_params[owned[0]]
        radii = np.asarray(params["radii"] if "radii" in params else [params["radius"]] * 3, float)
        centre = np.asarray(params.get("center", [0.0, 0.0, 0.0]), float)
        component[LANDMARKS.index(name)] = index
        point[LANDMARKS.index(name)] = centre + np.multiply(direction, radii)
    return component, point


KNUCKLES = ("left_pinky", "right_pinky", "left_index", "right_index")
"""Landmarks the tracker's cue leaves out: BlazePose places the knuckles from the body's image alone, and
they stray far more than the wrist that already marks the hand (docs/history.md); the first pose's fit still
uses them to turn the hand."""


def cue_points(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """:func:`anchors` without the :data:`KNUCKLES` (component -1): the landmarks the tracker fuses."""
    component, point = anchors(model)
    component[[LANDMARKS.index(name) for name in KNUCKLES]] = -1
    return component, point


def placers(model: Model, component: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The component (K,) whose pose places each joint landmark: the parent of ``component`` for a landmark at
    its joint centre (``point`` zero; a wrist is where the forearm ends); -1 for the others, on the surface of
    the head, hands and feet (small parts whose outlines fit the edges worse even where tracked right, the
    feet against the floor's), and for a landmark without a component."""
    parent = model.parent[np.maximum(component, 0)]
    centre = (component >= 0) & ~np.any(point, axis=1) & (parent >= 0)
    return np.where(centre, parent, -1)


def limbs(model: Model, component: np.ndarray) -> np.ndarray:
    """The limb each landmark can lead (K, N) bool (:meth:`tracker.tracking.track.Tracker.lead`): for a landmark
    on a component whose parent has no other child (an elbow, wrist, knee or ankle, or a point on a hand or foot),
    the whole chain of such components above it, up to the one that hangs from a branching component (the upper arm
    below the torso, the thigh below the pelvis), with everything below; none for the others (a shoulder, a hip, a
    face point: moving them moves the trunk) and for a landmark without a component."""
    parent = model.parent
    children = np.bincount(parent[parent >= 0], minlength=model.size)
    out = np.zeros((len(component), model.size), bool)
    for j, i in enumerate(component):
        if i < 0 or parent[i] < 0 or children[parent[i]] != 1:
            continue
        top = parent[i]
        while parent[top] >= 0 and children[parent[top]] == 1:
            top = parent[top]
        out[j] = with_descendants(parent, np.arange(model.size) == top)
    return out


def landmark_world(poses: np.ndarray, component: np.ndarray, point: np.ndarray) -> np.ndarray:
    """World points (K, 3) of the landmarks' model points ``point`` (K, 3), fixed in components ``component``
    (K,), at ``poses`` (N, 4, 4); NaN for landmarks without a component (-1)."""
    out = np.full((len(component), 3), np.nan)
    marked = component >= 0
    out[marked] = np.einsum("kij,kj->ki", poses[component[marked], :3, :3], point[marked])
    out[marked] += poses[component[marked], :3, 3]
    return out


def landmark_points(model: Model, landmarks: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each of ``landmarks``: its component (K,) int (-1 when the model has none) and its point (K, 3)
    in that component's frame (the joint centre), and the left/right pairs (P, 2) of landmark indices."""
    component = np.full(len(landmarks), -1, np.int64)
    for index, name in enumerate(landmarks):
        side, _, part = name.partition("_")
        if side in ("left", "right") and part in SIDES and f"{SIDES[part]}_{side[0]}" in model.names:
            component[index] = model.names.index(f"{SIDES[part]}_{side[0]}")
    return component, np.zeros((len(landmarks), 3)), left_right_pairs(landmarks)


TRUNK_TURN = 0.35
"""Radians the joints between the hips and the shoulders (:func:`trunk`) turn from rest before the fits of the
first pose and the re-seeds (:mod:`tracker.keypoints.fit`) and the tracker (``Settings.trunk_hold``) pull them
back: the pelvis turns about the line through the hips without moving them, so neither the landmarks nor the
pelvis's round outline see its pitch well, and hips that the detector reads a few centimetres high (behind a table)
would otherwise fold the trunk to its limit to reach them (docs/keypoints.md, "The trunk held near rest")."""


def trunk(model: Model, component: np.ndarray) -> np.ndarray:
    """The components (T,) whose joints lie on the path between the hips' parent and the shoulders' parent, from
    the landmarks' components ``component`` (33,) (:func:`landmark_points`): the torso's joint with the pelvis in
    models/human.toml; none when the model has no hips or shoulders."""
    ends = [component[LANDMARKS.index(f"{side}_{part}")] for part in ("hip", "shoulder") for side in ("left", "right")]
    if min(ends) < 0:
        return np.zeros(0, np.int64)
    n = model.size
    under = np.array([with_descendants(model.parent, np.arange(n) == c) for c in range(n)])  # x is c or below it
    on_path = np.zeros(n, bool)  # a joint lies on the path where one end is at or below its component, not both
    for low in {model.parent[i] for i in ends[:2]}:
        for high in {model.parent[i] for i in ends[2:]}:
            on_path |= under[:, low] != under[:, high]
    return np.flatnonzero(on_path)


def left_right_pairs(landmarks: tuple[str, ...]) -> np.ndarray:
    """The (P, 2) indices of ``left_<part>`` and ``right_<part>`` for every part named both ways in ``landmarks``."""
    pairs = [
        (index, landmarks.index("right_" + name[5:]))
        for index, name in enumerate(landmarks)
        if name.startswith("left_") and "right_" + name[5:] in landmarks
    ]
    return np.array(pairs, np.int64).reshape(-1, 2)


SWAP_MARGIN = 0.02
"""Share of the body's image size by which a left/right pair must fit better as detected than swapped to count
in full (:func:`keypoint_kernel`); below it, its weight falls linearly to zero where the two fit alike."""


@njit(cache=True)
def project_point(k_mat, lens, dist, camera_from_component, point):
    """Recorded pixel (2,) of ``point`` (3,) of a component and its Jacobian (2, 6) with respect to the
    component's body twist, through the lens model ``lens``, ``dist`` (:mod:`tracker.geometry.lens`);
    NaN when the point is behind the camera."""
    e = camera_from_component
    x_cam = e[:3, :3] @ point + e[:3, 3]
    jac = np.zeros((2, 6))
    if x_cam[2] <= 1e-9:
        return np.full(2, np.nan), jac
    depth = x_cam[2]
    px = k_mat[0, 0] * x_cam[0] / depth + k_mat[0, 1] * x_cam[1] / depth + k_mat[0, 2]
    py = k_mat[1, 1] * x_cam[1] / depth + k_mat[1, 2]
    u, v, j00, j01, j10, j11 = distort(k_mat, lens, dist, px, py)
    for row in range(2):
        gx, gy = (j00, j01) if row == 0 else (j10, j11)
        rx, ry, rz = component_row(k_mat, e, px, py, depth, gx, gy)
        jac[row, 0] = rx
        jac[row, 1] = ry
        jac[row, 2] = rz
        jac[row, 3] = point[1] * rz - point[2] * ry
        jac[row, 4] = point[2] * rx - point[0] * rz
        jac[row, 5] = point[0] * ry - point[1] * rx
    return np.array([u, v]), jac


@njit(cache=True, nogil=True)
def keypoint_kernel(
    poses,
    gains,
    camera_from_world,
    matrix,
    lens,
    distortion,
    component,
    point,
    pairs,
    pixels,
    confidence,
    min_confidence,
    robust_c,
    scale,
    tolerance,
    reach,
    information,
    eta,
    misfit,
):
    """Add every usable landmark's w J^T J and w J^T r to ``information`` (N, 6, 6) and ``eta`` (N, 6), each view's
    landmarks placed by the ``poses`` (C, N, 4, 4) of that camera's capture time and its Jacobians scaled by its
    ``gains`` (C,), how far its view moves as the poses move (docs/sync.md).

    ``camera_from_world``, ``matrix``, ``lens`` and ``distortion`` are the rig's
    (:class:`tracker.tracking.outline.Rig`); ``pixels`` (C, K, 2) and ``confidence`` (C, K) are one frame's
    detections; a landmark is used when its component is >= 0, its confidence at least ``min_confidence``, its pixel
    finite, and it is not half of a left/right pair of ``pairs`` (P, 2) that fits better swapped: a pair's weight
    falls from full, where swapping it would lengthen its two residuals by :data:`SWAP_MARGIN` of the body's size or
    more, to zero where swapping would not lengthen them, so that a pair on the fence counts a little rather than all
    or nothing.  Each residual is shrunk by the detector's noise, ``tolerance`` (K,) times the predicted body's size
    in that image (the diagonal of its landmarks' bounding box): a landmark within it is not used, one further is
    weighted by its excess e = |r| - radius, w = s q (e / |r|) / ((c + e) (1 + (e / (reach size))^2)), so its pull
    grows from zero at the zone's edge and fades again beyond ``reach`` (K,) times the body's size (a wrong detection,
    or a body that far off, is left to the recovery; inf: no fade).  ``misfit`` (C, K) receives |r| over the body's
    size for every usable landmark, NaN for the others.  Returns (landmarks used, pairs
    rejected)."""
    cameras, count = pixels.shape[0], pixels.shape[1]
    misfit[:] = np.nan
    used = 0
    rejected = 0
    predicted = np.full((count, 2), np.nan)
    jacobians = np.zeros((count, 2, 6))
    usable = np.zeros(count, np.bool_)
    trust = np.ones(count)
    for k in range(cameras):
        low = np.full(2, np.inf)
        high = np.full(2, -np.inf)
        for j in range(count):
            i = component[j]
            predicted[j] = np.nan
            if i >= 0:
                predicted[j], jacobians[j] = project_point(
                    matrix[k], lens[k], distortion[k], camera_from_world[k] @ poses[k, i], point[j]
                )
                jacobians[j] *= gains[k]
                if np.isfinite(predicted[j, 0]):
                    low = np.minimum(low, predicted[j])
                    high = np.maximum(high, predicted[j])
            usable[j] = (
                i >= 0
                and confidence[k, j] >= min_confidence
                and np.isfinite(pixels[k, j, 0])
                and np.isfinite(pixels[k, j, 1])
                and np.isfinite(predicted[j, 0])
            )
        size = np.sqrt(((high - low) ** 2).sum()) if high[0] >= low[0] else 0.0
        trust[:] = 1.0
        for p in range(pairs.shape[0]):
            a, b = pairs[p, 0], pairs[p, 1]
            if usable[a] and usable[b] and size > 0.0:
                straight = np.linalg.norm(pixels[k, a] - predicted[a]) + np.linalg.norm(pixels[k, b] - predicted[b])
                swapped = np.linalg.norm(pixels[k, a] - predicted[b]) + np.linalg.norm(pixels[k, b] - predicted[a])
                margin = (swapped - straight) / (SWAP_MARGIN * size)
                trust[a] = trust[b] = min(max(margin, 0.0), 1.0)
                if margin <= 0.0:
                    rejected += 1
        for j in range(count):
            if not usable[j] or trust[j] <= 0.0:
                continue
            r = pixels[k, j] - predicted[j]
            length = np.sqrt(r[0] * r[0] + r[1] * r[1])
            if size > 0.0:
                misfit[k, j] = length / size
            radius = tolerance[j] * size
            excess = length - radius
            if radius > 0.0 and excess <= 0.0:
                continue
            share = excess / length if radius > 0.0 else 1.0
            fade = excess / (reach[j] * size) if size > 0.0 else 0.0
            w = scale * trust[j] * confidence[k, j] * share / ((robust_c + excess) * (1.0 + fade * fade))
            jac = jacobians[j]
            information[component[j]] += w * (jac.T @ jac)
            eta[component[j]] += w * (jac.T @ r)
            used += 1
    return used, rejected
