"""Body model TOML loader (tracker.model)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from tracker import chain
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.geometry.quadric import evaluate
from tracker.model import load_model, poses_from_rotations, rest_poses, with_descendants

HUMAN = Path(__file__).resolve().parents[1] / "models" / "human.toml"

SPHERE = '\n  [[component.quadric]]\n  shape = "sphere"\n  radius = 0.1\n'


def component(name, parent="", extra="", quadric=SPHERE):
    return f'[[component]]\nname = "{name}"\nparent = "{parent}"\n{extra}{quadric}\n'


def test_human_loads():
    model = load_model(HUMAN)
    assert model.size == 15
    assert model.names[0] == "pelvis" and model.parent[0] == -1
    assert np.all(model.parent[1:] < np.arange(1, 15)) and np.all(model.parent[1:] >= 0)
    assert len(set(model.names)) == 15
    # the tree is the file's: every component's parent by name
    spec = {c["name"]: c for c in tomllib.loads(HUMAN.read_text())["component"]}
    assert set(spec) == set(model.names)
    for i, name in enumerate(model.names[1:], start=1):
        assert model.names[model.parent[i]] == spec[name]["parent"]
        np.testing.assert_allclose(model.rest[i][:3, 3], spec[name].get("at", [0, 0, 0]))
    assert model.joint_type[model.index("forearm_l")] == chain.HINGE
    assert model.joint_type[model.index("torso")] == chain.BALL
    assert model.joint_type[0] == chain.FREE
    assert len(model.quadric) == 15 and np.all(np.bincount(model.quadric_component) == 1)
    np.testing.assert_allclose(model.quadric, np.transpose(model.quadric, (0, 2, 1)))


def test_human_quadrics_match_the_file():
    """Each quadric is zero on points of its surface and each clip keeps the surface between the ends."""
    model = load_model(HUMAN)
    for j, params in enumerate(model.quadric_params):
        q = model.quadric[j]
        u = np.linspace(0.1, 2 * np.pi, 7)
        if params["shape"] == "ellipsoid":
            radii = np.array(params["radii"])
            points = np.array(params["center"]) + radii * np.stack(
                [np.cos(u) * np.sin(u / 2), np.sin(u) * np.sin(u / 2), np.cos(u / 2)], 1
            )
            assert np.abs(evaluate(q, points)).max() < 1e-9
            assert evaluate(q, np.array(params["center"])[None])[0] < 0  # negative inside
        else:
            start, end = np.array(params["from"]), np.array(params["to"])
            r0, r1 = params["radii"]
            axis = (end - start) / np.linalg.norm(end - start)
            side = np.cross(axis, [1.0, 0.0, 0.0])
            side /= np.linalg.norm(side)
            for f in (0.0, 0.3, 1.0):
                point = start + f * (end - start) + (r0 + f * (r1 - r0)) * side
                assert abs(evaluate(q, point[None])[0]) < 1e-9
                assert evaluate(model.clip[j], point[None])[0] <= 1e-12
            beyond = end + 0.05 * axis
            assert evaluate(model.clip[j], beyond[None])[0] > 0


BAD_MODELS = {
    "cycle": component("root") + component("a", "b") + component("b", "a"),
    "unknown_parent": component("root") + component("a", "nobody"),
    "two_roots": component("root") + component("other"),
    "no_root": component("a", "b") + component("b", "a"),
    "unknown_shape": component("root", quadric='\n  [[component.quadric]]\n  shape = "torus"\n  radius = 0.1\n'),
    "negative_radius": component("root", quadric='\n  [[component.quadric]]\n  shape = "sphere"\n  radius = -0.1\n'),
    "negative_cone_radius": component(
        "root",
        quadric='\n  [[component.quadric]]\n  shape = "cone"\n  from = [0, 0, 0]\n  to = [0, 0, 1]\n'
        "  radii = [0.1, -0.05]\n",
    ),
    "hinge_zero_axis": component("root") + component("a", "root", 'joint = "hinge"\naxis = [0.0, 0.0, 0.0]\n'),
    "duplicate_names": component("root") + component("a", "root") + component("a", "root"),
    "bad_toml": component("root") + "[[component]\nname = ",
    "no_quadrics": component("root", quadric=""),
    "root_not_free": component("root", extra='joint = "ball"\n'),
}


@pytest.mark.parametrize("case", list(BAD_MODELS))
def test_bad_model_names_the_file(tmp_path, case):
    path = tmp_path / f"{case}.toml"
    path.write_text(BAD_MODELS[case])
    with pytest.raises(TrackerInputError) as info:
        load_model(path)
    assert str(path) in str(info.value)


def test_missing_model_file(tmp_path):
    path = tmp_path / "nowhere" / "model.toml"
    with pytest.raises(TrackerInputError) as info:
        load_model(path)
    assert str(path) in str(info.value)


def test_good_small_model_loads_in_breadth_first_order(tmp_path):
    text = (
        component("c", "b")
        + component("b", "root")
        + component("root")
        + component("d", "root")
        + component("e", "c", 'joint = "hinge"\naxis = [0.0, 2.0, 0.0]\nat = [0.1, 0.2, 0.3]\n')
    )
    path = tmp_path / "small.toml"
    path.write_text(text)
    model = load_model(path)
    assert model.names[0] == "root"
    assert np.all(model.parent[1:] < np.arange(1, model.size))
    for i in range(1, model.size):
        assert model.names[model.parent[i]] == {"b": "root", "c": "b", "d": "root", "e": "c"}[model.names[i]]
    np.testing.assert_allclose(model.axis[model.index("e")], [0.0, 1.0, 0.0])
    # quadrics follow their components
    assert [model.names[c] for c in model.quadric_component] == list(model.names)


def random_rotations(rng, n):
    return np.array([se3.exp_so3(rng.uniform(0, 2.5) * unit(rng)) for _ in range(n)])


def unit(rng):
    x = rng.normal(size=3)
    return x / np.linalg.norm(x)


def test_rest_poses_hang_children_on_their_parents_joints():
    rng = np.random.default_rng(0)
    model = load_model(HUMAN)
    spec = {c["name"]: c for c in tomllib.loads(HUMAN.read_text())["component"]}
    root = se3.from_rotvec(rng.normal(size=3), rng.normal(size=3))
    poses = rest_poses(model, root)
    np.testing.assert_allclose(poses[0], root, atol=1e-15)
    for i in range(1, model.size):
        at = np.append(spec[model.names[i]].get("at", [0, 0, 0]), 1.0)
        np.testing.assert_allclose(poses[i][:3, 3], (poses[model.parent[i]] @ at)[:3], atol=1e-12)
        rest_rotation = se3.exp_so3(np.array(spec[model.names[i]].get("rest", [0.0, 0.0, 0.0]), float))
        np.testing.assert_allclose(poses[i][:3, :3], poses[model.parent[i]][:3, :3] @ rest_rotation, atol=1e-12)


def test_poses_from_rotations_hang_children_on_their_parents_joints():
    rng = np.random.default_rng(1)
    model = load_model(HUMAN)
    spec = {c["name"]: c for c in tomllib.loads(HUMAN.read_text())["component"]}
    rotations = random_rotations(rng, model.size)
    root_t = rng.normal(size=3)
    poses = poses_from_rotations(model, root_t, rotations)
    np.testing.assert_allclose(poses[:, :3, :3], rotations, atol=0)
    np.testing.assert_allclose(poses[:, 3], np.tile([0, 0, 0, 1.0], (model.size, 1)), atol=0)
    np.testing.assert_allclose(poses[0, :3, 3], root_t, atol=0)
    for i in range(1, model.size):
        at = np.append(spec[model.names[i]].get("at", [0, 0, 0]), 1.0)
        np.testing.assert_allclose(poses[i][:3, 3], (poses[model.parent[i]] @ at)[:3], atol=1e-12)
    # with rest rotations the two agree
    rest = rest_poses(model, se3.from_rotvec(np.zeros(3), root_t))
    np.testing.assert_allclose(
        poses_from_rotations(model, root_t, np.tile(np.eye(3), (model.size, 1, 1))), rest, atol=1e-15
    )


@pytest.mark.parametrize(
    "text",
    [
        "component = [1]\n",
        '[[component]]\nname = "root"\nparent = ""\nquadric = [1]\n',
    ],
)
def test_non_table_entries_give_a_tracker_input_error(tmp_path, text):
    path = tmp_path / "odd.toml"
    path.write_text(text)
    with pytest.raises(TrackerInputError) as info:
        load_model(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    "extra, joint",
    [
        ("limits = [0.0, 1.0]", "ball"),
        ("limits = [1.0, 0.0]", "hinge"),
        ("max_angle = 1.0", "hinge"),
        ("max_angle = -1.0", "ball"),
        ("max_twist = 1.0", "hinge"),
        ("max_twist = 0.0", "ball"),
    ],
)
def test_bad_joint_limits_name_the_file(tmp_path, extra, joint):
    path = tmp_path / "limits.toml"
    path.write_text(
        '[[component]]\nname = "a"\nparent = ""\n[[component.quadric]]\nshape = "sphere"\nradius = 0.1\n'
        f'[[component]]\nname = "b"\nparent = "a"\njoint = "{joint}"\n{extra}\n'
        '[[component.quadric]]\nshape = "sphere"\nradius = 0.1\n'
    )
    with pytest.raises(TrackerInputError, match="limits.toml"):
        load_model(path)


def test_human_model_has_joint_limits():
    model = load_model(HUMAN)
    elbow = model.index("forearm_l")
    assert model.lower[elbow] == 0.0 and model.upper[elbow] == pytest.approx(2.6)
    assert model.upper[model.index("foot_r")] == pytest.approx(1.3)
    assert np.isinf(model.upper[model.index("thigh_l")])
    assert model.twist[model.index("upperarm_r")] == pytest.approx(2.0)
    assert np.isinf(model.twist[model.index("thigh_l")]) and np.isinf(model.twist[model.index("torso")])


def test_with_descendants_takes_every_part_below_the_chosen_ones():
    parent = np.array([-1, 0, 0, 1, 1, 2, 3])
    below_one = with_descendants(parent, np.arange(7) == 1)
    assert list(np.flatnonzero(below_one)) == [1, 3, 4, 6]
    assert list(np.flatnonzero(with_descendants(parent, np.isin(np.arange(7), [2, 3])))) == [2, 3, 5, 6]
    assert not with_descendants(parent, np.zeros(7, bool)).any()
