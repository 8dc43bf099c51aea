"""Outline sampling kernel (tracker.tracking.outline) against docs/method-tracking.md, sections 2 and 3.

Every check recomputes the geometry independently in numpy (or with OpenCV
through Camera.project / Camera.undistort_pixels) from the model's quadrics,
the poses and the cameras: contour points on the surface and tangent to the
viewing ray, reprojection, outward normals, arc-length spacing, clipping,
occlusion, culling, and the Jacobian rows against finite differences.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from test_ownership import placed_at

from tracker.camera import Camera
from tracker.geometry import se3
from tracker.geometry.quadric import KEEP_ALL
from tracker.model import load_model, model_from_dict
from tracker.tracking.outline import sample_outlines
from tracker.tracking.rig import Rig
from tracker.tracking.samples import Samples

SIZE = (640, 480)

# One quadric per shape; "slab" is the clip (unit axis, d1, d2) in the component frame, or None.
SHAPES = {
    "sphere": (dict(shape="sphere", center=[0.02, -0.03, 0.01], radius=0.15), None),
    "ellipsoid": (dict(shape="ellipsoid", center=[0.0, 0.03, -0.02], radii=[0.1, 0.18, 0.3]), None),
    "clipped_ellipsoid": (
        dict(shape="ellipsoid", center=[0.01, 0.0, 0.05], radii=[0.14, 0.2, 0.3], clip=[-0.2, 0.12]),
        ([0.0, 0.0, 1.0], 0.05 - 0.2, 0.05 + 0.12),
    ),
    "cylinder": (
        dict(shape="cylinder", **{"from": [0.0, -0.05, -0.25], "to": [0.05, 0.0, 0.3]}, radius=0.08),
        "axis",
    ),
    "cone": (
        dict(shape="cone", **{"from": [0.0, 0.0, 0.2], "to": [0.02, 0.03, -0.3]}, radii=[0.12, 0.05]),
        "axis",
    ),
}


def slab_of(name):
    spec, slab = SHAPES[name]
    if slab == "axis":
        start, end = np.array(spec["from"]), np.array(spec["to"])
        d = (end - start) / np.linalg.norm(end - start)
        return d, d @ start, d @ end
    if slab is None:
        return None
    return np.array(slab[0]), slab[1], slab[2]


def one_component(spec):
    return model_from_dict({"name": "one", "component": [{"name": "body", "parent": "", "quadric": [spec]}]})


def look_at(name, eye, target, f, distortion=(), rng=None, skew=0.0):
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    if rng is not None:  # roll about the optical axis
        a = rng.uniform(-np.pi, np.pi)
        x, y = np.cos(a) * x + np.sin(a) * y, -np.sin(a) * x + np.cos(a) * y
    rot = np.stack([x, y, z])
    cx = SIZE[0] / 2 + (rng.uniform(-15, 15) if rng is not None else 0.0)
    cy = SIZE[1] / 2 + (rng.uniform(-15, 15) if rng is not None else 0.0)
    fy = f * (rng.uniform(0.98, 1.02) if rng is not None else 1.0)
    matrix = np.array([[f, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    dist = np.zeros(5)
    dist[: len(distortion)] = distortion
    return Camera(name, SIZE, matrix, dist, rot, -rot @ eye)


def random_distortion(rng):
    return (
        rng.uniform(-0.2, 0.1),
        rng.uniform(-0.05, 0.05),
        rng.uniform(-2e-3, 2e-3),
        rng.uniform(-2e-3, 2e-3),
        rng.uniform(-0.01, 0.01),
    )


def random_cameras(rng, n, distorted, distance=(1.6, 2.6)):
    cams = []
    for k in range(n):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        eye = rng.uniform(*distance) * direction
        target = rng.normal(scale=0.05, size=3)
        dist = random_distortion(rng) if distorted else ()
        cams.append(look_at(f"cam{k}", eye, target, rng.uniform(550, 800), dist, rng))
    return cams


def random_pose(rng, scale=0.1):
    return se3.from_rotvec(rng.uniform(-np.pi, np.pi) * unit(rng), rng.normal(scale=scale, size=3))


def unit(rng):
    x = rng.normal(size=3)
    return x / np.linalg.norm(x)


def sample(model, poses, cams, spacing=3.0, capacity=20000):
    s = sample_outlines(
        model, np.ascontiguousarray(poses), Rig.from_cameras(cams), spacing=spacing, samples=Samples.allocate(capacity)
    )
    assert s.count < capacity
    return s


def homog(points):
    return np.hstack([points, np.ones((len(points), 1))])


def normalised_residual(q, points):
    """|X~^T Q X~| / (|Q|_F |X~|^2): the scale-free distance of the points from the quadric."""
    h = homog(points)
    return np.abs(np.einsum("mi,ij,mj->m", h, q, h)) / (np.linalg.norm(q) * np.einsum("mi,mi->m", h, h))


def world_points(poses, comp, points):
    return np.einsum("mij,mj->mi", poses[comp], homog(points))[:, :3]


def camera_centres(poses, comp, cams, cam_index):
    """Each sample's camera centre in its component's frame."""
    centres = np.array([c.center for c in cams])[cam_index]
    inv = np.linalg.inv(poses[comp])
    return np.einsum("mij,mj->mi", inv, homog(centres))[:, :3]


def ray_hits(cam, pose, q, pixels):
    """For each distorted pixel: does its viewing ray (s > 0) meet the (unclipped) quadric?"""
    xn = cam.undistort_pixels(pixels)
    cam_from_comp = cam.camera_from_world @ pose
    r, t = cam_from_comp[:3, :3], cam_from_comp[:3, 3]
    origin = -r.T @ t
    dirs = homog(xn) @ r  # R^T d for each row
    a = np.einsum("mi,ij,mj->m", dirs, q[:3, :3], dirs)
    b = 2.0 * (dirs @ (q[:3, :3] @ origin + q[:3, 3]))
    c = homog(origin[None])[0] @ q @ homog(origin[None])[0]
    disc = b * b - 4.0 * a * c
    hits = np.zeros(len(pixels), bool)
    for m in np.flatnonzero(disc >= 0.0):
        roots = ((-b[m] - np.sqrt(disc[m])) / (2 * a[m]), (-b[m] + np.sqrt(disc[m])) / (2 * a[m]))
        hits[m] = max(roots) > 0
    return hits


CASES = [(name, distorted) for name in SHAPES for distorted in (False, True)]


@pytest.fixture(scope="module")
def random_views():
    """For every (shape, distortion): a list of (model, poses, cams, samples) over random poses and rigs."""
    rng = np.random.default_rng(20240601)
    out = {}
    for name, distorted in CASES:
        model = one_component(SHAPES[name][0])
        views = []
        for _ in range(4):
            cams = random_cameras(rng, 3, distorted)
            poses = random_pose(rng)[None]
            views.append((model, poses, cams, sample(model, poses, cams, spacing=3.0)))
        out[name, distorted] = views
    return out


@pytest.mark.parametrize("name,distorted", CASES)
def test_contour_points_lie_on_the_quadric_and_reproject(random_views, name, distorted):
    total = 0
    for model, poses, cams, s in random_views[name, distorted]:
        n = s.count
        total += n
        assert np.all(s.component[:n] == 0) and np.all(s.quadric[:n] == 0)
        assert set(s.camera[:n]) <= set(range(len(cams)))
        point = s.point[:n]
        assert normalised_residual(model.quadric[0], point).max() < 1e-9
        world = world_points(poses, s.component[:n], point)
        for k, cam in enumerate(cams):
            sel = s.camera[:n] == k
            if sel.any():
                err = np.linalg.norm(cam.project(world[sel]) - s.pixel[:n][sel], axis=1)
                assert err.max() < 1e-6, f"camera {k}: reprojection error {err.max():.3g} px"
    assert total > 300


@pytest.mark.parametrize("name,distorted", CASES)
def test_viewing_ray_is_tangent_at_the_contour_point(random_views, name, distorted):
    for model, poses, cams, s in random_views[name, distorted]:
        n = s.count
        point = s.point[:n]
        ray = point - camera_centres(poses, s.component[:n], cams, s.camera[:n])
        grad = (homog(point) @ model.quadric[0])[:, :3]
        cos = np.abs(np.einsum("mi,mi->m", grad, ray)) / (np.linalg.norm(grad, axis=1) * np.linalg.norm(ray, axis=1))
        assert cos.max() < 1e-6


@pytest.mark.parametrize("name,distorted", CASES)
def test_normal_is_unit_and_outward(random_views, name, distorted):
    """1.5 px outward the viewing ray misses the surface; 1.5 px inward it meets it.

    The probes use the whole (unclipped) quadric: near a clip boundary, or when the
    camera looks almost along a tube, the inward ray meets the surface beyond the clip.
    """
    checked = 0
    for model, poses, cams, s in random_views[name, distorted]:
        n = s.count
        normal = s.normal[:n]
        assert np.abs(np.linalg.norm(normal, axis=1) - 1.0).max() < 1e-12
        for k, cam in enumerate(cams):
            sel = s.camera[:n] == k
            outside = ray_hits(cam, poses[0], model.quadric[0], s.pixel[:n][sel] + 1.5 * normal[sel])
            inside = ray_hits(cam, poses[0], model.quadric[0], s.pixel[:n][sel] - 1.5 * normal[sel])
            assert not outside.any(), f"{outside.sum()} outward probes hit the surface"
            assert inside.all(), f"{(~inside).sum()} inward probes miss the surface"
            checked += sel.sum()
    assert checked > 200


def ideal_to_distorted(cam, ideal):
    """Ideal (undistorted) pixels -> recorded pixels, through Camera.distort_normalized."""
    xn = (homog(ideal) @ np.linalg.inv(cam.matrix).T)[:, :2]
    return cam.distort_normalized(xn)


@pytest.mark.parametrize("name,distorted", CASES)
def test_normal_is_perpendicular_to_the_distorted_outline(random_views, name, distorted):
    """n is along J_d^-T grad(C_pix): perpendicular to the image J_d t of the ideal outline's tangent t."""
    h = 1e-4
    for model, poses, cams, s in random_views[name, distorted]:
        n = s.count
        for k, cam in enumerate(cams):
            sel = s.camera[:n] == k
            pixel, normal = s.pixel[:n][sel], s.normal[:n][sel]
            ideal = (homog(cam.undistort_pixels(pixel)) @ cam.matrix.T)[:, :2]
            conic = outline_conic(cam, poses[0], model.quadric[0])
            values = np.einsum("mi,ij,mj->m", homog(ideal), conic, homog(ideal))
            grad = (homog(ideal) @ conic)[:, :2]
            # on the conic: its value over its gradient is the distance in ideal pixels
            assert np.abs(values / (2 * np.linalg.norm(grad, axis=1))).max() < 1e-6
            tangent = np.stack([-grad[:, 1], grad[:, 0]], 1)
            jd = np.stack(
                [
                    (ideal_to_distorted(cam, ideal + h * e) - ideal_to_distorted(cam, ideal - h * e)) / (2 * h)
                    for e in np.eye(2)
                ],
                2,
            )  # (M, 2, 2), columns d/dx, d/dy
            image_tangent = np.einsum("mij,mj->mi", jd, tangent)
            cos = np.abs(np.einsum("mi,mi->m", normal, image_tangent)) / np.linalg.norm(image_tangent, axis=1)
            assert cos.max() < 1e-6
            outward = np.einsum(
                "mi,mi->m", np.linalg.solve(np.transpose(jd, (0, 2, 1)), grad[:, :, None])[:, :, 0], normal
            )
            assert np.all(outward > 0)


