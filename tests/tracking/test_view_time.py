"""A view's capture time from its edges (tracker.tracking.view_time): poses between tracked frames on the geodesic,
and the edges' distance against the true track least at each camera's true offset."""

import numpy as np
import pytest
from conftest import HUMAN, ROOT

from tracker.cli import main
from tracker.geometry.se3 import from_rotvec
from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.landmarks.time_offsets import resampled_least, rises
from tracker.model import load_model
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings
from tracker.tracking.view_time import edge_costs, poses_at


def test_poses_between_frames_follow_the_screw_through_them():
    """Brute force: a component screwing about a fixed axis (turning about it through a point and sliding along it,
    each at one rate), seen at whole frames, is between them where that screw motion puts it."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    through, origin, turn, slide = np.array([0.5, -0.2, 1.0]), np.array([0.1, 0.2, 0.3]), 0.6, 0.05  # rad, m a frame
    start = from_rotvec(np.array([0.2, 0.1, -0.3]), origin)

    def at(time):
        spun = from_rotvec(turn * time * axis)[:3, :3]
        pose = np.eye(4)
        pose[:3, :3] = spun @ start[:3, :3]
        pose[:3, 3] = through + spun @ (origin - through) + slide * time * axis
        return pose

    track = np.ascontiguousarray(np.stack([at(0.0), at(1.0), at(2.0)])[:, None])  # (3, 1, 4, 4)
    for time in (0.0, 0.25, 0.5, 1.0, 1.75, 2.0):
        np.testing.assert_allclose(poses_at(track, time)[0], at(time), atol=1e-12)


@pytest.fixture(scope="module")
def late_render(tmp_path_factory):
    """A render whose cam1 is captured 0.04 s (1.2 frames) late and cam2 0.025 s (0.75 frames) early."""
    rec = tmp_path_factory.mktemp("late") / "rec"
    args = ["synth", "--model", str(HUMAN), "--calib", str(ROOT / "calib" / "demo3.toml"), "--out", str(rec)]
    staging = ["--motion", "athletic", "--fps", "30", "--frames", "30", "--seed", "4", "--texture", "mixed"]
    assert main(args + staging + ["--backdrop", "room", "--time-offsets", "cam1=0.04,cam2=-0.025", "--quiet"]) == 0
    return rec


@pytest.mark.parametrize(("camera", "offset"), [("cam1", 0.04), ("cam2", -0.025)])
def test_the_edges_lie_nearest_the_true_track_at_the_cameras_offset(late_render, camera, offset):
    truth = np.ascontiguousarray(load_poses(late_render / "truth.npz")["poses"])
    alone = open_recording(late_render, [camera], paired=False)
    tracker = Tracker(
        load_model(late_render / "model.toml"), alone.cameras, truth[0], Settings().but(motion=dict(frame_rate=30.0))
    )
    shifts = round(offset * 30.0) + np.arange(-2.0, 2.0 + 1e-9, 0.25)
    table = edge_costs(tracker, frames(alone, 4, 26, prepare=tracker.smooth), truth, shifts=shifts)[:, :, 4:]
    assert table.shape == (len(shifts), 2, 22) and (table[:, 1] > 0).all()
    least, sigma = resampled_least(shifts, table, block=8)
    assert least == pytest.approx(offset * 30.0, abs=0.1)  # a tenth of a frame: 3 ms
    assert sigma < 0.1
    cost = table[:, 0].sum(axis=1) / table[:, 1].sum(axis=1)
    assert rises(cost, steps=4, ratio=1.1)  # a frame off, the edges lie 10 % further or more
    outside = edge_costs(tracker, frames(alone, 28, 30, prepare=tracker.smooth), truth, shifts=np.array([3.0]))
    assert outside.shape == (1, 2, 30) and not outside.any()  # beyond the track: nothing counted
