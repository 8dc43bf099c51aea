import numpy as np
import viser.transforms as vtf

from tracker.cli import main
from tracker.geometry import se3
from tracker.io.posefile import load_pose_file, pose_frame
from tracker.io.recording import open_recording
from tracker.model import joint_centres, load_model
from tracker.viewer.placement import Placement, in_view, subtree
from tracker.viewer.scene import Scene


def test_subtree_of_a_breadth_first_tree():
    parent = np.array([-1, 0, 0, 1, 1, 2, 3])
    assert list(subtree(parent, 1)) == [1, 3, 4, 6]
    assert list(subtree(parent, 0)) == list(range(7))
    assert list(subtree(parent, 6)) == [6]


def test_in_view_finds_where_the_cameras_look(tiny_recording):
    cameras = open_recording(tiny_recording).cameras  # both look at (0, 0, 0.9)
    pose = in_view(cameras, height=1.0)
    np.testing.assert_allclose(pose[0:3, 3], [0.0, 0.0, 1.0], atol=1e-6)


def _drag(placement, i, rotation=None, position=None):
    """What a browser drag does: the gizmo's pose changes, then its update callback runs."""
    gizmo = placement.gizmos[i]
    if rotation is not None:
        gizmo.wxyz = vtf.SO3.from_matrix(rotation @ placement.poses[i, 0:3, 0:3]).wxyz
    if position is not None:
        gizmo.position = position
    placement.moved(i)


def test_gizmos_move_subtrees_snap_to_the_images_and_save_an_init_that_tracks(server, tiny_recording, tmp_path):
    rec = open_recording(tiny_recording)
    model = load_model(rec.model_path)
    truth = load_pose_file(rec.init_path, model)
    out = tmp_path / "init.toml"
    placement = Placement(Scene(server, model, rec.cameras), rec, model, truth, out)

    arm = model.index("upperarm_l")
    hand = model.index("hand_l")
    before = placement.poses.copy()
    turn = se3.exp_so3(np.array([0.0, 0.4, 0.0]))
    _drag(placement, arm, rotation=turn)
    moved = placement.poses
    np.testing.assert_allclose(moved[arm, 0:3, 3], before[arm, 0:3, 3], atol=1e-9)  # turned about its joint
    assert np.linalg.norm(moved[hand, 0:3, 3] - before[hand, 0:3, 3]) > 0.1  # the hand came along
    np.testing.assert_allclose(moved[0], before[0])  # the rest of the body stayed
    np.testing.assert_allclose(model.coerce(moved), moved, atol=1e-9)  # joints exact
    np.testing.assert_allclose(placement.gizmos[hand].position, moved[hand, 0:3, 3])

    # a coarse start: the whole body 6 cm off and the arm turned; snapping pulls it onto the images
    _drag(placement, arm, rotation=turn.T)
    _drag(placement, 0, position=placement.poses[0, 0:3, 3] + np.array([0.06, -0.03, 0.0]))
    error_before = np.linalg.norm(joint_centres(placement.poses) - joint_centres(truth), axis=1).mean()
    placement.snap()
    error_after = np.linalg.norm(joint_centres(placement.poses) - joint_centres(truth), axis=1).mean()
    assert error_before > 0.05 and error_after < 0.015
    assert "Snapped" in placement.message.content

    placement.save()
    assert placement.saved.is_set() and out.is_file() and pose_frame(out) == 0
    np.testing.assert_allclose(load_pose_file(out, model), placement.poses, atol=1e-9)
    assert main(["track", str(tiny_recording), "--init", str(out), "--out", str(tmp_path / "run"), "--quiet"]) == 0
    placement.frame = 2  # placed in frame 2 (tracker init --start 2): the file says so
    placement.save()
    assert pose_frame(out) == 2
