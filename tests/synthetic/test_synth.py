"""Synthetic recordings: BVH parsing, retargeting, the renderer, recording folders."""

from __future__ import annotations

import hashlib
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
import tomli_w
from conftest import SHARED_DATA, TEST_DATA, needs_shared

from tracker import raycast
from tracker.camera import load_calibration, look_at_camera, save_calibration
from tracker.cli import main
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io import bvh_clip
from tracker.io.avi import MjpegAviWriter
from tracker.model import joint_centres, load_model, model_from_dict
from tracker.synthetic import actor as capsules
from tracker.synthetic import clips, props, render, synth, texture
from tracker.tomlfile import read_toml

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "human.toml"
CMU = TEST_DATA / "cmu-mocap" / "131_01_500-619.bvh"  # frames 500-619 of the clip: frame f here is 500 + f there
FULL_CMU = SHARED_DATA / "cmu-mocap" / "131_01.bvh"


@pytest.fixture(scope="module")
def human():
    return load_model(MODEL)


@pytest.fixture(scope="module")
def bvh():
    return bvh_clip.load_bvh(CMU)


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
    full = bvh_clip.load_bvh(FULL_CMU)
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
    world = bvh_clip.bvh_global(bvh, np.array([100]))[0]
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
    world = bvh_clip.bvh_global(bvh, 100 + 3 * np.arange(5))
    for name in ("thigh_r", "shin_r", "upperarm_l", "forearm_l", "foot_r"):
        joint, tip, direction = clips.RETARGET_MAP[name]
        bone = (world[:, bvh.index(tip), 0:3, 3] - world[:, bvh.index(joint), 0:3, 3]) @ clips.BVH_TO_WORLD.T
        bone /= np.linalg.norm(bone, axis=1, keepdims=True)
        ours = poses[:, human.index(name), 0:3, 0:3] @ np.asarray(direction)
        np.testing.assert_allclose(ours, bone, atol=1e-6)


def test_bvh_errors(tmp_path, human):
    with pytest.raises(TrackerInputError, match="not found"):
        bvh_clip.load_bvh(tmp_path / "missing.bvh")
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
    tiny = bvh_clip.load_bvh(path)
    assert tiny.names == ("Hips", "Spine") and tiny.frames == 2
    world = bvh_clip.bvh_global(tiny)
    np.testing.assert_allclose(world[1, 1, 0:3, 3], [0, 19, 1])
    np.testing.assert_allclose(world[1, 1, 0:3, 0:3] @ [0, 1, 0], [0, 0, 1], atol=1e-12)  # 90 deg about X
    with pytest.raises(TrackerInputError, match="tiny.bvh.*no joint"):
        clips.retarget(tiny, human, path=path)
    with pytest.raises(TrackerInputError, match="no joint"):
        synth.synthesize(MODEL, _rig(tmp_path), tmp_path / "out", motion=f"bvh:{path}", frames=1, progress=False)
    (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0\n")
    with pytest.raises(TrackerInputError, match="bad.bvh"):
        bvh_clip.load_bvh(tmp_path / "bad.bvh")


def test_seated_motion_sits(human):
    poses = clips.seated_motion(human, 40, fps=30.0, seed=5)
    assert joint_gap(human, poses) < 1e-9
    assert abs(float(np.median(clips.lowest_points(human, poses)))) < 1e-9
    centres = joint_centres(poses)
    knee, hip = centres[:, human.index("shin_l")], centres[:, human.index("thigh_l")]
    ankle = centres[:, human.index("foot_l")]
    thigh = np.linalg.norm(human.rest[human.index("shin_l"), 0:3, 3])
    assert np.abs(knee[:, 2] - hip[:, 2]).max() < 0.15 * thigh  # thighs about level
    assert np.linalg.norm((knee - hip)[:, :2], axis=1).min() > 0.95 * thigh
    assert np.abs(ankle[:, :2] - knee[:, :2]).max() < 0.1  # shins about upright
    assert np.ptp(centres[:, human.index("forearm_r")], axis=0).max() > 0.1  # the arms work
    assert np.linalg.norm(np.diff(centres, axis=0), axis=2).max() < 0.1


def test_procedural_motion_valid(human):
    poses = clips.procedural_motion(human, 30, fps=30.0, seed=3)
    assert joint_gap(human, poses) < 1e-9
    assert abs(float(np.median(clips.lowest_points(human, poses)))) < 1e-9
    step = np.linalg.norm(np.diff(joint_centres(poses), axis=0), axis=2)
    assert step.max() < 0.1  # smooth: under 3 m/s at 30 fps
    assert not np.allclose(poses[0], poses[-1])


def test_renderer_image(human):
    camera = synth.demo3_rig()[0]
    renderer = render.Renderer(human, camera)
    poses = clips.procedural_motion(human, 2, seed=0)
    image = renderer.render(poses[0], np.random.default_rng(0))
    assert image.shape == (480, 640, 3) and image.dtype == np.uint8
    component, _, _ = renderer.cast(poses[1])
    assert set(np.unique(component)) - {-1} == set(range(human.size))  # every part in view


# --- recordings -----------------------------------------------------------------------------


def _rig(tmp_path) -> Path:
    path = tmp_path / "rig.toml"
    cams = [
        look_at_camera(
            "a", (0.5, -4.0, 1.4), (0, 0, 0.9), size=(160, 120), focal=140.0, distortions=(-0.05, 0.01, 0, 0)
        ),
        look_at_camera("b", (4.0, 0.5, 1.2), (0, 0, 0.9), size=(160, 120), focal=140.0),
    ]
    save_calibration(cams, path)
    return path


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
        committed = load_calibration(Path(__file__).resolve().parents[2] / "calib" / made.name)
        for a, b in zip(load_calibration(made), committed, strict=True):
            assert a.name == b.name and a.size == b.size
            np.testing.assert_allclose(a.matrix, b.matrix)
            np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)
            np.testing.assert_allclose(a.translation, b.translation, atol=1e-12)


