"""The ray caster against analytic answers, its pure-numpy reference and the limbs it should hit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker import raycast
from tracker.camera import look_at_camera
from tracker.geometry import se3
from tracker.model import load_model, model_from_dict, rest_poses
from tracker.raycast import RayCaster
from tracker.synthetic import clips

MODEL = Path(__file__).resolve().parents[1] / "models" / "human.toml"


@pytest.fixture(scope="module")
def human():
    return load_model(MODEL)


def _one_component(shape: dict) -> object:
    return model_from_dict({"component": [{"name": "body", "parent": "", "joint": "free", "quadric": [shape]}]})


def _cast(model, poses, camera):
    return [a.copy() for a in RayCaster(model, camera).cast(poses)]


@pytest.mark.parametrize("distortions", [(0.0, 0.0, 0.0, 0.0), (-0.08, 0.02, 0.0, 0.0)])
def test_sphere_silhouette_matches_analytic_projection(distortions):
    radius, distance, f = 0.3, 3.0, 200.0
    model = _one_component({"shape": "sphere", "center": [0, 0, 0], "radius": radius})
    camera = look_at_camera(
        "c", (0.0, -distance, 0.0), (0.0, 0.0, 0.0), size=(161, 121), focal=f, distortions=distortions
    )
    comp, shade, depth = _cast(model, np.eye(4)[None], camera)
    # the silhouette is the cone of rays tangent to the sphere: a circle of normalised radius rho
    rho = radius / np.sqrt(distance**2 - radius**2)
    k1, k2 = distortions[0], distortions[1]
    expected = f * rho * (1 + k1 * rho**2 + k2 * rho**4)
    measured = np.sqrt(np.count_nonzero(comp == 0) / np.pi)
    assert measured == pytest.approx(expected, abs=0.3)
    row = np.flatnonzero(comp[60] == 0)
    assert (row[-1] - row[0] + 1) / 2 == pytest.approx(expected, abs=1.0)
    assert depth[60, 80] == pytest.approx(distance - radius, abs=1e-9)  # centre pixel: the nearest point
    assert shade[comp == 0].min() > 0 and np.all(shade[comp < 0] == 0)


def test_kernel_matches_pure_render(human):
    camera = look_at_camera(
        "c", (2.5, -2.5, 1.4), (0, 0, 0.9), size=(120, 100), focal=150.0, distortions=(-0.08, 0.02, 0, 0)
    )
    poses = clips.procedural_motion(human, 1, seed=1)[0]
    comp, shade, depth = _cast(human, poses, camera)
    surfaces, planes = raycast.view_quadrics(human, poses, camera)
    light = camera.rotation @ (raycast.DEFAULT_LIGHT / np.linalg.norm(raycast.DEFAULT_LIGHT))
    comp2, shade2, depth2 = raycast.render(
        raycast.pixel_rays(camera), surfaces, planes, owner=human.quadric_component, light=light
    )
    assert np.count_nonzero(comp >= 0) > 500
    assert np.count_nonzero(comp != comp2) <= 2  # root ties at grazing rays only
    same = (comp == comp2) & (comp >= 0)
    np.testing.assert_allclose(shade[same], shade2[same], atol=1e-6)
    np.testing.assert_allclose(depth[same], depth2[same], rtol=1e-6)


def test_rays_through_limbs_hit_them(human):
    poses = rest_poses(human, se3.from_rotvec(np.zeros(3), (0.0, 0.0, 0.92)))
    camera = look_at_camera(
        "c", (0.3, -3.5, 1.0), (0, 0, 0.9), size=(320, 240), focal=260.0, distortions=(-0.08, 0.02, 0, 0)
    )
    comp, _, _ = _cast(human, poses, camera)
    middles = {  # a point on each limb's axis, in its frame
        "upperarm_l": -0.145,
        "upperarm_r": -0.145,
        "forearm_l": -0.125,
        "forearm_r": -0.125,
        "thigh_l": -0.21,
        "thigh_r": -0.21,
        "shin_l": -0.2,
        "shin_r": -0.2,
        "torso": 0.2,
        "head": 0.14,
    }
    for name, z in middles.items():
        i = human.index(name)
        u, v = np.rint(camera.project((poses[i] @ [0.0, 0.0, z, 1.0])[None, 0:3])[0]).astype(int)
        assert human.names[comp[v, u]] == name
    # joint centres (knees, elbows) are on one of the two limbs they join
    for name in ("shin_l", "forearm_r"):
        i = human.index(name)
        u, v = np.rint(camera.project(poses[i, 0:3, 3][None])[0]).astype(int)
        assert comp[v, u] in (i, human.parent[i])


def test_clipped_cylinder_ends_and_open_tube():
    model = _one_component({"shape": "cylinder", "from": [0, 0, 0], "to": [0, 0, -0.4], "radius": 0.05})
    side = look_at_camera("c", (0.0, -2.0, -0.2), (0.0, 0.0, -0.2), size=(200, 200), focal=300.0)
    comp, _, _ = _cast(model, np.eye(4)[None], side)
    for z, seen in ((-0.39, True), (-0.41, False), (-0.01, True), (0.01, False)):
        u, v = np.rint(side.project(np.array([[0.0, -0.05, z]]))[0]).astype(int)
        assert (comp[v, u] == 0) == seen, z
    # looking obliquely into the open top: the ray through its centre hits the far inside wall
    eye = np.array([0.0, -1.0, 1.0])
    into = look_at_camera("c", eye, (0.0, 0.0, 0.0), size=(201, 201), focal=300.0)
    comp, shade, depth = _cast(model, np.eye(4)[None], into)
    assert comp[100, 100] == 0
    direction = -eye / np.linalg.norm(eye)
    # far intersection with x^2 + y^2 = r^2 along eye + s d: (-1 + s d_y)^2 = 0.05^2 -> s = (1 + 0.05)/d_y
    s = (1.0 + 0.05) / direction[1]
    assert depth[100, 100] == pytest.approx(s * (direction @ (into.rotation[2])), rel=1e-9)
    assert shade[100, 100] > 0