def test_spacing_along_an_ellipse_is_even():
    rng = np.random.default_rng(7)
    model = one_component(SHAPES["ellipsoid"][0])
    for spacing in (2.0, 4.0, 8.0):
        for _ in range(3):
            cam = look_at("c", 2.2 * unit(rng), [0, 0, 0], rng.uniform(550, 800), (), rng)
            poses = random_pose(rng, scale=0.03)[None]
            s = sample(model, poses, [cam], spacing=spacing)
            steps = np.linalg.norm(np.diff(s.pixel[: s.count], axis=0), axis=1)
            assert len(steps) > 30
            assert abs(np.median(steps) / spacing - 1.0) < 0.1
            # every step (except the wrap-around) within the first-order bound of the note
            assert np.all(np.abs(steps[:-1] / spacing - 1.0) < 0.25), (steps / spacing).min()


def without_clip(model):
    return dataclasses.replace(model, clip=np.array([KEEP_ALL] * len(model.clip)))


@pytest.mark.parametrize("name", ["clipped_ellipsoid", "cylinder", "cone"])
@pytest.mark.parametrize("distorted", [False, True])
def test_clipping_matches_a_direct_slab_test(name, distorted):
    """The clipped samples are exactly the unclipped samples whose contour point lies in the slab."""
    rng = np.random.default_rng(11)
    direction, d1, d2 = slab_of(name)
    model = one_component(SHAPES[name][0])
    free = without_clip(model)
    compared = dropped = 0
    for _ in range(6):
        cams = random_cameras(rng, 2, distorted)
        poses = random_pose(rng)[None]
        clipped = sample(model, poses, cams, spacing=2.0)
        full = sample(free, poses, cams, spacing=2.0)
        along = clipped.point[: clipped.count] @ direction
        assert np.all((along >= d1 - 1e-9) & (along <= d2 + 1e-9))
        along_full = full.point[: full.count] @ direction
        inside = (along_full >= d1) & (along_full <= d2)
        np.testing.assert_array_equal(full.pixel[: full.count][inside], clipped.pixel[: clipped.count])
        np.testing.assert_array_equal(full.camera[: full.count][inside], clipped.camera[: clipped.count])
        compared += full.count
        dropped += (~inside).sum()
    assert compared > 500 and dropped > 50


