"""A recorded folder's track judged with the frames after each one (tracker.apps.smoothing, ``tracker track
--smooth``): end to end on a render with truth, what a stop during the backward pass leaves, and where the fused
track's motion restarts."""

import contextlib
import io
import signal

import numpy as np
import pytest
from conftest import stopping_after

from tracker.apps.smoothing import JUDGED_OVER, Track, _fused, smoothing_input, taken
from tracker.cli import main
from tracker.evaluate import evaluate
from tracker.geometry import se3
from tracker.io.posefile import save_pose_file
from tracker.io.poses import load_poses
from tracker.model import load_model
from tracker.status import LOST, RESEEDED, TRACKED
from tracker.tracking.frame_loop import FrameResult


@pytest.fixture(scope="module")
def leg_off(tiny_recording, tmp_path_factory):
    """tiny_recording's true first pose with the right thigh turned 0.4 rad off: the forward track drags the leg for
    frames before the edges bring it back."""
    truth = load_poses(tiny_recording / "truth.npz")
    model = load_model(tiny_recording / "model.toml")
    poses = truth["poses"][0].copy()
    thigh = model.index("thigh_r")
    poses[thigh] = poses[thigh] @ se3.exp(np.array([0.0, 0.0, 0.0, 0.4, 0.0, 0.0]))
    path = tmp_path_factory.mktemp("leg_off") / "init.toml"
    save_pose_file(path, model, model.coerce(poses), frame=0)
    return path


def _tracked(recording, init, out, *extra) -> dict:
    with contextlib.redirect_stdout(io.StringIO()):
        args = ["track", str(recording), "--out", str(out), "--quiet", "--keypoints", "off", "--init", str(init)]
        assert main([*args, *extra]) == 0
    return load_poses(out / "poses.npz")


def test_the_frames_after_each_one_mend_a_track_that_started_off(tiny_recording, leg_off, tmp_path):
    """From a first pose with a leg off (edges alone), the forward track holds the leg off for frames; tracked back
    from the last frame, where the forward track had it right, the leg is right throughout: both-ways lies nearer
    the truth than the forward track by a third or more, and the smoother alone is no worse than it.  The files
    are of one format, frame for frame, and every joint holds."""
    truth = load_poses(tiny_recording / "truth.npz")
    forward = _tracked(tiny_recording, leg_off, tmp_path / "none", "--smooth", "none")
    smoothed = _tracked(tiny_recording, leg_off, tmp_path / "rts", "--smooth", "rts")
    both = _tracked(tiny_recording, leg_off, tmp_path / "both", "--smooth", "both-ways")
    error = {name: evaluate(poses, truth).mpjpe_mm for name, poses in (("none", forward), ("rts", smoothed))}
    error["both-ways"] = evaluate(both, truth).mpjpe_mm
    assert error["both-ways"] < 0.67 * error["none"]
    assert error["rts"] <= error["none"]
    model = load_model(tiny_recording / "model.toml")
    for poses in (smoothed, both):
        assert sorted(poses) == sorted(forward)
        for key in ("frame", "time", "component_names", "joint_names"):
            np.testing.assert_array_equal(poses[key], forward[key])
        assert max(np.abs(model.coerce(row) - row).max() for row in poses["poses"]) < 1e-9


def test_a_stop_while_tracking_back_keeps_the_forward_track(tiny_recording, leg_off, tmp_path, monkeypatch, capsys):
    """Ctrl-C while the recording is tracked back from its last frame: exit 130, and poses.npz is the forward track,
    every frame of it, as ``--smooth none`` writes it."""
    forward = _tracked(tiny_recording, leg_off, tmp_path / "none", "--smooth", "none")
    monkeypatch.setattr(
        "tracker.commands.options.bar", stopping_after(3, signal.SIGINT, "tracking back from the last frame")
    )
    out = tmp_path / "both"
    args = ["track", str(tiny_recording), "--out", str(out), "--quiet", "--keypoints", "off", "--init", str(leg_off)]
    assert main([*args, "--smooth", "both-ways"]) == 130
    assert f"wrote {out / 'poses.npz'} (6 frames)" in capsys.readouterr().out
    stopped = load_poses(out / "poses.npz")
    for key in ("frame", "poses", "joints", "status", "residual"):
        np.testing.assert_array_equal(stopped[key], forward[key], err_msg=key)


