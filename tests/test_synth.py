"""Synthetic recordings: BVH parsing, retargeting, the ray caster against analytic answers, recording folders."""

from __future__ import annotations

import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import SHARED_DATA, TEST_DATA, needs_shared

from tracker import clips, render, synth
from tracker.camera import load_calibration, save_calibration
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io import bvh as bvh_io
from tracker.io.avi import MjpegAviWriter
from tracker.model import joint_centres, load_model, model_from_dict, rest_poses

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "human.toml"
CMU = TEST_DATA / "cmu-mocap" / "131_01_500-619.bvh"  # frames 500-619 of the clip: frame f here is 500 + f there
FULL_CMU = SHARED_DATA / "cmu-mocap" / "131_01.bvh"


@pytest.fixture(scope="module")
def human():
    return load_model(MODEL)


@pytest.fixture(scope="module")
def bvh():
    return bvh_io.load_bvh(CMU)


def joint_gap(model, poses) -> float:
    """Largest distance between a component's origin and its joint on the parent, over frames."""
    poses = poses.reshape(-1, model.size, 4, 4)
    return max(
        float(np.abs((poses[:, model.parent[i]] @ model.rest[i])[:, 0:3, 3] - poses[:, i, 0:3, 3]).max())
        for i in range(1, model.size)
    )


# --- BVH and retargeting --------------------------------------------------------------------


def _bvh_parse(bvh, frames: int) -> None:
    assert len(bvh.names) == 31
    assert bvh.names[0] == "Hips" and bvh.parents[0] == -1
    assert bvh.frames == frames
    assert bvh.frame_time == pytest.approx(1 / 120, rel=1e-4)
    assert bvh.channels[0][:3] == ("Xposition", "Yposition", "Zposition")
    assert bvh.channels[bvh.index("LeftShoulder")] == ("Zrotation", "Xrotation", "Yrotation")
    assert bvh.motion.shape == (frames, sum(len(c) for c in bvh.channels))


def test_bvh_parse(bvh):
    _bvh_parse(bvh, 120)


@needs_shared("cmu-mocap", "131_01.bvh")
def test_full_clip_parses_and_holds_the_committed_frames(bvh, human):
    full = bvh_io.load_bvh(FULL_CMU)
    _bvh_parse(full, 994)
    assert full.names == bvh.names and full.channels == bvh.channels
    np.testing.assert_array_equal(full.parents, bvh.parents)
    np.testing.assert_array_equal(full.offsets, bvh.offsets)
    np.testing.assert_array_equal(full.motion[500:620], bvh.motion)
    # the same poses from either file (measured: 4.6e-8 apart, round-off)
    np.testing.assert_allclose(
        clips.retarget(full, human, start=500, frames=40, stride=2),
        clips.retarget(bvh, human, start=0, frames=40, stride=2),
        rtol=0,
        atol=1e-6,
    )


def test_bvh_forward_kinematics_intrinsic_order(bvh):
    """A joint's world rotation is the parent's times Rz Ry Rx (channels in listed order) and offsets hang on it."""
    world = bvh_io.bvh_global(bvh, np.array([100]))[0]
    j = bvh.index("LeftKnee")
    p = bvh.parents[j]
    start = bvh.channel_start[j]
    z, y, x = np.radians(bvh.motion[100, start : start + 3])
    local = se3.exp_so3(np.array([0, 0, z])) @ se3.exp_so3(np.array([0, y, 0])) @ se3.exp_so3(np.array([x, 0, 0]))
    np.testing.assert_allclose(world[j, 0:3, 0:3], world[p, 0:3, 0:3] @ local, atol=1e-12)
    np.testing.assert_allclose(world[j, 0:3, 3], world[p, 0:3, 0:3] @ bvh.offsets[j] + world[p, 0:3, 3], atol=1e-12)