def sphere_in_front_of_cylinder():
    spec = {
        "name": "two",
        "component": [
            {
                "name": "pole",
                "parent": "",
                "quadric": [{"shape": "cylinder", "from": [0.0, 0.0, -0.5], "to": [0.0, 0.0, 0.5], "radius": 0.1}],
            },
            {"name": "ball", "parent": "pole", "quadric": [{"shape": "sphere", "radius": 0.15}]},
        ],
    }
    return model_from_dict(spec), spec


def test_occlusion_matches_a_segment_sphere_test():
    rng = np.random.default_rng(3)
    model, spec = sphere_in_front_of_cylinder()
    pole_only = model_from_dict({"component": [spec["component"][0]]})
    ball_only = model_from_dict({"component": [dict(spec["component"][1], parent="")]})
    radius = 0.15
    occluded_total = kept_total = 0
    for trial in range(4):
        pole = random_pose(rng, scale=0.02)
        pole[:3, :3] = se3.exp_so3(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)])) @ se3.exp_so3(
            np.array([rng.uniform(-0.3, 0.3), 0.0, 0.0])
        )
        toward = np.array([1.0, rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2)])
        toward /= np.linalg.norm(toward)
        ball = se3.from_rotvec(rng.normal(size=3), pole[:3, 3] + 0.45 * toward + rng.normal(scale=0.03, size=3))
        poses = np.stack([pole, ball])
        cams = []
        for k in range(3):
            eye = pole[:3, 3] + rng.uniform(2.0, 3.0) * (toward + rng.normal(scale=0.25, size=3))
            cams.append(
                look_at(
                    f"c{k}", eye, ball[:3, 3], rng.uniform(550, 800), random_distortion(rng) if trial % 2 else (), rng
                )
            )
        both = sample(model, poses, cams, spacing=1.0)
        alone = sample(pole_only, poses[:1], cams, spacing=1.0)
        n, m = both.count, alone.count
        # brute force: does the segment camera centre -> contour point pass through the sphere?
        world = world_points(poses[:1].repeat(m, 0), np.zeros(m, int), alone.point[:m])
        centre = np.array([c.center for c in cams])[alone.camera[:m]]
        seg = world - centre
        u = np.clip(np.einsum("mi,mi->m", ball[:3, 3] - centre, seg) / np.einsum("mi,mi->m", seg, seg), 0, 1)
        gap = np.linalg.norm(centre + u[:, None] * seg - ball[:3, 3], axis=1)
        occluded = gap < radius
        ambiguous = np.abs(gap - radius) < 1e-9
        assert not ambiguous.any()
        pole_rows = both.quadric[:n] == 0
        np.testing.assert_array_equal(alone.pixel[:m][~occluded], both.pixel[:n][pole_rows])
        np.testing.assert_array_equal(alone.camera[:m][~occluded], both.camera[:n][pole_rows])
        assert np.all(both.component[:n][pole_rows] == 0) and np.all(both.component[:n][~pole_rows] == 1)
        # the sphere is in front: none of its samples are hidden
        ball_alone = sample(ball_only, poses[1:], cams, spacing=1.0)
        np.testing.assert_array_equal(ball_alone.pixel[: ball_alone.count], both.pixel[:n][~pole_rows])
        occluded_total += occluded.sum()
        kept_total += (~occluded).sum()
    assert occluded_total > 200 and kept_total > 1000


