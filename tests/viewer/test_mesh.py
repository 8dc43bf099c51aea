from pathlib import Path

import numpy as np
import pytest

from tracker.geometry import quadric
from tracker.model import load_model
from tracker.viewer.mesh import component_meshes, cone_mesh, ellipsoid_mesh

ROOT = Path(__file__).resolve().parents[2]


def volume(vertices, faces):
    """Signed volume by the divergence theorem: positive for a closed mesh with outward faces."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


def test_ellipsoid_mesh_lies_on_the_surface_and_encloses_its_volume():
    centre, radii = np.array([0.1, -0.2, 0.3]), np.array([0.05, 0.08, 0.12])
    v, f = ellipsoid_mesh(centre, radii, segments=96)
    assert np.abs(quadric.evaluate(quadric.ellipsoid(centre, radii), v)).max() < 1e-12
    assert volume(v, f) == pytest.approx(4 / 3 * np.pi * radii.prod(), rel=2e-3)


def test_clipped_ellipsoid_is_closed_by_caps_inside_the_clip():
    centre, radii, clip = np.zeros(3), np.array([0.1, 0.1, 0.2]), (-0.05, 0.1)
    v, f = ellipsoid_mesh(centre, radii, clip=clip, segments=128)
    keep = quadric.slab([0, 0, 1], clip[0], clip[1])
    assert quadric.evaluate(keep, v).max() < 1e-12
    z0, z1 = clip
    exact = np.pi * 0.1 * 0.1 * ((z1 - z0) - (z1**3 - z0**3) / (3 * 0.2**2))  # integral of the cross-section area
    assert volume(v, f) == pytest.approx(exact, rel=2e-3)


def test_cone_mesh_on_its_surface_with_the_frustum_volume():
    start, end, r0, r1 = np.array([0.0, 0.1, 0.0]), np.array([0.2, 0.1, -0.3]), 0.05, 0.03
    v, f = cone_mesh(start, end, radius_start=r0, radius_end=r1, segments=128)
    side = np.abs(quadric.evaluate(quadric.cone(start, end, radius_start=r0, radius_end=r1), v)) < 1e-9
    assert side[:256].all()  # both rings lie on the cone; the cap centres are on the axis
    length = np.linalg.norm(end - start)
    assert volume(v, f) == pytest.approx(np.pi * length * (r0 * r0 + r0 * r1 + r1 * r1) / 3, rel=2e-3)


def test_every_component_of_the_human_model_gets_a_closed_outward_mesh():
    model = load_model(ROOT / "models" / "human.toml")
    meshes = component_meshes(model)
    assert len(meshes) == model.size
    for vertices, faces in meshes:
        assert len(faces) > 0 and faces.max() < len(vertices) and volume(vertices.astype(float), faces) > 0
