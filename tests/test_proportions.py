"""A model's proportions (tracker.proportions): stretched parts, placed joints, the sizes listed, the file."""

from __future__ import annotations

import numpy as np
from conftest import HUMAN

from tracker.geometry.quadric import evaluate
from tracker.model import load_model, model_from_dict, save_model
from tracker.proportions import reshaped, sizes, stretched
from tracker.tomlfile import read_toml


def test_a_stretched_part_maps_its_surface_onto_the_stretched_surface():
    """Every quadric of the stretched model holds the points of the model's quadrics stretched by the same
    factors (a cone's radius by its mean factor across the axis), and the children's joints move with them."""
    document = read_toml(HUMAN, "model", "")
    factors = {
        "torso": np.array([0.9, 1.1, 1.2]),
        "shin_l": np.array([1.1, 1.1, 0.8]),
        "head": np.array([1.0, 0.9, 1.1]),
    }
    base, out = model_from_dict(document), model_from_dict(stretched(document, factors))
    rng = np.random.default_rng(0)
    for name, factor in factors.items():
        [q] = np.flatnonzero(base.quadric_component == base.index(name))
        params = base.quadric_params[q]
        if params["shape"] == "ellipsoid":
            direction = rng.normal(size=(20, 3))
            direction /= np.linalg.norm(direction, axis=1, keepdims=True)
            points = np.asarray(params["center"]) + direction * np.asarray(params["radii"])
            moved = factor * points
        else:  # a cone along z: axis points scale by the factors, the radius by the mean across
            start, end = np.asarray(params["from"]), np.asarray(params["to"])
            t, angle = rng.uniform(0.1, 0.9, 20), rng.uniform(0, 2 * np.pi, 20)
            radius = params["radii"][0] + t * (params["radii"][1] - params["radii"][0])
            ring = np.stack([np.cos(angle), np.sin(angle), 0 * angle], 1) * radius[:, None]
            points = start + t[:, None] * (end - start) + ring
            moved = factor * (start + t[:, None] * (end - start)) + (factor[0] + factor[1]) / 2 * ring
        assert np.abs(evaluate(base.quadric[q], points)).max() < 1e-9
        assert np.abs(evaluate(out.quadric[q], moved)).max() < 1e-9
    for child in ("head", "upperarm_l", "upperarm_r"):
        i = base.index(child)
        np.testing.assert_allclose(out.rest[i, :3, 3], factors["torso"] * base.rest[i, :3, 3], atol=1e-5)
    np.testing.assert_allclose(out.rest[base.index("foot_l"), :3, 3], [0, 0, -0.41 * 0.8], atol=1e-5)
    np.testing.assert_allclose(out.rest[base.index("foot_r")], base.rest[base.index("foot_r")])


def test_reshaped_places_joints_apart_from_the_parts():
    document = read_toml(HUMAN, "model", "")
    out = model_from_dict(reshaped(document, {"forearm_l": np.array([0.01, 0.02, -0.3])}, {}))
    base = model_from_dict(document)
    np.testing.assert_allclose(out.rest[base.index("forearm_l"), :3, 3], [0.01, 0.02, -0.3])
    np.testing.assert_allclose(out.quadric, base.quadric)


def test_sizes_list_every_joint_distance_and_radius():
    document = read_toml(HUMAN, "model", "")
    listed = {(size.component, size.what): size.metres for size in sizes(document)}
    assert listed[("upperarm_l", "length to forearm_l")] == 0.29
    assert np.isclose(listed[("torso", "length to upperarm_r")], np.hypot(0.2, 0.42))
    assert listed[("shin_l", "radius 1 of quadric 0")] == 0.035
    assert sum(what.startswith("length") for _, what in listed) == 14


def test_a_saved_model_reads_back_the_same(tmp_path):
    document = stretched(read_toml(HUMAN, "model", ""), {"thigh_l": np.array([1.05, 1.05, 1.1])}, name="mine")
    save_model(tmp_path / "m.toml", document, "fitted here\n\nby a test")
    text = (tmp_path / "m.toml").read_text()
    assert text.startswith("# fitted here\n#\n# by a test\n")
    again = load_model(tmp_path / "m.toml")
    model = model_from_dict(document)
    assert again.name == "mine" and again.names == model.names
    np.testing.assert_allclose(again.quadric, model.quadric)
    np.testing.assert_allclose(again.rest, model.rest)
    np.testing.assert_array_equal(again.upper, model.upper)