# --- renders unlike the model ---------------------------------------------------------------


def _tiny_camera(size=(160, 120), focal=150.0):
    return look_at_camera(
        "c", (0.6, -3.6, 1.3), (0.0, 0.0, 0.9), size=size, focal=focal, distortions=(-0.05, 0.01, 0.0, 0.0)
    )


def _moved(camera, world_from_new):
    """The camera seeing the world moved by ``world_from_new`` as it saw the old one."""
    return camera.with_camera_from_world(camera.camera_from_world @ np.linalg.inv(world_from_new))


def test_texture_changes_body_pixels_only_moves_with_the_body_and_is_deterministic(human):
    camera = _tiny_camera()
    poses = clips.procedural_motion(human, 1, seed=2)[0]
    plain = render.Renderer(human, camera, noise=0.0, blur=0.0)
    comp = plain.cast(poses)[0].copy()
    reference = plain.render(poses)
    for kind in texture.KINDS:
        made = texture.make_texture(kind, human.names, render.albedos(human), seed=4)
        dressed = render.Renderer(human, camera, noise=0.0, blur=0.0, texture=made).render(poses)
        changed = np.any(dressed != reference, axis=2)
        assert not np.any(changed & (comp < 0)), kind  # the background is untouched
        assert changed[comp >= 0].mean() > 0.1, kind  # a good share of the body is repainted
        again = render.Renderer(human, camera, noise=0.0, blur=0.0, texture=made).render(poses)
        np.testing.assert_array_equal(again, dressed)
        # body, camera and light moved together by one rigid motion: the same image, so the pattern rides on the body
        motion = se3.from_rotvec((0.1, -0.2, 0.7), (0.4, -0.3, 0.2))
        light = motion[0:3, 0:3] @ raycast.DEFAULT_LIGHT
        riding = render.Renderer(human, _moved(camera, motion), light=light, noise=0.0, blur=0.0, texture=made)
        moved = riding.render(np.einsum("ab,nbc->nac", motion, poses))
        assert np.mean(moved.astype(int) != dressed) < 0.002  # a few edge pixels round differently
    other = texture.make_texture("stripes", human.names, render.albedos(human), seed=5)
    first = texture.make_texture("stripes", human.names, render.albedos(human), seed=4)
    assert not np.allclose(other.period, first.period)
    left, right = human.index("thigh_l"), human.index("thigh_r")
    assert first.period[left] == first.period[right]  # a pair of trousers


