"""Search limits from predicted edge ownership (tracker.tracking.ownership) against brute force and a simple scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker.camera import Camera
from tracker.model import load_model, model_from_dict
from tracker.synthetic.synth import demo3_rig, motion_poses
from tracker.tracking.outline import place, sample_outlines
from tracker.tracking.ownership import (
    GRID_MARGIN,
    GRID_STEP,
    NCOEF,
    Ownership,
    line_labels,
    pixel_scale,
    undistort_grid,
)
from tracker.tracking.rig import Rig
from tracker.tracking.samples import Placed, Samples

HUMAN = Path(__file__).resolve().parents[2] / "models" / "human.toml"


def placed_at(model, poses, rig) -> Placed:
    """The camera-frame quadrics that the outline stage hands to the ownership stage, at ``poses`` (N, 4, 4) in
    every camera or (C, N, 4, 4) each camera's own."""
    cameras = len(rig.names)
    placed = Placed.allocate(cameras, model.quadric.shape[0])
    place(
        model.quadric,
        model.clip,
        model.quadric_bound,
        model.quadric_component,
        np.ascontiguousarray(np.broadcast_to(poses, (cameras, *poses.shape[-3:]))),
        rig.camera_from_world,
        placed.camera_from,
        placed.quadric,
        placed.clip,
        placed.sphere,
        placed.cone,
    )
    return placed


def brute_labels(model, poses, camera: Camera, pixels):
    """Front-most component hit by the exact ray of every pixel (M, 2): Camera.undistort_pixels, then every
    clipped quadric in the camera frame (s^2 x^T A x + 2 s b^T x + c = 0, nearest s > 0 inside its clip)."""
    xn = camera.undistort_pixels(pixels)
    rays = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
    nearest = np.full(len(rays), np.inf)
    label = np.full(len(rays), -1)
    for j in range(model.quadric.shape[0]):
        e_inv = np.linalg.inv(camera.camera_from_world @ poses[model.quadric_component[j]])
        q = e_inv.T @ model.quadric[j] @ e_inv
        c = e_inv.T @ model.clip[j] @ e_inv
        qa = np.einsum("ma,ab,mb->m", rays, q[:3, :3], rays)
        qb = 2.0 * rays @ q[:3, 3]
        disc = qb * qb - 4.0 * qa * q[3, 3]
        ok = (disc >= 0.0) & (qa != 0.0)
        root = np.sqrt(np.where(ok, disc, 0.0))
        for sign in (-1.0, 1.0):
            with np.errstate(divide="ignore", invalid="ignore"):
                z = (-qb + sign * root) / (2.0 * qa)
            points = z[:, None] * rays
            value = np.einsum("ma,ab,mb->m", points, c[:3, :3], points) + 2.0 * points @ c[:3, 3] + c[3, 3]
            hit = ok & (z > 0.0) & (z < nearest) & (value <= 0.0)
            nearest[hit] = z[hit]
            label[hit] = model.quadric_component[j]
    return label