def in_image(px):
    return bool(np.all((px >= 0.0) & (px <= np.array(SIZE) - 1.0)))


def test_nothing_behind_the_camera_or_outside_the_image():
    rng = np.random.default_rng(5)
    # a sphere behind the camera gives no samples
    sphere = one_component(SHAPES["sphere"][0])
    cam = look_at("c", [0, 0, 2.0], [0, 0, 0], 600.0, random_distortion(rng))
    behind = se3.from_rotvec(np.zeros(3), [0.0, 0.0, 3.0])[None]
    assert sample(sphere, behind, [cam]).count == 0
    # a big sphere cut by the image border: only in-image samples
    big = one_component(dict(shape="sphere", radius=0.5))
    for _ in range(5):
        pose = se3.from_rotvec(np.zeros(3), [rng.uniform(-1.2, 1.2), rng.uniform(-0.9, 0.9), 0.0])[None]
        s = sample(big, pose, [cam], spacing=2.0)
        px = s.pixel[: s.count]
        assert s.count > 20
        assert in_image(px)
    # a long cylinder running from behind the camera to far in front, beside it
    pole = one_component(dict(shape="cylinder", **{"from": [0.0, 0.0, -3.0], "to": [0.0, 0.0, 6.0]}, radius=0.1))
    cams = [look_at("c", [0, 0, 0], [0.3, 0.1, 1.0], 600.0, dist, rng) for dist in ((), random_distortion(rng))]
    for offset in ([0.4, 0.0, 0.0], [0.0, -0.5, 0.0], [0.3, 0.3, 0.0]):
        pose = se3.from_rotvec(np.zeros(3), offset)[None]
        s = sample(pole, pose, cams, spacing=2.0)
        n = s.count
        assert n > 50
        world = world_points(pose.repeat(n, 0), np.zeros(n, int), s.point[:n])
        for k, cam in enumerate(cams):
            sel = s.camera[:n] == k
            depth = world[sel] @ cam.rotation[2] + cam.translation[2]
            assert np.all(depth > 0)
            np.testing.assert_allclose(cam.project(world[sel]), s.pixel[:n][sel], atol=1e-6)
            px = s.pixel[:n][sel]
            assert in_image(px)
        assert normalised_residual(pole.quadric[0], s.point[:n]).max() < 1e-9


