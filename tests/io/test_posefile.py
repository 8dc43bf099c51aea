"""Pose TOML files (tracker.io.posefile): round trip, validation, projection onto the joints."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.posefile import load_pose_file, pose_frame, save_pose_file, starting_pose_file
from tracker.model import load_model, poses_from_rotations, rest_poses

HUMAN = Path(__file__).resolve().parents[2] / "models" / "human.toml"


@pytest.fixture(scope="module")
def human():
    return load_model(HUMAN)


def unit(rng):
    x = rng.normal(size=3)
    return x / np.linalg.norm(x)


def valid_poses(rng, model, max_angle=2.5):
    """Rest poses with random rotations, projected onto the joints by Model.coerce."""
    root = se3.from_rotvec(rng.uniform(0, max_angle) * unit(rng), rng.normal(size=3))
    rotations = np.array([se3.exp_so3(rng.uniform(0, max_angle) * unit(rng)) for _ in range(model.size)])
    rotations[0] = root[:3, :3]
    poses = poses_from_rotations(model, root[:3, 3], rotations)
    assert rest_poses(model, root).shape == poses.shape
    return model.coerce(poses)


def joint_errors(model, poses):
    """Origin-on-parent's-joint gap and, for hinges, how far the relative rotation moves the axis."""
    gap, axis_error = 0.0, 0.0
    for i in range(1, model.size):
        p = model.parent[i]
        expected = poses[p] @ model.rest[i]
        gap = max(gap, np.linalg.norm(poses[i][:3, 3] - expected[:3, 3]))
        if model.joint_type[i] == 2:  # hinge
            relative = expected[:3, :3].T @ poses[i][:3, :3]
            axis_error = max(axis_error, np.linalg.norm(relative @ model.axis[i] - model.axis[i]))
    return gap, axis_error


def test_round_trip(tmp_path, human):
    rng = np.random.default_rng(0)
    for trial in range(10):
        poses = valid_poses(rng, human)
        assert max(joint_errors(human, poses)) < 1e-12
        path = tmp_path / f"init{trial}.toml"
        save_pose_file(path, human, poses, frame=0)
        loaded = load_pose_file(path, human)
        np.testing.assert_allclose(loaded, poses, rtol=0, atol=1e-12)


def test_a_pose_file_says_its_frame(tmp_path, human):
    """The writer records the frame; a file without one (written before the key) is the pose at frame 0; a frame that
    is no frame number is a one-line error naming the file."""
    poses = valid_poses(np.random.default_rng(3), human)
    save_pose_file(tmp_path / "at150.toml", human, poses, frame=150)
    assert pose_frame(tmp_path / "at150.toml") == 150
    np.testing.assert_allclose(load_pose_file(tmp_path / "at150.toml", human), poses, rtol=0, atol=1e-12)
    assert pose_frame(write(tmp_path / "old.toml", ROOT)) == 0
    for written, read in (("-1", "-1"), ("1.5", "1.5"), ('"3"', "'3'"), ("true", "True")):
        path = write(tmp_path / "bad.toml", f"frame = {written}\n" + ROOT)
        with pytest.raises(TrackerInputError) as info:
            pose_frame(path)
        assert str(info.value) == (
            f"{path}: frame = {read} is not a frame number; write frame = N, the recording's frame the pose is of"
        )


def test_a_run_starts_from_a_pose_file_only_at_its_frame(tmp_path):
    """--init of another frame is refused in one line naming its frame and the fix; the recording's own init.toml of
    another frame is passed over with a warning when the run can find its first pose by itself, else refused; at its
    own frame either is used."""
    given, found = write(tmp_path / "given.toml", "frame = 150\n" + ROOT), write(tmp_path / "init.toml", ROOT)
    assert starting_pose_file(150, given, found) == given
    assert starting_pose_file(0, None, found) == found and starting_pose_file(0, None, None) is None
    with pytest.raises(TrackerInputError) as info:
        starting_pose_file(0, given, found)
    assert str(info.value) == (
        f"{given}: is the pose at frame 150, but the run starts at frame 0; pass --start 150, or --init with a pose "
        "at frame 0, or no --init to find the first pose by itself"
    )
    with pytest.warns(UserWarning) as caught:
        assert starting_pose_file(150, None, found) is None
    assert [str(warning.message) for warning in caught] == [
        f"ignoring {found}, the pose at frame 0: the run starts at frame 150, where it finds the first pose by itself"
    ]
    with pytest.raises(TrackerInputError) as info:
        starting_pose_file(150, None, found, by_itself=False)
    assert str(info.value) == (
        f"{found}: is the pose at frame 0 (it says no frame: add frame = 150 to it if it is the pose at frame 150), "
        "but the run starts at frame 150, where it cannot find the first pose by itself; pass --start 0, or --init "
        "with a pose at frame 150"
    )
    said = write(tmp_path / "said.toml", "frame = 0\n" + ROOT)
    with pytest.raises(TrackerInputError) as info:
        starting_pose_file(150, said, None)
    assert str(info.value).startswith(f"{said}: is the pose at frame 0, but the run starts at frame 150;")