def test_capsule_body_sizes_within_jitter_and_seeded(human):
    data = read_toml(MODEL, "model", "")
    actor = model_from_dict(capsules.capsule_body(data, 0.1, seed=3))
    assert actor.names == human.names and set(actor.quadric_shape) == {"cylinder", "sphere"}
    np.testing.assert_array_equal(actor.parent, human.parent)
    np.testing.assert_array_equal(actor.joint_type, human.joint_type)
    bones = np.linalg.norm(human.rest[:, 0:3, 3], axis=1) > 0
    ratio = np.linalg.norm(actor.rest[bones, 0:3, 3], axis=1) / np.linalg.norm(human.rest[bones, 0:3, 3], axis=1)
    assert np.all((ratio >= 0.9) & (ratio <= 1.1)) and np.ptp(ratio) > 0.05
    for name in ("thigh_l", "shin_r", "upperarm_l", "forearm_r"):  # cones -> capsules of the mean radius, +-10 %
        model_radius = np.mean(human.quadric_params[list(human.quadric_component).index(human.index(name))]["radii"])
        radii = [p["radius"] for p, c in zip(actor.quadric_params, actor.quadric_component) if c == actor.index(name)]
        assert len(set(radii)) == 1 and 0.9 <= radii[0] / model_radius <= 1.1
    pair = [actor.quadric_params[list(actor.quadric_component).index(actor.index(n))] for n in ("shin_l", "shin_r")]
    assert pair[0]["radius"] == pair[1]["radius"]  # left and right alike
    assert capsules.capsule_body(data, 0.1, seed=3) == capsules.capsule_body(data, 0.1, seed=3)
    assert capsules.capsule_body(data, 0.1, seed=4) != capsules.capsule_body(data, 0.1, seed=3)


def test_capsule_render_truth_is_the_rendered_body(tmp_path, human):
    out = tmp_path / "rec"
    staging = synth.Staging(body="capsules")
    synth.synthesize(
        MODEL, _rig(tmp_path), out, frames=3, seed=2, codec="png", noise=0.0, progress=False, staging=staging
    )
    assert (out / "model.toml").read_bytes() == MODEL.read_bytes()  # the tracking model, unperturbed
    with np.load(out / "truth.npz") as truth:
        true_poses, joints, names = truth["poses"], truth["joints"], list(truth["joint_names"])
    assert names == list(human.joint_names)
    actor = model_from_dict(capsules.capsule_body(read_toml(MODEL, "model", ""), 0.1, seed=2))
    motion, _, _ = synth.motion_poses(human, "procedural", 3, seed=2)
    np.testing.assert_allclose(true_poses, capsules.actor_poses(actor, human, motion), atol=1e-12)
    np.testing.assert_allclose(joints, joint_centres(true_poses))  # all seen here
    assert joint_gap(actor, true_poses) < 1e-9
    assert np.abs(joint_centres(motion) - joints).max() > 0.02  # not the model's joints
    camera = load_calibration(out / "calibration.toml")[0]
    background = cv2.imread(str(out / "a" / "000001.png"))
    photo = render.load_backgrounds([camera], None, 2)[0][0]
    assert np.array_equal(render.Renderer(actor, camera, photo, noise=0.0).render(true_poses[1]), background)
    assert not np.array_equal(render.Renderer(human, camera, photo, noise=0.0).render(true_poses[1]), background)


def test_seen_joints_behind_a_box_or_outside_every_image():
    camera = look_at_camera("c", (0.0, -4.0, 1.0), (0.0, 0.0, 1.0), size=(200, 100), focal=200.0)
    points = np.array([[[0.0, 0.0, 1.0], [0.0, 0.0, 0.3], [3.0, 0.0, 1.0]]])  # centre, low, far off to the side
    np.testing.assert_array_equal(synth.seen_joints(points, [camera]), [[True, True, False]])
    box = props.Box(se3.from_rotvec((0.0, 0.0, 0.0), (0.0, -1.0, 0.25)), np.array([0.5, 0.2, 0.25]))
    np.testing.assert_array_equal(synth.seen_joints(points, [camera], (box,)), [[True, False, False]])
    behind = props.Box(se3.from_rotvec((0.0, 0.0, 0.0), (0.0, 1.0, 0.25)), np.array([0.5, 0.2, 0.25]))
    np.testing.assert_array_equal(synth.seen_joints(points, [camera], (behind,)), [[True, True, False]])
    side = look_at_camera("s", (4.0, 0.0, 1.0), (0.0, 0.0, 1.0), size=(200, 100), focal=200.0)
    np.testing.assert_array_equal(synth.seen_joints(points, [camera, side], (box,)), [[True, True, True]])
    # the box's depth along a ray: its near face, 4 - 1 - 0.2 = 2.8 m from the camera
    depth, index, normal = props.cast_boxes([box], camera, np.array([[0.0, 0.75 / 2.8], [0.0, -0.2]]))
    assert depth[0] == pytest.approx(2.8) and index.tolist() == [0, -1] and np.isinf(depth[1])
    np.testing.assert_allclose(normal[0], [0.0, 0.0, -1.0], atol=1e-12)


