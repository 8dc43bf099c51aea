"""The face on the head: its coordinates worked by hand, hair at the back, skin in front, and a render
that changes only the head's pixels and tells the front from the back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker.camera import look_at_camera
from tracker.geometry import se3
from tracker.model import load_model, model_from_dict, rest_poses
from tracker.synthetic import render, synth, texture
from tracker.synthetic.actor import capsule_body
from tracker.synthetic.face import HAIR, Face, head_coordinates, paint_face
from tracker.tomlfile import read_toml

MODEL = Path(__file__).resolve().parents[2] / "models" / "human.toml"
SKIN = np.array([0.5, 0.6, 0.8])


@pytest.fixture(scope="module")
def human():
    return load_model(MODEL)


def test_head_coordinates_and_colours_at_hand_picked_points():
    face = Face(0, np.array([0.0, -0.01, 0.14]), np.array([0.085, 0.1, 0.115]), SKIN, HAIR)
    ahead, left, behind, crown, chin = np.array(
        [[0.0, -0.1, 0.0], [0.085, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.115], [0.0, -0.05, -0.1]]
    ) + [0.0, -0.01, 0.14]
    azimuth, height = head_coordinates(face, np.array([ahead, left, behind, crown]))
    np.testing.assert_allclose(azimuth[:3], [0.0, np.pi / 2, np.pi], atol=1e-12)  # none on the crown
    np.testing.assert_allclose(height, [0.0, 0.0, 0.0, 1.0], atol=1e-12)
    colours = paint_face(face, np.array([ahead, behind, crown, chin]))
    np.testing.assert_allclose(colours, [SKIN, HAIR, HAIR, SKIN], atol=1e-12)  # between the eyes; hair; the chin
    up = np.arcsin(0.12)  # the eyes' height e = sin(elevation)
    eye = face.centre + face.radii * [np.sin(0.38) * np.cos(up), -np.cos(0.38) * np.cos(up), np.sin(up)]
    assert paint_face(face, eye[None])[0].max() < 0.3  # the left iris, dark


def test_the_face_repaints_only_the_head_and_tells_front_from_back(human):
    camera = look_at_camera("c", (0.0, -2.0, 1.6), (0.0, 0.0, 1.45), size=(160, 120), focal=500.0)
    front = rest_poses(human, se3.from_rotvec(np.zeros(3), (0.0, 0.0, 0.92)))
    back = np.einsum("ab,nbc->nac", se3.from_rotvec((0.0, 0.0, np.pi)), front)
    head = human.index("head")
    clothes = texture.make_texture("stripes", human.names, render.albedos(human), seed=1)
    dressed = render.Renderer(human, camera, noise=0.0, blur=0.0, texture=clothes)
    faced = render.Renderer(human, camera, noise=0.0, blur=0.0, texture=clothes, face=synth.head_face(human))
    brightness = {}
    for side, poses in (("front", front), ("back", back)):
        comp = dressed.cast(poses)[0].copy()
        plain, painted = dressed.render(poses), faced.render(poses)
        changed = np.any(plain != painted, axis=2)
        assert not np.any(changed & (comp != head))  # the clothes elsewhere are untouched
        assert changed[comp == head].mean() > 0.1
        brightness[side] = (painted[comp == head].mean(), plain[comp == head].mean())
    assert brightness["front"][0] > 1.5 * brightness["back"][0]  # skin in front, hair behind
    assert brightness["front"][1] == pytest.approx(brightness["back"][1], rel=0.2)  # without the face: alike


def test_a_capsule_head_gets_a_round_face():
    actor = model_from_dict(capsule_body(read_toml(MODEL, "model", ""), 0.1, seed=2))
    face = synth.head_face(actor)
    radius = next(p["radius"] for p, c in zip(actor.quadric_params, actor.quadric_component) if c == face.component)
    np.testing.assert_allclose(face.radii[0:2], radius, rtol=0.01)  # the tube's radius, sampled on 24 directions
    assert face.radii[2] > radius and face.component == actor.index("head")
