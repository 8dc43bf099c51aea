"""A body model's proportions: its joints placed anew and its parts stretched along their own axes, and the
sizes that shows (docs/fit-model.md).

A model's shape is the place ``at_i`` of every joint in its parent's frame and, per component c, three factors
``a_c = (a_x, a_y, a_z)`` that stretch its quadrics along the axes of its frame (at rest: x to the body's left,
y backwards, z up; a limb's z runs along its bone):

    a quadric's centre, ``from``, ``to`` -> a_c * (...),   an ellipsoid's radii -> a_c * radii,
    a cone's or cylinder's radii -> their mean factor across its axis, sum_k a_k (1 - d_k^2) / 2 (d its unit
    axis), a sphere's radius -> the mean of a_c,   an ellipsoid's clip [z0, z1] -> a_z [z0, z1]

(products elementwise).  Rotations, joint axes and limits do not change, so a pose of the model is a pose of
the reshaped model, each part hung on its own joints.  :func:`stretched` also moves the children's joints with
their parent's factors, ``at_child -> a_c * at_child``: a body stretched whole.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np


def reshaped(
    document: dict, joints: dict[str, np.ndarray], factors: dict[str, np.ndarray], *, name: str | None = None
) -> dict:
    """A model TOML document (parsed, formats.md "Body model") with the joints named in ``joints`` at their new
    ``at`` (3,) and the quadrics of the components named in ``factors`` stretched by their (3,) factors (module
    docstring); the rest as it was.  ``name`` renames the model."""
    components = copy.deepcopy(document["component"])
    for component in components:
        key = str(component["name"])
        if key in joints and component.get("parent", ""):
            component["at"] = _rounded(np.asarray(joints[key], np.float64))
        if key in factors:
            factor = np.asarray(factors[key], np.float64)
            component["quadric"] = [_stretched_quadric(spec, factor) for spec in component.get("quadric", [])]
    out = {**document, "component": components}
    if name is not None:
        out["name"] = name
    return out


def stretched(document: dict, factors: dict[str, np.ndarray], *, name: str | None = None) -> dict:
    """A model TOML document (parsed) with each component named in ``factors`` stretched by its (3,) factors, its
    quadrics and its children's joints (module docstring)."""
    joints = {}
    for component in document["component"]:
        parent = str(component.get("parent", ""))
        if parent in factors:
            at = np.asarray(component.get("at", [0.0, 0.0, 0.0]), np.float64)
            joints[str(component["name"])] = np.asarray(factors[parent], np.float64) * at
    return reshaped(document, joints, factors, name=name)


def _stretched_quadric(spec: dict, factor: np.ndarray) -> dict:
    """One ``[[component.quadric]]`` table stretched by ``factor`` (3,) (module docstring)."""
    out = dict(spec)
    shape = spec["shape"]
    if shape in ("cone", "cylinder"):
        start, end = np.asarray(spec["from"], np.float64), np.asarray(spec["to"], np.float64)
        axis = (end - start) / np.linalg.norm(end - start)
        across = float(factor @ (1.0 - axis**2)) / 2.0
        out["from"], out["to"] = _rounded(factor * start), _rounded(factor * end)
        if shape == "cone":
            out["radii"] = _rounded(across * np.asarray(spec["radii"], np.float64))
        else:
            out["radius"] = _round(across * float(spec["radius"]))
        return out
    if "center" in spec:
        out["center"] = _rounded(factor * np.asarray(spec["center"], np.float64))
    if shape == "sphere":
        out["radius"] = _round(float(np.mean(factor)) * float(spec["radius"]))
    else:
        out["radii"] = _rounded(factor * np.asarray(spec["radii"], np.float64))
    if "clip" in spec:
        out["clip"] = _rounded(factor[2] * np.asarray(spec["clip"], np.float64))
    return out


DECIMALS = 5
"""Metres are written to 0.01 mm: a fitted model stays readable and round-trips exactly."""


def _round(value: float) -> float:
    return round(float(value), DECIMALS)


def _rounded(values: np.ndarray) -> list[float]:
    return [_round(v) for v in values]


@dataclass(frozen=True)
class Size:
    """One size of a model: ``component``, ``what`` it measures (``length to <child>``: the distance from the
    component's joint to its child's; ``radius <k> of quadric <q>``), and its ``metres``."""

    component: str
    what: str
    metres: float


def sizes(document: dict) -> list[Size]:
    """The sizes of a model TOML document (parsed): every joint's distance from its parent's joint, then every
    quadric's radii, component by component in the file's order."""
    components = document["component"]
    out = []
    for component in components:
        name = str(component["name"])
        for child in components:
            if str(child.get("parent", "")) == name:
                at = np.asarray(child.get("at", [0.0, 0.0, 0.0]), np.float64)
                out.append(Size(name, f"length to {child['name']}", float(np.linalg.norm(at))))
        for q, spec in enumerate(component.get("quadric", [])):
            radii = spec["radii"] if "radii" in spec else [spec["radius"]]
            for k, radius in enumerate(radii):
                out.append(Size(name, f"radius {k} of quadric {q}", float(radius)))
    return out
