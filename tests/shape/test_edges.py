"""The edge rows of the shape fit (tracker.shape.edges): the stretch against the stretched surface, the chain
and the joints' motions against the model posed, the rows against renders, the step against a dense solve."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from conftest import HUMAN, ROOT

from tracker.camera import load_calibration
from tracker.geometry.quadric import evaluate
from tracker.io.posefile import load_pose_file
from tracker.model import model_from_dict, poses_from_rotations
from tracker.proportions import stretched
from tracker.shape.edges import (
    FrameRows,
    bundle_step,
    chain_maps,
    frame_rows,
    joint_twists,
    moved,
    stretch_rows,
)
from tracker.shape.layout import Layout
from tracker.synthetic.render import Renderer
from tracker.tomlfile import read_toml
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings
from tracker.tracking.workspace import Inspection

PARTS = {
    "name": "parts",
    "component": [
        {"name": "a", "parent": "", "quadric": [{"shape": "sphere", "center": [0.0, 0.02, 0.05], "radius": 0.1}]},
        {
            "name": "b",
            "parent": "a",
            "at": [0.0, 0.0, 0.1],
            "quadric": [{"shape": "cylinder", "from": [0.0, 0.0, 0.0], "to": [0.0, 0.0, 0.3], "radius": 0.05}],
        },
        {
            "name": "c",
            "parent": "b",
            "at": [0.0, 0.0, 0.3],
            "quadric": [{"shape": "cone", "from": [0.0, 0.0, 0.0], "to": [0.25, 0.0, 0.0], "radii": [0.04, 0.03]}],
        },
        {
            "name": "d",
            "parent": "c",
            "at": [0.25, 0.0, 0.0],
            "quadric": [{"shape": "ellipsoid", "center": [0.05, 0.01, 0.0], "radii": [0.06, 0.03, 0.02]}],
        },
    ],
}


def surface_points(model, rng, count):
    """Points on each quadric's surface (component, quadric, point), from random rays out of its centre."""
    out = []
    for q, params in enumerate(model.quadric_params):
        centre = np.asarray(params.get("center", params.get("from", [0.0, 0.0, 0.0])), float)
        if "to" in params:
            centre = (centre + np.asarray(params["to"], float)) / 2
        for _ in range(count):
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            lo, hi = 0.0, 1.0  # bisect the ray for the surface
            for _ in range(80):
                mid = (lo + hi) / 2
                inside = evaluate(model.quadric[q], (centre + mid * direction)[None])[0] < 0
                lo, hi = (mid, hi) if inside else (lo, mid)
            out.append((model.quadric_component[q], q, centre + lo * direction))
    return out


def fake_inspection(samples):
    """An Inspection of the (component, quadric, point) samples, three per point with g = each axis."""
    count = 3 * len(samples)
    jacobian = np.zeros((count, 6))
    jacobian[:, :3] = np.tile(np.eye(3), (len(samples), 1))
    return Inspection(
        camera=np.zeros(count, np.int64),
        component=np.repeat([s[0] for s in samples], 3),
        pixel=np.zeros((count, 2)),
        normal=np.zeros((count, 2)),
        lo=np.zeros(count, np.int64),
        hi=np.zeros(count, np.int64),
        offset=np.zeros(count),
        weight=np.ones(count),
        quadric=np.repeat([s[1] for s in samples], 3),
        point=np.repeat([s[2] for s in samples], 3, axis=0),
        jacobian=jacobian,
    )