@pytest.mark.parametrize("distorted", [False, True])
def test_hyperbolic_outline_of_an_ellipsoid_reaching_behind_the_camera(distorted):
    """A cigar passing beside the camera and behind it: its outline conic is a hyperbola."""
    rng = np.random.default_rng(23)
    cigar = one_component(dict(shape="ellipsoid", radii=[0.1, 0.15, 4.0]))
    cam = look_at("c", [0, 0, 0], [0.2, 0.1, 1.0], 500.0, random_distortion(rng) if distorted else (), rng)
    hyperbolas = 0
    for offset in ([0.4, 0.0, 0.5], [0.0, -0.5, 1.0], [0.3, 0.3, -0.5]):
        pose = se3.from_rotvec(np.zeros(3), offset)[None]
        conic = outline_conic(cam, pose[0], cigar.quadric[0])
        hyperbolas += np.linalg.det(conic[:2, :2]) < 0  # a hyperbola in the (ideal) image plane
        s = sample(cigar, pose, [cam], spacing=2.0)
        n = s.count
        assert n > 50
        world = world_points(pose.repeat(n, 0), np.zeros(n, int), s.point[:n])
        assert np.all(world @ cam.rotation[2] + cam.translation[2] > 0)
        np.testing.assert_allclose(cam.project(world), s.pixel[:n], atol=1e-6)
        assert in_image(s.pixel[:n])
        assert normalised_residual(cigar.quadric[0], s.point[:n]).max() < 1e-9
        steps = np.linalg.norm(np.diff(s.pixel[:n], axis=0), axis=1)
        if not distorted:
            assert abs(np.median(steps) / 2.0 - 1.0) < 0.1
    assert hyperbolas >= 2


