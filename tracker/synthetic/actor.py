"""A rendered body unlike the tracking model: its sizes perturbed, and every part a capsule or the model's own.

The actor keeps the model's components, joints and limits, so it plays the same motion.  A capsule body:

    part        a capsule (a cylinder closed by two spheres) instead of the model's quadric: a cone
                or cylinder keeps its axis and takes the mean radius; an ellipsoid becomes the
                capsule along its longest axis, as long, with the mean of the other two radii
    length      the part and the joints of its children (their ``at``) scaled by l in [1 - j, 1 + j]
    radius      the capsule's radius scaled by r in [1 - j, 1 + j]

with l, r drawn from the seed, the same for a left and a right part.  A stretched body keeps the model's quadrics,
each part and its children's joints stretched by l along the part's z (its bone) and by r across it
(:func:`tracker.proportions.stretched`): the body a fitted model should find.  The actor's poses take the
model's rotations and root, hang each part on its own (perturbed) joints and lift the body so its
feet stand where the model's stood; its joint centres are then what motion capture of the rendered
body would give.
"""

from __future__ import annotations

import copy

import numpy as np

from tracker.model import Model, poses_from_rotations
from tracker.proportions import stretched
from tracker.synthetic.clips import lowest_points


def part_factors(data: dict, jitter: float = 0.1, seed: int = 0) -> dict[str, np.ndarray]:
    """Per component of a model TOML document (parsed), its length and radius factors (2,), drawn from ``seed``
    within [1 - ``jitter``, 1 + ``jitter``], the same for a left and a right part."""
    rng = np.random.default_rng([seed, 3])
    names = [str(c["name"]) for c in data["component"]]
    pairs = sorted({_pair(name) for name in names})
    factors = {pair: rng.uniform(1.0 - jitter, 1.0 + jitter, 2) for pair in pairs}
    return {name: factors[_pair(name)] for name in names}


def capsule_body(data: dict, jitter: float = 0.1, seed: int = 0) -> dict:
    """A model TOML document (parsed) whose every part is a capsule of perturbed size (see the module)."""
    factors = part_factors(data, jitter, seed)
    components = copy.deepcopy(data["component"])
    for component in components:
        parent = str(component.get("parent", ""))
        if parent and "at" in component:
            component["at"] = [factors[parent][0] * float(v) for v in component["at"]]
        scale, widen = factors[str(component["name"])]
        component["quadric"] = [
            piece for spec in component.get("quadric", []) for piece in _capsule(spec, scale, widen)
        ]
    return {**data, "name": f"{data.get('name', 'model')}-capsules", "component": components}


def stretched_body(data: dict, jitter: float = 0.1, seed: int = 0) -> dict:
    """A model TOML document (parsed) of the model's own parts, each stretched along its frame's z by its length
    factor and across it by its radius factor (:func:`part_factors`, :func:`tracker.proportions.stretched`)."""
    factors = {
        name: np.array([widen, widen, length]) for name, (length, widen) in part_factors(data, jitter, seed).items()
    }
    return stretched(data, factors, name=f"{data.get('name', 'model')}-stretched")


def _pair(name: str) -> str:
    """A part's name without its side: ``thigh_l`` and ``thigh_r`` share their factors."""
    return name[:-2] if name.endswith(("_l", "_r")) else name


def _capsule(spec: dict, scale: float, widen: float) -> list[dict]:
    """The quadric tables of the capsule replacing one model quadric, lengths x ``scale``, radius x ``widen``
    (an ellipsoid's clipping planes are dropped: the capsule is whole)."""
    shape = spec["shape"]
    if shape in ("cone", "cylinder"):
        radii = spec["radii"] if shape == "cone" else [spec["radius"]] * 2
        start = scale * np.asarray(spec["from"], dtype=np.float64)
        end = scale * np.asarray(spec["to"], dtype=np.float64)
        radius = widen * float(np.mean(radii))
    else:
        centre = scale * np.asarray(spec.get("center", [0.0, 0.0, 0.0]), dtype=np.float64)
        radii = np.full(3, float(spec["radius"])) if shape == "sphere" else np.asarray(spec["radii"], float)
        long = int(np.argmax(radii))
        radius = widen * float(np.mean(np.delete(radii, long)))
        half = max(scale * float(radii[long]) - radius, 0.0)
        start, end = centre - half * np.eye(3)[long], centre + half * np.eye(3)[long]
    caps = [{"shape": "sphere", "center": [float(v) for v in p], "radius": radius} for p in (start, end)]
    if np.linalg.norm(end - start) < 1e-6:
        return caps[:1]
    tube = {"shape": "cylinder", "from": [float(v) for v in start], "to": [float(v) for v in end], "radius": radius}
    return [tube, *caps]


def actor_poses(actor: Model, model: Model, poses: np.ndarray) -> np.ndarray:
    """The actor's poses (F, N, 4, 4) playing the model's poses (F, N, 4, 4): the same rotations and root,
    each part on the actor's joints, lifted by one height so that the median over frames of the lowest
    surface point is the model's."""
    out = np.stack([poses_from_rotations(actor, p[0, 0:3, 3], p[:, 0:3, 0:3]) for p in poses])
    lift = np.median(lowest_points(model, poses)) - np.median(lowest_points(actor, out))
    out[:, :, 2, 3] += lift
    return out