def test_the_stretch_moves_each_surface_point_onto_the_stretched_surface(monkeypatch):
    """S(X) da takes a point of every kind of quadric (sphere, cylinder, cone across x, offset ellipsoid) of a
    model already stretched onto the surface stretched by da more."""
    monkeypatch.setattr("tracker.proportions.DECIMALS", 12)  # the file's rounding to 0.01 mm is not tested here
    rng = np.random.default_rng(1)
    now = {name: rng.uniform(0.85, 1.15, 3) for name in "abcd"}
    model = model_from_dict(stretched(PARTS, now))
    samples = surface_points(model, rng, 6)
    rows = stretch_rows(model, np.array([now[n] for n in model.names]), fake_inspection(samples))
    ratios = []
    for step in (1e-2, 4e-3):
        delta = {name: rng.normal(size=3) * step for name in "abcd"}
        after = model_from_dict(stretched(PARTS, {name: now[name] + delta[name] for name in "abcd"}))
        before_move, after_move = [], []
        for k, (component, q, point) in enumerate(samples):
            gradient = np.linalg.norm(2 * (after.quadric[q][:3, :3] @ point + after.quadric[q][:3, 3]))
            moved_point = point + rows[3 * k : 3 * k + 3] @ delta[model.names[component]]
            before_move.append(abs(evaluate(after.quadric[q], point[None])[0]) / gradient)
            after_move.append(abs(evaluate(after.quadric[q], moved_point[None])[0]) / gradient)
        ratios.append(sum(after_move) / sum(before_move))  # what S da leaves of the distance to the new surface
    assert max(ratios) < 1e-6  # the stretch is linear in the factors: S da is exact


def test_the_chain_moves_each_origin_as_the_posed_model_does():
    """With the rotations held, chain_maps dx is how far each component's origin moves when the joints change
    by dx (exactly: it is linear, up to the model file's rounding to 0.01 mm), for tied sides too."""
    document = read_toml(HUMAN, "model", "")
    model = model_from_dict(document)
    layout = Layout.of(model)
    rng = np.random.default_rng(2)
    rotations = np.stack([cv2.Rodrigues(rng.normal(size=3) * 0.5)[0] for _ in range(model.size)])
    poses = poses_from_rotations(model, np.array([0.1, 0.2, 1.0]), rotations)
    x = layout.start()
    dx = np.zeros(layout.width)
    dx[: layout.factor.min()] = rng.normal(size=layout.factor.min()) * 0.02
    other = model_from_dict(layout.document(x + dx, document))
    after = poses_from_rotations(other, poses[0, :3, 3], rotations)
    np.testing.assert_allclose(after[:, :3, 3] - poses[:, :3, 3], chain_maps(layout, model, poses) @ dx, atol=5e-5)


def test_a_joint_motion_moves_points_at_its_twist_and_keeps_the_joints():
    model = model_from_dict(read_toml(HUMAN, "model", ""))
    rng = np.random.default_rng(3)
    rotations = np.stack([cv2.Rodrigues(rng.normal(size=3) * 0.3)[0] for _ in range(model.size)])
    poses = model.coerce(poses_from_rotations(model, np.array([0.0, 0.0, 1.0]), rotations))
    twists, moves = joint_twists(model, poses)
    assert moves.shape == (len(twists), model.size) and moves[:, 0].sum() == 6  # only the root moves the pelvis
    point = np.array([0.01, 0.02, -0.1])  # a point fixed in the left hand
    hand = model.index("hand_l")
    for p in np.flatnonzero(moves[:, hand]):
        motion = np.zeros(len(twists))
        motion[p] = 1e-5
        after = moved(model, poses, motion)
        before = poses[hand, :3, :3] @ point + poses[hand, :3, 3]
        world = after[hand, :3, :3] @ point + after[hand, :3, 3]
        velocity = np.cross(twists[p, :3], before) + twists[p, 3:]
        np.testing.assert_allclose((world - before) / 1e-5, velocity, atol=2e-4)
    np.testing.assert_allclose(moved(model, poses, np.zeros(len(twists))), poses, atol=1e-12)