@pytest.mark.parametrize("name", list(SHAPES))
def test_bounding_disc_culling_drops_no_visible_sample(name):
    """Sampling with a 20x larger bounding sphere finds the same outline (wide lenses, objects off-axis)."""
    rng = np.random.default_rng(29)
    model = one_component(SHAPES[name][0])
    bound = model.quadric_bound.copy()
    bound[:, 3] *= 20.0
    wide = dataclasses.replace(model, quadric_bound=bound)
    for trial in range(30):
        eye = rng.uniform(0.6, 1.5) * unit(rng)
        cam = look_at(
            "c",
            eye,
            rng.normal(scale=0.6, size=3),
            rng.uniform(150.0, 400.0),
            random_distortion(rng) if trial % 2 else (),
            rng,
        )
        poses = random_pose(rng)[None]
        a = sample(model, poses, [cam], spacing=2.0)
        b = sample(wide, poses, [cam], spacing=2.0)
        if SHAPES[name][1] == "axis":  # line pairs: the samples sit elsewhere on the chord, count them
            assert abs(a.count - b.count) <= 4
        else:
            np.testing.assert_array_equal(a.pixel[: a.count], b.pixel[: b.count])


# ---------------------------------------------------------------- Jacobian rows


def project_numpy(cam, world):
    """Camera.project written out (Brown-Conrady k1 k2 p1 p2 k3, K with skew)."""
    xc = world @ cam.rotation.T + cam.translation
    x, y = xc[:, 0] / xc[:, 2], xc[:, 1] / xc[:, 2]
    k1, k2, p1, p2, k3 = cam.distortions[:5]
    r2 = x * x + y * y
    f = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * f + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * f + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return (homog(np.stack([xd, yd], 1)) @ cam.matrix.T)[:, :2]


@pytest.mark.parametrize("name", list(SHAPES))
def test_jacobian_row_matches_material_point_finite_differences(name):
    """L alpha = n . d/de project(E exp(e alpha) X_comp) at e = 0, with lens distortion."""
    rng = np.random.default_rng(13)
    model = one_component(SHAPES[name][0])
    eps = 1e-6
    worst = 0.0
    for _ in range(3):
        cams = random_cameras(rng, 2, distorted=True)
        poses = random_pose(rng)[None]
        s = sample(model, poses, cams, spacing=6.0)
        n = s.count
        assert n > 20
        for k, cam in enumerate(cams):
            sel = np.flatnonzero(s.camera[:n] == k)
            for m in sel:
                alpha = rng.normal(size=6)
                alpha[3:] *= 2.0
                x = homog(s.point[m][None])[0]
                plus = (poses[0] @ se3.exp(eps * alpha) @ x)[:3]
                minus = (poses[0] @ se3.exp(-eps * alpha) @ x)[:3]
                moved = (cam.project(plus[None]) - cam.project(minus[None]))[0] / (2 * eps)
                fd = moved @ s.normal[m]
                predicted = s.jacobian[m] @ alpha
                scale = max(abs(fd), 0.05 * np.linalg.norm(s.jacobian[m]) * np.linalg.norm(alpha))
                worst = max(worst, abs(fd - predicted) / scale)
    assert worst < 1e-5


LENSES = {  # name: (distortions, fisheye), the kinds of lens a calibration file can give
    "fisheye": ([0.08, -0.02, 0.01, 0.003], True),
    "brown 4": ([-0.1, 0.02, 0.001, -0.002], False),
    "brown 5": ([-0.1, 0.02, 0.001, -0.002, 0.005], False),
    "rational 8": ([-0.08, 0.02, 0.001, -0.002, 0.0, 0.05, 0.3, 0.05], False),
    "thin prism 12": ([-0.08, 0.02, 0.001, -0.002, 0.0, 0.05, 0.3, 0.05, 0.003, -0.002, 0.001, 0.004], False),
    "tilted 14": ([-0.08, 0.02, 0.001, -0.002, 0.0, 0.05, 0.3, 0.05, 0.003, -0.002, 0.001, 0.004, 0.02, -0.03], False),
}