def test_retarget_valid_poses_and_hinge_knee(bvh, human):
    poses = clips.retarget(bvh, human, start=0, frames=40, stride=2)  # the clip's frames 500-578
    assert poses.shape == (40, human.size, 4, 4)
    assert joint_gap(human, poses) < 1e-9
    rot = poses[:, :, 0:3, 0:3]
    np.testing.assert_allclose(np.einsum("fnba,fnbc->fnac", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)
    for name in ("shin_l", "shin_r", "forearm_l", "forearm_r"):
        i = human.index(name)
        relative = np.einsum("fba,fbc->fac", rot[:, human.parent[i]], rot[:, i])
        w = np.array([se3.log_so3(np.ascontiguousarray(r)) for r in relative])
        angle = w @ human.axis[i]
        np.testing.assert_allclose(w, np.outer(angle, human.axis[i]), atol=1e-9)  # pure hinge
    knee = [
        se3.log_so3(np.ascontiguousarray(r)) @ human.axis[human.index("shin_l")]
        for r in np.einsum("fba,fbc->fac", rot[:, human.index("thigh_l")], rot[:, human.index("shin_l")])
    ]
    assert np.ptp(knee) > np.radians(30) and np.min(knee) > np.radians(-5)  # the knee bends, forwards only
    # walking: the pelvis moves, upright, feet on the floor, centred on the origin
    assert np.all(poses[:, 0, 2, 2] > 0.8)
    assert abs(float(np.median(clips.lowest_points(human, poses)))) < 1e-9


def test_retarget_follows_bvh_bone_directions(bvh, human):
    poses = clips.retarget(bvh, human, start=100, frames=5, stride=3, centre=False)  # the clip's 600-612
    world = bvh_io.bvh_global(bvh, 100 + 3 * np.arange(5))
    for name in ("thigh_r", "shin_r", "upperarm_l", "forearm_l", "foot_r"):
        joint, tip, direction = clips.RETARGET_MAP[name]
        bone = (world[:, bvh.index(tip), 0:3, 3] - world[:, bvh.index(joint), 0:3, 3]) @ clips.BVH_TO_WORLD.T
        bone /= np.linalg.norm(bone, axis=1, keepdims=True)
        ours = poses[:, human.index(name), 0:3, 0:3] @ np.asarray(direction)
        np.testing.assert_allclose(ours, bone, atol=1e-6)


def test_bvh_errors(tmp_path, human):
    with pytest.raises(TrackerInputError, match="not found"):
        bvh_io.load_bvh(tmp_path / "missing.bvh")
    text = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Spine
  {
    OFFSET 0 2 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 2 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0083333
0 17 0 0 0 0 0 0 0
0 17 1 0 0 0 0 90 0
"""
    path = tmp_path / "tiny.bvh"
    path.write_text(text)
    tiny = bvh_io.load_bvh(path)
    assert tiny.names == ("Hips", "Spine") and tiny.frames == 2
    world = bvh_io.bvh_global(tiny)
    np.testing.assert_allclose(world[1, 1, 0:3, 3], [0, 19, 1])
    np.testing.assert_allclose(world[1, 1, 0:3, 0:3] @ [0, 1, 0], [0, 0, 1], atol=1e-12)  # 90 deg about X
    with pytest.raises(TrackerInputError, match="tiny.bvh.*no joint"):
        clips.retarget(tiny, human, path=path)
    with pytest.raises(TrackerInputError, match="no joint"):
        synth.synthesize(MODEL, _rig(tmp_path), tmp_path / "out", motion=f"bvh:{path}", frames=1, progress=False)
    (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0\n")
    with pytest.raises(TrackerInputError, match="bad.bvh"):
        bvh_io.load_bvh(tmp_path / "bad.bvh")


def test_procedural_motion_valid(human):
    poses = clips.procedural_motion(human, 30, fps=30.0, seed=3)
    assert joint_gap(human, poses) < 1e-9
    assert abs(float(np.median(clips.lowest_points(human, poses)))) < 1e-9
    step = np.linalg.norm(np.diff(joint_centres(poses), axis=0), axis=2)
    assert step.max() < 0.1  # smooth: under 3 m/s at 30 fps
    assert not np.allclose(poses[0], poses[-1])


# --- the ray caster -------------------------------------------------------------------------


def _one_component(shape: dict) -> object:
    return model_from_dict({"component": [{"name": "body", "parent": "", "joint": "free", "quadric": [shape]}]})


def _cast(model, poses, camera):
    renderer = render.Renderer(model, camera, noise=0.0, blur=0.0)
    return [a.copy() for a in renderer.cast(poses)]


@pytest.mark.parametrize("distortions", [(0.0, 0.0, 0.0, 0.0), (-0.08, 0.02, 0.0, 0.0)])
def test_sphere_silhouette_matches_analytic_projection(distortions):
    radius, distance, f = 0.3, 3.0, 200.0
    model = _one_component({"shape": "sphere", "center": [0, 0, 0], "radius": radius})
    camera = synth.look_at_camera("c", (0.0, -distance, 0.0), (0.0, 0.0, 0.0), (161, 121), f, distortions)
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
    camera = synth.look_at_camera("c", (2.5, -2.5, 1.4), (0, 0, 0.9), (120, 100), 150.0, (-0.08, 0.02, 0, 0))
    poses = clips.procedural_motion(human, 1, seed=1)[0]
    comp, shade, depth = _cast(human, poses, camera)
    surfaces, planes = render.view_quadrics(human, poses, camera)
    light = camera.rotation @ (render.DEFAULT_LIGHT / np.linalg.norm(render.DEFAULT_LIGHT))
    comp2, shade2, depth2 = render.render(render.pixel_rays(camera), surfaces, planes, human.quadric_component, light)
    assert np.count_nonzero(comp >= 0) > 500
    assert np.count_nonzero(comp != comp2) <= 2  # root ties at grazing rays only
    same = (comp == comp2) & (comp >= 0)
    np.testing.assert_allclose(shade[same], shade2[same], atol=1e-6)
    np.testing.assert_allclose(depth[same], depth2[same], rtol=1e-6)


def test_rays_through_limbs_hit_them(human):
    poses = rest_poses(human, se3.from_rotvec(np.zeros(3), (0.0, 0.0, 0.92)))
    camera = synth.look_at_camera("c", (0.3, -3.5, 1.0), (0, 0, 0.9), (320, 240), 260.0, (-0.08, 0.02, 0, 0))
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
    side = synth.look_at_camera("c", (0.0, -2.0, -0.2), (0.0, 0.0, -0.2), (200, 200), 300.0)
    comp, _, _ = _cast(model, np.eye(4)[None], side)
    for z, seen in ((-0.39, True), (-0.41, False), (-0.01, True), (0.01, False)):
        u, v = np.rint(side.project(np.array([[0.0, -0.05, z]]))[0]).astype(int)
        assert (comp[v, u] == 0) == seen, z
    # looking obliquely into the open top: the ray through its centre hits the far inside wall
    eye = np.array([0.0, -1.0, 1.0])
    into = synth.look_at_camera("c", eye, (0.0, 0.0, 0.0), (201, 201), 300.0)
    comp, shade, depth = _cast(model, np.eye(4)[None], into)
    assert comp[100, 100] == 0
    direction = -eye / np.linalg.norm(eye)
    # far intersection with x^2 + y^2 = r^2 along eye + s d: (-1 + s d_y)^2 = 0.05^2 -> s = (1 + 0.05)/d_y
    s = (1.0 + 0.05) / direction[1]
    assert depth[100, 100] == pytest.approx(s * (direction @ (into.rotation[2])), rel=1e-9)
    assert shade[100, 100] > 0


def test_renderer_speed_and_image(human):
    camera = synth.demo3_rig()[0]
    renderer = render.Renderer(human, camera)
    poses = clips.procedural_motion(human, 2, seed=0)
    image = renderer.render(poses[0], np.random.default_rng(0))
    assert image.shape == (480, 640, 3) and image.dtype == np.uint8
    import time

    tick = time.perf_counter()
    for _ in range(3):
        renderer.cast(poses[1])
    assert (time.perf_counter() - tick) / 3 < 0.05


# --- recordings -----------------------------------------------------------------------------


def _rig(tmp_path) -> Path:
    path = tmp_path / "rig.toml"
    cams = [
        synth.look_at_camera("a", (0.5, -4.0, 1.4), (0, 0, 0.9), (160, 120), 140.0, (-0.05, 0.01, 0, 0)),
        synth.look_at_camera("b", (4.0, 0.5, 1.2), (0, 0, 0.9), (160, 120), 140.0),
    ]
    save_calibration(cams, path)
    return path


def test_look_at_camera_centres_target():
    cam = synth.look_at_camera("x", (3.0, -2.0, 1.5), (0.1, 0.2, 0.9), (640, 480), 500.0, (-0.1, 0.02, 0, 0))
    np.testing.assert_allclose(cam.project(np.array([[0.1, 0.2, 0.9]]))[0], [319.5, 239.5], atol=1e-9)
    up = cam.project(np.array([[0.1, 0.2, 1.2]]))[0]
    assert up[1] < 239.5  # world up is image up
    np.testing.assert_allclose(cam.center, [3.0, -2.0, 1.5], atol=1e-12)


@pytest.mark.parametrize("motion", ["procedural", "bvh"])
def test_synthesize_writes_recording(tmp_path, human, motion):
    if motion == "bvh":
        motion = f"bvh:{CMU}"
    out = tmp_path / "rec"
    summary = synth.synthesize(
        MODEL, _rig(tmp_path), out, motion=motion, frames=5, start=100, stride=2, seed=1, progress=False
    )  # bvh: the clip's frames 600-608
    names = {"calibration.toml", "a.avi", "b.avi", "model.toml", "init.toml", "truth.npz", "README.md"}
    assert names <= {p.name for p in out.iterdir()}
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files left
    assert summary["fps"] == 60.0 and summary["frames"] == 5
    assert [c.name for c in load_calibration(out / "calibration.toml")] == ["a", "b"]
    assert (out / "model.toml").read_bytes() == MODEL.read_bytes()
    for cam in ("a", "b"):
        capture = cv2.VideoCapture(str(out / f"{cam}.avi"))
        frames = []
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            frames.append(frame)
        assert len(frames) == 5 and frames[0].shape == (120, 160, 3)
        assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(60.0)
    with np.load(out / "truth.npz", allow_pickle=False) as truth:
        poses = truth["poses"]
        assert poses.shape == (5, human.size, 4, 4)
        assert list(truth["component_names"]) == list(human.names)
        assert list(truth["joint_names"]) == list(human.joint_names)
        assert truth["joint_names"].dtype.kind == "U"
        np.testing.assert_array_equal(truth["frame"], np.arange(5))
        np.testing.assert_allclose(truth["joints"], poses[:, :, 0:3, 3])
    assert joint_gap(human, poses) < 1e-9
    init = tomllib.loads((out / "init.toml").read_text())["pose"]
    assert set(init) == set(human.names)
    np.testing.assert_allclose(init["pelvis"]["translation"], poses[0, 0, 0:3, 3])
    for name, entry in init.items():
        i = human.index(name)
        np.testing.assert_allclose(se3.exp_so3(np.array(entry["rotation"])), poses[0, i, 0:3, 0:3], atol=1e-9)
        assert ("translation" in entry) == (i == 0)
    readme = (out / "README.md").read_text()
    assert ("CMU Graphics Lab" in readme) == motion.startswith("bvh:")


def test_mjpeg_writer_roundtrip(tmp_path):
    rng = np.random.default_rng(0)
    images = [cv2.GaussianBlur(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), (0, 0), 2.0) for _ in range(4)]
    with MjpegAviWriter(tmp_path / "v.avi", 25.0, (64, 48), quality=90) as writer:
        for image in images:
            writer.write(image)
    capture = cv2.VideoCapture(str(tmp_path / "v.avi"))
    assert capture.get(cv2.CAP_PROP_FRAME_COUNT) == 4
    assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(25.0)
    for image in images:
        ok, frame = capture.read()
        assert ok and np.abs(frame.astype(int) - image).mean() < 4
    assert not capture.read()[0]


def test_committed_rigs_are_the_ones_write_rigs_makes(tmp_path):
    """calib/demo3.toml and calib/ring4.toml are regenerated by synth.write_rigs(); they must agree."""
    for made in synth.write_rigs(tmp_path):
        committed = load_calibration(Path(__file__).resolve().parents[1] / "calib" / made.name)
        for a, b in zip(load_calibration(made), committed, strict=True):
            assert a.name == b.name and a.size == b.size
            np.testing.assert_allclose(a.matrix, b.matrix)
            np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)
            np.testing.assert_allclose(a.translation, b.translation, atol=1e-12)