def test_table_hides_the_legs_in_the_images_and_the_truth(tmp_path, human):
    out = tmp_path / "rec"
    rig = _rig(tmp_path)
    staging = synth.Staging(tables=("all",))
    synth.synthesize(MODEL, rig, out, frames=2, seed=1, codec="png", noise=0.0, progress=False, staging=staging)
    with np.load(out / "truth.npz") as truth:
        joints, poses = truth["joints"], truth["poses"]
    hidden = [human.names[j] for j in np.flatnonzero(np.isnan(joints).any(axis=(0, 2)))]
    assert {"foot_l", "foot_r"} <= set(hidden) and "head" not in hidden and "pelvis" not in hidden
    assert not np.isnan(poses).any()  # the poses stay whole; only unseen joints are NaN
    cameras = load_calibration(out / "calibration.toml")
    for camera in cameras:  # the ankles' pixels show the table, not the body
        image = cv2.imread(str(out / camera.name / "000000.png"))
        plain = render.Renderer(human, camera, render.load_backgrounds([camera], None, 1)[0][0], noise=0.0)
        comp = plain.cast(poses[0])[0]
        for name in ("foot_l", "foot_r"):
            u, v = np.rint(camera.project(poses[0, human.index(name), 0:3, 3][None])[0]).astype(int)
            assert comp[v, u] >= 0  # the body is there without the table ...
            table = np.array(props.TABLE_ALBEDO) * 255.0 * 0.35  # ... and now the table's colour, at least its ambient
            assert np.all(image[v, u] >= table - 2) and np.all(image[v, u] < 255 * np.array(props.TABLE_ALBEDO) + 2)


def test_exposure_poses_interpolate_between_frames(human):
    poses = clips.procedural_motion(human, 6, fps=30.0, seed=1)
    exposure = clips.exposure_poses(human, poses, samples=3, shutter=2.0)  # offsets -1, 0, +1 frame
    np.testing.assert_allclose(exposure[2:5, 0], poses[1:4], atol=1e-9)
    np.testing.assert_allclose(exposure[2:5, 1], poses[2:5], atol=0)
    np.testing.assert_allclose(exposure[2:5, 2], poses[3:6], atol=1e-9)
    half = clips.exposure_poses(human, poses, samples=5, shutter=1.0)
    assert joint_gap(human, half) < 1e-9
    np.testing.assert_array_equal(clips.exposure_poses(human, poses, samples=1, shutter=1.0)[:, 0], poses)
    middle = joint_centres(half[3, 4])  # half a frame on: between frames 3 and 4
    assert np.linalg.norm(middle - 0.5 * (joint_centres(poses[3]) + joint_centres(poses[4])), axis=1).max() < 0.01


def test_poses_at_fractional_times(human):
    """Whole frames give the clip's poses exactly; between them the joints move on between the two frames; before
    the first and after the last the motion is carried on; every pose keeps its joints together."""
    poses = clips.procedural_motion(human, 6, fps=30.0, seed=1)
    np.testing.assert_array_equal(clips.poses_at(human, poses, np.array([0.0, 3.0, 5.0])), poses[[0, 3, 5]])
    between = clips.poses_at(human, poses, np.array([2.25, -0.5, 5.5]))
    assert joint_gap(human, between) < 1e-9
    quarter = joint_centres(between[0])
    expected = 0.75 * joint_centres(poses[2]) + 0.25 * joint_centres(poses[3])
    assert np.linalg.norm(quarter - expected, axis=1).max() < 0.01
    root = human.index("pelvis")
    np.testing.assert_allclose(between[1, root, :3, 3], 1.5 * poses[0, root, :3, 3] - 0.5 * poses[1, root, :3, 3])
    np.testing.assert_allclose(between[2, root, :3, 3], 1.5 * poses[5, root, :3, 3] - 0.5 * poses[4, root, :3, 3])


def _frames(video: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(video))
    frames = []
    while (read := capture.read())[0]:
        frames.append(read[1])
    return frames