@pytest.mark.parametrize("lens", list(LENSES))
def test_samples_and_rows_follow_the_calibrated_lens(lens):
    """With every lens model, each sample is Camera.project of its contour point (the outline where the
    calibrated lens images it) and its row is L alpha = n . d/de Camera.project(E exp(e alpha) X_comp)."""
    rng = np.random.default_rng(31)
    model = one_component(SHAPES["ellipsoid"][0])
    distortions, fisheye = LENSES[lens]
    cams = [
        dataclasses.replace(cam, distortions=distortions, fisheye=fisheye)
        for cam in random_cameras(rng, 2, distorted=False)
    ]
    poses = random_pose(rng)[None]
    s = sample(model, poses, cams, spacing=4.0)
    n = s.count
    world = world_points(poses.repeat(n, 0), np.zeros(n, int), s.point[:n])
    eps = 1e-6
    worst = 0.0
    for k, cam in enumerate(cams):
        sel = np.flatnonzero(s.camera[:n] == k)
        assert len(sel) > 50
        assert np.abs(cam.project(world[sel]) - s.pixel[sel]).max() < 1e-9
        for m in sel:
            alpha = rng.normal(size=6)
            x = homog(s.point[m][None])[0]
            plus = (poses[0] @ se3.exp(eps * alpha) @ x)[:3]
            minus = (poses[0] @ se3.exp(-eps * alpha) @ x)[:3]
            fd = ((cam.project(plus[None]) - cam.project(minus[None]))[0] / (2 * eps)) @ s.normal[m]
            scale = max(abs(fd), 0.05 * np.linalg.norm(s.jacobian[m]) * np.linalg.norm(alpha))
            worst = max(worst, abs(fd - s.jacobian[m] @ alpha) / scale)
    assert worst < 1e-5


def test_nothing_beyond_the_fold_of_the_lens():
    """x_d = x (1 - 0.2 r^2) folds over at r = 1.29 (x_d = 0.86): a ball at r = 1.5 would be drawn back inside
    the image at x_d = 0.83 by the formula, but no pixel's ray reaches it; one at r = 1 is seen."""
    rot = np.eye(3)
    cam = Camera(
        "c",
        SIZE,
        np.array([[300.0, 0.0, 319.5], [0.0, 300.0, 239.5], [0.0, 0.0, 1.0]]),
        [-0.2, 0, 0, 0],
        rot,
        np.zeros(3),
    )
    model = one_component(dict(shape="sphere", center=[0.0, 0.0, 0.0], radius=0.1))
    for r, seen in ((1.5, False), (1.0, True)):
        pose = se3.from_rotvec(np.zeros(3), np.array([2.0 * r, 0.0, 2.0]))
        assert 0 < cam.project(pose[:3, 3][None])[0, 0] < SIZE[0] - 1
        assert (sample(model, pose[None], [cam]).count > 0) == seen


def outline_conic(cam, pose, q):
    """C_pix = K^-T (c A - b b^T) K^-1 with Q' = E^-T Q E^-1, E = camera-from-component
    (docs/method-tracking.md, section 2)."""
    e_inv = np.linalg.inv(cam.camera_from_world @ pose)
    qc = e_inv.T @ q @ e_inv
    a, b, c = qc[:3, :3], qc[:3, 3], qc[3, 3]
    k_inv = np.linalg.inv(cam.matrix)
    return k_inv.T @ (c * a - np.outer(b, b)) @ k_inv


def offset_to_conic(conic, p, normal):
    """The root s nearest 0 of (p + s n)~^T C (p + s n)~ = 0."""
    ph = np.append(p, 1.0)
    nh = np.append(normal, 0.0)
    a, b, c = nh @ conic @ nh, 2.0 * (nh @ conic @ ph), ph @ conic @ ph
    roots = np.roots([a, b, c]) if abs(a) > 0 else np.array([-c / b])
    roots = roots[np.isreal(roots)].real
    return roots[np.argmin(np.abs(roots))]