def test_round_trip_of_rotations_near_pi(tmp_path, human):
    """Uniformly random rotations, so some relative rotations come close to pi."""
    rng = np.random.default_rng(1)
    for trial in range(10):
        poses = valid_poses(rng, human, max_angle=np.pi)
        path = tmp_path / f"init{trial}.toml"
        save_pose_file(path, human, poses, frame=0)
        np.testing.assert_allclose(load_pose_file(path, human), poses, rtol=0, atol=1e-12)


def toml_list(values):
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def write(path, text):
    path.write_text(text)
    return path


ROOT = "[pose.pelvis]\nrotation = [0.1, 0.2, 0.3]\ntranslation = [0.0, 0.0, 1.0]\n"


@pytest.mark.parametrize(
    "text",
    [
        ROOT + "[pose.tail]\nrotation = [0.0, 0.0, 0.0]\n",  # unknown component
        "[pose.pelvis]\nrotation = [0.1, 0.2, 0.3]\n",  # root without translation
        "[pose.torso]\nrotation = [0.1, 0.2, 0.3]\n",  # root missing altogether
        'title = "no poses"\n',
        "[pose.pelvis]\nrotation = [0.1, 0.2]\ntranslation = [0.0, 0.0, 1.0]\n",
        "[pose.pelvis]\nrotation = [0.1, 0.2, nan]\ntranslation = [0.0, 0.0, 1.0]\n",
        ROOT + '[pose.head]\nrotation = "up"\n',
        "[pose.pelvis\nrotation = [0.1, 0.2, 0.3]\n",  # not TOML
    ],
)
def test_bad_pose_file_names_the_file(tmp_path, human, text):
    path = write(tmp_path / "init.toml", text)
    with pytest.raises(TrackerInputError) as info:
        load_pose_file(path, human)
    assert str(path) in str(info.value)


def test_unknown_component_is_named(tmp_path, human):
    path = write(tmp_path / "init.toml", ROOT + "[pose.tail]\nrotation = [0.0, 0.0, 0.0]\n")
    with pytest.raises(TrackerInputError, match="tail"):
        load_pose_file(path, human)


def test_missing_pose_file(tmp_path, human):
    path = tmp_path / "missing" / "init.toml"
    with pytest.raises(TrackerInputError) as info:
        load_pose_file(path, human)
    assert str(path) in str(info.value)


def test_root_only_gives_the_rest_pose(tmp_path, human):
    poses = load_pose_file(write(tmp_path / "init.toml", ROOT), human)
    root = se3.from_rotvec(np.array([0.1, 0.2, 0.3]), [0.0, 0.0, 1.0])
    np.testing.assert_allclose(poses, rest_poses(human, root), atol=1e-14)


def test_hinge_rotation_off_its_axis_is_projected(tmp_path, human):
    rng = np.random.default_rng(2)
    i = human.index("forearm_l")
    p = human.parent[i]
    for _ in range(5):
        parent_w = rng.normal(scale=0.7, size=3)
        # world rotation of the forearm: the parent's, then a relative rotation off the hinge axis
        relative_w = rng.normal(scale=0.6, size=3)
        child = se3.exp_so3(parent_w) @ se3.exp_so3(relative_w)
        text = (
            ROOT
            + f"[pose.{human.names[p]}]\nrotation = {toml_list(parent_w)}\n"
            + f"[pose.forearm_l]\nrotation = {toml_list(se3.log_so3(child))}\n"
        )
        poses = load_pose_file(write(tmp_path / "init.toml", text), human)
        gap, axis_error = joint_errors(human, poses)
        assert gap < 1e-12 and axis_error < 1e-12
        # the hinge keeps the part of the relative rotation vector along its axis (eq. 24 with p = 0),
        # clamped to the elbow's limits
        d = human.axis[i]
        relative = (poses[p] @ human.rest[i])[:3, :3].T @ poses[i][:3, :3]
        angle = np.clip(relative_w @ d, human.lower[i], human.upper[i])
        np.testing.assert_allclose(se3.log_so3(relative), angle * d, atol=1e-12)
        # the parent (a ball joint) and everything else keep the file's rotations
        np.testing.assert_allclose(poses[p][:3, :3], se3.exp_so3(parent_w), atol=1e-12)


def test_child_translation_off_its_joint_warns_and_is_ignored(tmp_path, human):
    text = ROOT + "[pose.head]\nrotation = [0.0, 0.3, 0.0]\ntranslation = [5.0, 5.0, 5.0]\n"
    with pytest.warns(UserWarning, match="head"):
        poses = load_pose_file(write(tmp_path / "init.toml", text), human)
    assert max(joint_errors(human, poses)) < 1e-12
    # a translation that agrees with the joint does not warn
    text = ROOT + f"[pose.torso]\ntranslation = {toml_list(poses[human.index('torso')][:3, 3])}\n"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_pose_file(write(tmp_path / "init2.toml", text), human)