def test_a_camera_rendered_late_shows_the_later_frames(tmp_path, human):
    """``--time-offsets b=T``: camera b's frame n shows the body at frame n + T fps of the clip; camera a and the
    truth are those of the render without offsets, and the recording does not name the offsets."""
    rig = _rig(tmp_path)
    render_args = dict(motion="procedural", frames=5, fps=30.0, seed=1, noise=0.0, progress=False)
    synth.synthesize(MODEL, rig, tmp_path / "on_time", **render_args)
    synth.synthesize(MODEL, rig, tmp_path / "late", staging=synth.Staging(time_offsets=(("b", 1 / 30),)), **render_args)
    on_time, late = tmp_path / "on_time", tmp_path / "late"
    for a, b in zip(_frames(on_time / "a.avi"), _frames(late / "a.avi"), strict=True):
        np.testing.assert_array_equal(a, b)
    ahead, shown = _frames(on_time / "b.avi"), _frames(late / "b.avi")
    for f in range(4):
        assert np.abs(shown[f].astype(int) - ahead[f + 1]).max() <= 2  # the same pose to the last bits
    assert np.abs(shown[0].astype(int) - ahead[0]).max() > 20  # and not the frame on time
    with np.load(on_time / "truth.npz") as one, np.load(late / "truth.npz") as other:
        np.testing.assert_array_equal(one["joints"], other["joints"])
    assert "offset" not in (late / "README.md").read_text()


def test_time_offsets_are_checked(tmp_path):
    rig = _rig(tmp_path)
    for offsets, message in [
        ((("c", 0.01),), "time offset of 'c': the rig has a, b"),
        ((("b", float("nan")),), "time offset of 'b': nan is not a number"),
        ((("b", 0.2),), "each must be shorter than the recording"),
    ]:
        with pytest.raises(TrackerInputError, match=message):
            synth.synthesize(
                MODEL,
                rig,
                tmp_path / "x",
                frames=5,
                fps=30.0,
                progress=False,
                staging=synth.Staging(time_offsets=offsets),
            )