def test_the_rows_predict_how_the_edges_move_in_a_render_of_the_body_reshaped():
    """Render the demo's first pose with the body reshaped by a small dx (joints moved 1-3 cm, parts stretched
    5-10 %), measure its edges along the given model's outlines at the same pose: the change of each offset from
    the render of the given model is the rows times dx (the median ratio near 1 over the samples that move)."""
    document = read_toml(HUMAN, "model", "")
    model = model_from_dict(document)
    layout = Layout.of(model)
    cameras = load_calibration(ROOT / "recordings" / "demo" / "calibration.toml")
    poses = load_pose_file(ROOT / "recordings" / "demo" / "init.toml", model)
    x = layout.start()

    def seen(dx):
        other = model_from_dict(layout.document(x + dx, document))
        images = [
            cv2.cvtColor(Renderer(other, camera, noise=0.0).render(other.coerce(poses)), cv2.COLOR_BGR2GRAY)
            for camera in cameras
        ]
        tracker = Tracker(
            model, cameras, poses, Settings().but(motion=dict(dynamics="none"), outline=dict(ownership=False))
        )
        return tracker.inspect(images, poses=poses, search_range=10)

    base = seen(np.zeros(layout.width))
    every = dataclasses.replace(base, offset=np.zeros_like(base.offset), weight=np.ones_like(base.weight))
    rows = frame_rows(layout, model, factors=layout.factors(x), poses=poses, inspection=every).shape
    changes = [
        ("forearm_l", "joint", 2, -0.03),
        ("shin_l", "joint", 2, -0.03),
        ("upperarm_l", "joint", 0, 0.02),
        ("torso", "factor", 2, 0.05),
    ]
    for name, kind, axis, amount in changes:
        i = model.index(name)
        dx = np.zeros(layout.width)
        dx[(layout.joint[i] if kind == "joint" else layout.factor[i]) + axis] = amount
        change = seen(dx).offset - base.offset
        predicted = rows @ dx
        moving = np.isfinite(change) & (np.abs(change) < 6) & (np.abs(predicted) > 0.5)
        ratio = np.median(change[moving] / predicted[moving])  # some samples find another part's edge instead
        assert moving.sum() > 30 and 0.8 < ratio < 1.15, (name, kind, moving.sum(), ratio)


def test_the_step_is_the_dense_least_squares_solution():
    """Shape and poses solved together, each frame's pose eliminated, equal the dense solution of the stacked
    weighted rows with the prior."""
    rng = np.random.default_rng(4)
    width, count = 7, 3
    frames = [
        FrameRows(
            rng.normal(size=(40, width)),
            rng.normal(size=(40, 5)),
            rng.normal(size=40),
            rng.uniform(0.2, 1, 40),
            np.zeros(40, np.int64),
            np.zeros(40, np.int64),
        )
        for _ in range(count)
    ]
    prior = rng.normal(size=(4, width))
    x = rng.normal(size=width)
    new_x, motions = bundle_step(frames, prior, x)
    blocks = []
    for k, frame in enumerate(frames):
        pose = np.zeros((40, 5 * count))
        pose[:, 5 * k : 5 * k + 5] = frame.pose
        blocks.append(np.sqrt(frame.weight)[:, None] * np.hstack([frame.shape, pose]))
    damping = np.hstack([np.zeros((5 * count, width)), np.eye(5 * count)])  # POSE_DAMPING = 1
    system = np.vstack([*blocks, np.hstack([prior, np.zeros((4, 5 * count))]), damping])
    target = np.concatenate([np.sqrt(f.weight) * f.offset for f in frames] + [-prior @ x, np.zeros(5 * count)])
    dense = np.linalg.lstsq(system, target, rcond=None)[0]
    np.testing.assert_allclose(new_x - x, dense[:width], atol=1e-9)
    np.testing.assert_allclose(np.concatenate(motions), dense[width:], atol=1e-9)


@pytest.mark.parametrize("axis", [0, 2])
def test_rows_of_samples_without_an_edge_are_left_out(axis):
    model = model_from_dict(read_toml(HUMAN, "model", ""))
    layout = Layout.of(model)
    rng = np.random.default_rng(5)
    inspection = fake_inspection(surface_points(model, rng, 2))
    inspection.offset[axis::3] = np.nan
    rows = frame_rows(
        layout,
        model,
        factors=layout.factors(layout.start()),
        poses=np.tile(np.eye(4), (model.size, 1, 1)),
        inspection=inspection,
    )
    assert len(rows.offset) == len(inspection.offset) - len(inspection.offset[axis::3])