def rule(labels, own, r):
    """The research rule on labels[t + r + 1], t in [-r - 1, r + 1]: (lo, hi)."""

    def at(t):
        return labels[t + r + 1]

    outside = at(1)

    def cuts(a, b):
        return a != b and {a, b} != {own, outside}

    hi = r
    for t in range(1, r + 1):
        if cuts(at(t), at(t + 1)):
            hi = min(r, (2 * t + 1) // 4)
            break
    lo = -r
    for t in range(1, r + 1):
        if cuts(at(-t), at(-t - 1)):
            lo = max(-r, -((2 * t + 1) // 4))
            break
    return lo, hi


def test_undistortion_grid_inverts_the_lens():
    """The grid's nodes are the lens's exact inverse (tracker.geometry.lens.undistort, checked against OpenCV in
    tests/geometry/test_lens.py), and the pixel scale bounds the rays' spread."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        k = np.array(
            [
                [rng.uniform(400, 700), rng.uniform(-1, 1), rng.uniform(300, 340)],
                [0.0, rng.uniform(400, 700), rng.uniform(220, 260)],
                [0.0, 0.0, 1.0],
            ]
        )
        d = np.array(
            [
                rng.uniform(-0.12, 0.05),
                rng.uniform(-0.03, 0.03),
                rng.uniform(-2e-3, 2e-3),
                rng.uniform(-2e-3, 2e-3),
                rng.uniform(-0.005, 0.005),
            ]
        )  # ordinary lenses
        camera = Camera("c", (640, 480), k, d, np.eye(3), np.zeros(3))
        rig = Rig.from_cameras([camera])
        grid = undistort_grid(rig)
        nodes = np.stack(np.meshgrid(np.arange(grid.shape[2]), np.arange(grid.shape[1])), axis=2) * GRID_STEP
        exact = camera.undistort_pixels(nodes.reshape(-1, 2) - GRID_MARGIN)
        assert np.abs(grid[0].reshape(-1, 2) - exact).max() * k[0, 0] < 1e-6
        assert pixel_scale(grid)[0] >= 1.0 / min(k[0, 0], k[1, 1])


@pytest.fixture(scope="module")
def human_views():
    """Samples of models/human.toml in the (distorted) demo3 rig at a few procedural poses."""
    model = load_model(HUMAN)
    cameras = demo3_rig()
    rig = Rig.from_cameras(cameras)
    poses, _, _ = motion_poses(model, "procedural", 60, seed=4)
    views = []
    for f in (0, 25, 59):
        samples = sample_outlines(model, poses[f], rig, spacing=4.0, samples=Samples.allocate(20000))
        views.append((poses[f], samples))
    return model, cameras, rig, views


@pytest.mark.parametrize("r", [20, 6])
def test_fast_labels_match_brute_force(human_views, r):
    """Straight segments between the two undistorted ends agree with per-pixel exact rays on >= 99% of the
    points, and every disagreement is within a pixel of a boundary.  The sample itself (t = 0) lies on its
    own outline by construction, a boundary whose label either way is a matter of rounding: the rule never
    reads it, and it is left out."""
    model, cameras, rig, views = human_views
    n_quadrics = model.quadric.shape[0]
    grid = undistort_grid(rig)
    cand = np.zeros(n_quadrics, np.int64)
    coef = np.zeros((n_quadrics, NCOEF))
    total = agree = 0
    ts = np.arange(-r - 1, r + 2)
    used = ts != 0
    for poses, s in views:
        placed = placed_at(model, poses, rig)
        fast = np.zeros(2 * r + 3, np.int64)
        for i in range(0, s.count, 3):
            k = s.camera[i]
            line_labels(
                placed.quadric,
                placed.clip,
                placed.sphere,
                model.quadric_component,
                rig.matrix,
                rig.lens,
                rig.distortion,
                grid,
                k,
                s.pixel[i, 0],
                s.pixel[i, 1],
                s.normal[i, 0],
                s.normal[i, 1],
                r,
                cand,
                coef,
                fast,
            )
            pixels = s.pixel[i] + ts[:, None] * s.normal[i]
            exact = brute_labels(model, poses, cameras[k], pixels)
            fine = brute_labels(
                model, poses, cameras[k], s.pixel[i] + np.arange(-r - 2, r + 2.01, 0.25)[:, None] * s.normal[i]
            )
            total += used.sum()
            agree += ((fast == exact) & used).sum()
            for t in np.flatnonzero((fast != exact) & used):
                # a boundary within a pixel: the exact labels on a 1/4 pixel grid change within +-1 of t
                window = fine[4 * t : 4 * t + 9]  # offsets t - 1 ... t + 1
                assert len(set(window.tolist())) > 1, (i, ts[t])
                assert fast[t] in window
    assert agree / total >= 0.99


def test_search_limits_match_the_rule_on_brute_force_labels(human_views):
    model, cameras, rig, views = human_views
    total = same = 0
    for r in (20, 12, 6):
        ts = np.arange(-r - 1, r + 2)
        for poses, s in views:
            lo, hi = Ownership(model, rig, s.count, r).limits(placed_at(model, poses, rig), s, r)
            for i in range(0, s.count, 2):
                k = s.camera[i]
                exact = brute_labels(model, poses, cameras[k], s.pixel[i] + ts[:, None] * s.normal[i])
                lo_b, hi_b = rule(exact, s.component[i], r)
                total += 1
                same += lo[i] == lo_b and hi[i] == hi_b
    assert same / total >= 0.99


def two_spheres(radius_a, radius_b, gap):
    """Component a: a sphere at the origin; b (child of a): a sphere on the +x side, ``gap`` m apart."""
    return model_from_dict(
        {
            "name": "two",
            "component": [
                {
                    "name": "a",
                    "parent": "",
                    "quadric": [{"shape": "sphere", "center": [0.0, 0.0, 0.0], "radius": radius_a}],
                },
                {
                    "name": "b",
                    "parent": "a",
                    "quadric": [
                        {"shape": "sphere", "center": [radius_a + gap + radius_b, 0.0, 0.0], "radius": radius_b}
                    ],
                },
            ],
        }
    )


def facing(model, focal=500.0):
    """A distortion-free camera 2 m in front of the spheres (image x = world x), its rig and samples."""
    rot = np.diag([1.0, -1.0, -1.0])  # looking down -z
    eye = np.array([0.0, 0.0, 2.0])
    camera = Camera(
        "c",
        (640, 480),
        np.array([[focal, 0.0, 319.5], [0.0, focal, 239.5], [0.0, 0.0, 1.0]]),
        np.zeros(5),
        rot,
        -rot @ eye,
    )
    rig = Rig.from_cameras([camera])
    poses = np.stack([np.eye(4), np.eye(4)])
    samples = sample_outlines(model, poses, rig, spacing=2.0, samples=Samples.allocate(2000))
    return poses, rig, samples


def test_another_outline_cuts_the_search_half_way():
    """A sample on a's right edge, normal +x: b's outline gap_px away cuts hi to ~gap_px / 2; inwards a's
    far side (a against the background again) does not cut: lo = -r."""
    r = 20
    model = two_spheres(0.03, 0.1, 0.05)  # a is 15 px across, the gap 12.5 px
    poses, rig, s = facing(model)
    lo, hi = Ownership(model, rig, s.count, r).limits(placed_at(model, poses, rig), s, r)
    on_a = np.flatnonzero((s.component[: s.count] == 0) & (s.normal[: s.count, 0] > 0.999))
    assert len(on_a)
    for i in on_a:
        gap_px = (0.03 + 0.05 - 0.0) * 500.0 / 2.0 - (s.pixel[i, 0] - 319.5)  # to b's left edge along +x
        assert abs(hi[i] - gap_px / 2.0) <= 1.0
        assert lo[i] == -r
    # b's left edge, normal -x: a's outline cuts lo the same way; inwards b is 50 px wide: no cut within r
    on_b = np.flatnonzero((s.component[: s.count] == 1) & (s.normal[: s.count, 0] < -0.999))
    assert len(on_b)
    for i in on_b:
        gap_px = (s.pixel[i, 0] - 319.5) - 0.03 * 500.0 / 2.0
        assert abs(hi[i] - gap_px / 2.0) <= 1.0  # +n points at a: the cut is on the hi side
        assert lo[i] == -r


def test_no_other_outline_no_cut():
    """Far apart spheres: every search keeps its full range."""
    r = 20
    model = two_spheres(0.05, 0.05, 0.6)
    poses, rig, s = facing(model)
    lo, hi = Ownership(model, rig, s.count, r).limits(placed_at(model, poses, rig), s, r)
    assert (lo == -r).all() and (hi == r).all()