def test_motion_blur_changes_only_near_moving_edges(human):
    camera = _tiny_camera()
    poses = clips.athletic_motion(human, 40, fps=30.0, seed=7)
    exposure = clips.exposure_poses(human, poses, samples=6, shutter=1.0)[25]
    renderer = render.Renderer(human, camera, noise=0.0, blur=0.7)
    sharp = renderer.render(poses[25]).astype(int)
    blurred = renderer.render(exposure).astype(int)
    comps = np.stack([renderer.cast(p)[0].copy() for p in (poses[25], *exposure)])
    moving = np.any(comps != comps[0], axis=0)  # pixels that change hands during the exposure or at its middle
    near_moving = cv2.dilate(moving.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    near_body = cv2.dilate(np.any(comps >= 0, axis=0).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    difference = np.abs(blurred - sharp).max(axis=2)
    assert moving.sum() > 50 and difference[moving].max() > 40  # the kick does blur
    assert np.all(difference[~near_body] == 0)  # far from the body nothing changes
    assert difference[~near_moving].max() <= 12  # inside the body: only the shading as parts turn a little


def test_default_render_is_bit_identical_to_before(tmp_path):
    """Hashes of a tiny render made by the code before Staging existed: the default options take the old path."""
    rig = _rig(tmp_path)
    expected = {
        ("procedural", 4, 0, 2, 1): "928dbc9e7a2a8d654070833354f8b131167314ab0885f8b4f1b281cd155f9c1d",
        (f"bvh:{CMU}", 3, 10, 4, 2): "80c82098089de97957d09417225aa8bee13f8199f4ce0c9d15da5b154e38811b",
    }
    for (motion, frames, start, stride, seed), digest in expected.items():
        out = tmp_path / motion[:3]
        synth.synthesize(
            MODEL,
            rig,
            out,
            motion=motion,
            frames=frames,
            start=start,
            stride=stride,
            seed=seed,
            codec="png",
            progress=False,
        )
        h = hashlib.sha256()
        for cam in ("a", "b"):
            for path in sorted((out / cam).glob("*.png")):
                h.update(cv2.imread(str(path), cv2.IMREAD_UNCHANGED).tobytes())
        with np.load(out / "truth.npz") as truth:
            for key in sorted(truth.files):
                h.update(key.encode())
                h.update(np.ascontiguousarray(truth[key]).tobytes())
        init = tomllib.loads((out / "init.toml").read_text())
        assert init.pop("frame") == 0  # the pose at the recording's first frame
        h.update(tomli_w.dumps(init).encode())  # the rest as written before init.toml said its frame
        assert h.hexdigest() == digest, motion


def test_athletic_motion_is_fast_airborne_turning_and_seeded(human):
    poses = clips.athletic_motion(human, 120, fps=30.0, seed=0)
    assert joint_gap(human, poses) < 1e-9
    low = clips.lowest_points(human, poses)
    assert abs(float(np.median(low))) < 1e-9 and low.max() > 0.1  # on the floor, and in the air at times
    assert np.ptp(np.unwrap(np.arctan2(poses[:, 0, 1, 0], poses[:, 0, 0, 0]))) > np.pi  # a spin
    speed = np.linalg.norm(np.diff(joint_centres(poses), axis=0), axis=2).max() * 30.0
    calm = np.linalg.norm(np.diff(joint_centres(clips.procedural_motion(human, 120, fps=30.0, seed=0)), axis=0), axis=2)
    assert speed > 4.0 and speed > 2.0 * calm.max() * 30.0
    kinds = {move for move, *_ in clips.athletic_schedule(4.0, seed=0)}
    assert kinds == set(clips.ATHLETIC_MOVES)
    np.testing.assert_array_equal(clips.athletic_motion(human, 10, fps=30.0, seed=0), poses[:10])
    assert not np.allclose(clips.athletic_motion(human, 10, fps=30.0, seed=1), poses[:10])


def test_moved_rig_zooms_and_backs_off():
    rig = synth.demo3_rig()
    zoomed = synth.moved_rig(rig, zoom=2.0)
    far = synth.moved_rig(rig, distance=2.5)
    centre = synth.SCENE_CENTRE[None]
    for camera, z, d in zip(rig, zoomed, far):
        np.testing.assert_allclose(z.matrix[[0, 1], [0, 1]], 2.0 * camera.matrix[[0, 1], [0, 1]])
        np.testing.assert_allclose(z.matrix[0:2, 2], camera.matrix[0:2, 2])
        np.testing.assert_array_equal(d.rotation, camera.rotation)
        np.testing.assert_allclose(
            np.cross(d.center - camera.center, camera.rotation[2]), 0.0, atol=1e-12
        )  # on its axis
        depth = lambda cam: float(cam.rotation[2] @ centre[0] + cam.translation[2])  # noqa: E731
        assert depth(d) == pytest.approx(2.5 * depth(camera))
        span = lambda cam: np.linalg.norm(np.diff(cam.project(centre + [[0, 0, -0.4], [0, 0, 0.4]]), axis=0))  # noqa: E731
        assert span(d) == pytest.approx(span(camera) / 2.5, rel=0.05)  # a body 2.5 times smaller


def test_synth_options_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "rec"
    args = ["synth", "--model", str(MODEL), "--calib", str(_rig(tmp_path)), "--motion", "athletic", "--out", str(out)]
    extra = ["--frames", "2", "--fps", "8", "--texture", "mixed", "--body", "capsules", "--table", "a", "--quiet"]
    staging = ["--zoom", "1.2", "--distance", "1.5", "--motion-blur", "3", "--backdrop", "room", "--face"]
    assert main(args + extra + staging + ["--no-init"]) == 0
    assert (out / "truth_init.toml").is_file() and not (out / "init.toml").exists()
    written, given = load_calibration(out / "calibration.toml"), load_calibration(tmp_path / "rig.toml")
    assert [c.matrix[0, 0] for c in written] == pytest.approx([1.2 * 140.0, 1.2 * 140.0])
    depth = [float(c.rotation[2] @ synth.SCENE_CENTRE + c.translation[2]) for c in (*written, *given)]
    assert depth[:2] == pytest.approx([1.5 * d for d in depth[2:]])
    with np.load(out / "truth.npz") as truth:
        assert truth["joints"].shape == (2, 15, 3)
    assert main(args + ["--frames", "3", "--quiet"]) == 2  # a recording is there: synth's own, yet kept
    assert capsys.readouterr().err.strip().endswith("write the render to another folder, or add --force to replace it")
    assert main(args + ["--frames", "3", "--time-offsets", "b=0.01, a=-0.02", "--force", "--quiet"]) == 0
    with np.load(out / "truth.npz") as truth:
        assert truth["joints"].shape == (3, 15, 3)  # replaced
    with pytest.raises(SystemExit):  # argparse's usage error, exit code 2
        main(args + ["--time-offsets", "b=soon"])
    assert "CAMERA=SECONDS" in capsys.readouterr().err
    assert main(args + ["--frames", "1", "--table", "cam9", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cam9" in err[0]