def test_live_tracks_frame_by_frame():
    """`tracker live` has no frames after the one it tracks: --smooth is not among its options."""
    with contextlib.redirect_stderr(io.StringIO()), pytest.raises(SystemExit) as stopped:
        main(["live", "--cameras", "a.mp4", "--calib", "c.toml", "--smooth", "rts"])
    assert stopped.value.code == 2


def _result(value: float, status: int = TRACKED) -> FrameResult:
    return FrameResult(np.full((1, 4, 4), value), status, 0.0, 1.0, 10, np.zeros(1, np.int8))


def test_the_fused_track_restarts_where_the_track_it_took_was_seeded_again():
    """Five frames: the forward track re-seeded at frame 1 and 4, the backward one (tracked last to first) at frame 2.
    Frames 2 and 3 take the backward poses: the fused track restarts at frame 1 (the forward track's re-seed, frame 0
    the forward's too) and at frame 3 (the backward track's frame 3 was tracked before its re-seed at frame 2), not at
    frame 4 (the forward re-seed, but frame 3 is the backward track's)."""
    forward = Track(
        frame=np.arange(5),
        poses=np.zeros((5, 1, 4, 4)),
        status=np.array([TRACKED, RESEEDED, TRACKED, TRACKED, RESEEDED]),
        residual=np.zeros(5),
        elapsed=np.ones(5),
        information=np.ones((5, 1, 2, 3, 3)),
    )
    backward = [_result(float(k), RESEEDED if k == 2 else TRACKED) for k in range(5)]
    taken = np.array([False, False, True, True, False])
    fused = _fused(forward, np.arange(5), backward, taken, np.arange(5) == 2, np.full(5, 0.5), False, 1.0)
    assert list(fused.starts) == [False, True, False, True, False]
    assert [row[0, 0, 0] for row in fused.track.poses] == [0.0, 0.0, 2.0, 3.0, 0.0]
    assert list(fused.track.status) == [TRACKED, RESEEDED, RESEEDED, TRACKED, RESEEDED]
    assert not fused.track.information[2:4].any() and fused.track.information[[0, 1, 4]].all()
    np.testing.assert_array_equal(fused.track.elapsed, np.full(5, 1.5))


def test_a_frame_not_measured_counts_as_its_nearest_measured_one_and_a_lost_one_for_nothing():
    """Frames 1 and 4 measured (information 1 and 4), frames 0, 2 and 3 not (re-seeds snapped outside the solve),
    frame 5 lost: the smoother weighs them 1, 1, 1, 4, 4 and 0."""
    information = np.zeros((6, 1, 2, 3, 3))
    information[1], information[4] = 1.0, 4.0
    status = np.array([RESEEDED, TRACKED, RESEEDED, TRACKED, TRACKED, LOST])
    track = Track(np.arange(6), np.zeros((6, 1, 4, 4)), status, np.zeros(6), np.zeros(6), information)
    weighed = smoothing_input(track)
    assert list(weighed[:, 0, 0, 0, 0]) == [1.0, 1.0, 1.0, 4.0, 4.0, 0.0]
    assert (weighed == weighed[:, :, :, :1, :1]).all()


def test_the_tracks_are_judged_over_the_frames_about_each_one():
    """Frames 1, 3 and 4 back the backward track by a hair (edges alone, no mask between detections) and frame 2, with
    the person's mask, backs the forward one clearly: over five frames the forward track keeps 0-4; frames 5 and 6
    agree (NaN) and keep it too; 7-9 back the backward track and take it."""
    assert JUDGED_OVER == 5
    difference = np.array([np.nan, 0.004, -0.06, 0.004, 0.004, np.nan, np.nan, 0.05, 0.05, 0.05])
    assert list(taken(difference)) == [False] * 7 + [True] * 3
