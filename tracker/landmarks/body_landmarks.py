"""The detector's landmarks on the body model (docs/keypoints.md): BlazePose's 33 names, the model point each one
marks (:func:`anchors`), the component that places each joint landmark (:func:`placers`), the limb each can lead
(:func:`limbs`), the trunk's joints (:func:`trunk`) and the left/right pairs."""

from __future__ import annotations

import numpy as np

from tracker.model import Model, with_descendants

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
    component's frame: the joint centres of :data:`tracker.landmarks.body_landmarks.SIDES` and the :data:`SURFACE`
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
they stray far more than the wrist that already marks the hand; the first pose's fit still
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
    """The limb each landmark can lead (K, N) bool (:meth:`tracker.tracking.lead.Lead.retry`): for a landmark
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
first pose and the re-seeds (:mod:`tracker.seeding.pose_fit`) and the tracker (``SolveSettings.trunk_hold``) pull them
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