@pytest.mark.parametrize("name", list(SHAPES))
def test_jacobian_row_matches_outline_offset_finite_differences(name):
    """Undistorted: L alpha = d/de of the offset along n from the sample to the moved outline conic."""
    rng = np.random.default_rng(17)
    model = one_component(SHAPES[name][0])
    q = model.quadric[0]
    eps = 1e-6
    worst = 0.0
    checked = 0
    for _ in range(3):
        cams = random_cameras(rng, 2, distorted=False)
        poses = random_pose(rng)[None]
        s = sample(model, poses, cams, spacing=6.0)
        n = s.count
        for m in range(n):
            cam = cams[s.camera[m]]
            p, normal = s.pixel[m], s.normal[m]
            # the sample is on the outline conic and n is its normal
            conic = outline_conic(cam, poses[0], q)
            assert abs(offset_to_conic(conic, p, normal)) < 1e-6
            grad = (conic @ np.append(p, 1.0))[:2]
            np.testing.assert_allclose(grad / np.linalg.norm(grad), normal, atol=1e-9)
            alpha = rng.normal(size=6)
            alpha[3:] *= 2.0
            s_plus = offset_to_conic(outline_conic(cam, poses[0] @ se3.exp(eps * alpha), q), p, normal)
            s_minus = offset_to_conic(outline_conic(cam, poses[0] @ se3.exp(-eps * alpha), q), p, normal)
            fd = (s_plus - s_minus) / (2 * eps)
            predicted = s.jacobian[m] @ alpha
            scale = max(abs(fd), 0.05 * np.linalg.norm(s.jacobian[m]) * np.linalg.norm(alpha))
            worst = max(worst, abs(fd - predicted) / scale)
            checked += 1
    assert checked > 60
    assert worst < 1e-4


def test_jacobian_with_a_skewed_camera_matrix():
    """The kernel allows skew in K: check pixels and L against a numpy projection that includes it."""
    rng = np.random.default_rng(19)
    model = one_component(SHAPES["ellipsoid"][0])
    cam = look_at("c", 2.0 * unit(rng), [0, 0, 0], 650.0, random_distortion(rng), rng, skew=4.0)
    poses = random_pose(rng, 0.03)[None]
    s = sample(model, poses, [cam], spacing=5.0)
    n = s.count
    world = world_points(poses.repeat(n, 0), np.zeros(n, int), s.point[:n])
    assert np.abs(project_numpy(cam, world) - s.pixel[:n]).max() < 1e-6
    eps = 1e-6
    for m in range(n):
        alpha = rng.normal(size=6)
        x = homog(s.point[m][None])[0]
        plus = (poses[0] @ se3.exp(eps * alpha) @ x)[:3]
        minus = (poses[0] @ se3.exp(-eps * alpha) @ x)[:3]
        fd = ((project_numpy(cam, plus[None]) - project_numpy(cam, minus[None]))[0] / (2 * eps)) @ s.normal[m]
        assert abs(fd - s.jacobian[m] @ alpha) < 1e-5 * max(abs(fd), 0.05 * np.linalg.norm(s.jacobian[m]) * 2.5)


def test_camera_project_agrees_with_the_outline_for_a_skewed_camera():
    rng = np.random.default_rng(19)
    model = one_component(SHAPES["ellipsoid"][0])
    cam = look_at("c", 2.0 * unit(rng), [0, 0, 0], 650.0, (), rng, skew=4.0)
    poses = random_pose(rng, 0.03)[None]
    s = sample(model, poses, [cam], spacing=5.0)
    n = s.count
    world = world_points(poses.repeat(n, 0), np.zeros(n, int), s.point[:n])
    assert np.abs(cam.project(world) - s.pixel[:n]).max() < 1e-6


def test_place_matches_the_matrix_formula():
    """place(): E = P_k W_kc (each camera's own poses, each view at its capture time), Q' = E^-T Q E^-1, clip
    likewise, bounding sphere centre E c."""
    rng = np.random.default_rng(23)
    model = load_model(Path(__file__).resolve().parents[2] / "models" / "human.toml")
    poses = np.stack([[se3.exp(rng.normal(size=6)) for _ in range(model.size)] for _ in range(2)])
    cams = random_cameras(rng, 2, distorted=False)
    rig = Rig.from_cameras(cams)
    placed = placed_at(model, poses, rig)
    for k in range(2):
        for j, c in enumerate(model.quadric_component):
            e = rig.camera_from_world[k] @ poses[k, c]
            e_inv = np.linalg.inv(e)
            np.testing.assert_allclose(placed.camera_from[k, j], e, atol=1e-12)
            np.testing.assert_allclose(placed.quadric[k, j], e_inv.T @ model.quadric[j] @ e_inv, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(placed.clip[k, j], e_inv.T @ model.clip[j] @ e_inv, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(
                placed.sphere[k, j, :3], (e @ np.append(model.quadric_bound[j, :3], 1.0))[:3], atol=1e-12
            )
