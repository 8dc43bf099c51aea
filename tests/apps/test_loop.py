"""The apps' frame loop (tracker.apps.loop): what it writes is what stepping a tracker by hand gives, a wrapped
keypoint source is fused, capture times reach the rows and the steps, and Ctrl-C keeps the frames done."""

import itertools

import numpy as np
import pytest

from tracker.apps.loop import track_frames
from tracker.io.posefile import load_pose_file
from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.model import joint_centres, load_model
from tracker.tracking.frame_loop import Tracker


@pytest.fixture
def tiny(tiny_recording):
    rec = open_recording(tiny_recording)
    model = load_model(rec.model_path)
    return rec, model, load_pose_file(rec.init_path, model)


def _smoothed(rec, tracker):
    return list(frames(rec, prepare=tracker.smooth))


def test_the_rows_are_those_of_a_tracker_stepped_by_hand(tiny, tmp_path):
    rec, model, init = tiny
    by_hand = Tracker(model, rec.cameras, init)
    expected = [by_hand.step(images, smoothed=True) for _, images in _smoothed(rec, by_hand)]
    tracker = Tracker(model, rec.cameras, init)
    seen = []
    run = track_frames(tracker, _smoothed(rec, tracker), tmp_path / "poses.npz", fps=rec.fps, each=seen.append)
    written = load_poses(tmp_path / "poses.npz")
    assert (run.frames, run.interrupted) == (len(expected), False) and run.seconds > run.writing > 0.0
    assert [frame.index for frame in seen] == list(range(len(expected)))
    assert written["poses"].tobytes() == np.stack([result.poses for result in expected]).tobytes()
    np.testing.assert_array_equal(written["joints"], joint_centres(written["poses"]))
    np.testing.assert_array_equal(written["status"], [result.status for result in expected])
    np.testing.assert_array_equal(written["residual"], [result.residual for result in expected])
    np.testing.assert_array_equal(written["elapsed"], [frame.spent for frame in seen])


def test_a_wrapped_keypoint_source_is_asked_for_every_frame_and_fused(tiny, tmp_path):
    """A source of landmarks at the true poses' joints, moved by 0.1 px of seeded noise as an ensemble test would:
    each frame asks for its own, and they pull the solve (the rows differ from the edges' alone)."""
    from tracker.landmarks.body_landmarks import cue_points, landmark_world

    rec, model, init = tiny
    truth = load_poses(rec.truth_path)["poses"]
    component, point = cue_points(model)
    rng = np.random.default_rng(7)
    asked = []

    def landmarks(index: int):
        asked.append(index)
        world = landmark_world(truth[index], component, point)
        pixels = np.stack([camera.project(world) for camera in rec.cameras])
        return pixels + rng.normal(0.0, 0.1, pixels.shape), np.where(np.isfinite(pixels[..., 0]), 1.0, 0.0)

    tracker = Tracker(model, rec.cameras, init)
    track_frames(tracker, _smoothed(rec, tracker), tmp_path / "cue.npz", fps=rec.fps, keypoints=landmarks)
    plain = Tracker(model, rec.cameras, init)
    track_frames(plain, _smoothed(rec, plain), tmp_path / "edges.npz", fps=rec.fps)
    assert asked == list(range(rec.frame_count))
    assert not np.array_equal(load_poses(tmp_path / "cue.npz")["poses"], load_poses(tmp_path / "edges.npz")["poses"])


def test_capture_times_reach_the_rows_and_the_steps(tiny, tmp_path, monkeypatch):
    rec, model, init = tiny
    at = {index: 0.5 + 0.04 * index**2 for index in range(rec.frame_count)}  # uneven steps, as a live capture's
    steps = []
    step = Tracker.step

    def timed(self, images, *, smoothed=False, dt=None, keypoints=None, late=None):
        steps.append(dt)
        return step(self, images, smoothed=smoothed, dt=dt, keypoints=keypoints, late=late)

    monkeypatch.setattr(Tracker, "step", timed)
    tracker = Tracker(model, rec.cameras, init)
    track_frames(tracker, _smoothed(rec, tracker), tmp_path / "poses.npz", fps=rec.fps, times=at.__getitem__)
    np.testing.assert_array_equal(load_poses(tmp_path / "poses.npz")["time"], list(at.values()))
    assert steps[0] is None
    np.testing.assert_allclose(steps[1:], np.diff(list(at.values())))


def test_ctrl_c_ends_the_loop_with_the_frames_done_written(tiny, tmp_path):
    rec, model, init = tiny
    tracker = Tracker(model, rec.cameras, init)

    def interrupted():
        yield from itertools.islice(_smoothed(rec, tracker), 3)
        raise KeyboardInterrupt

    run = track_frames(tracker, interrupted(), tmp_path / "poses.npz", fps=rec.fps)
    assert (run.frames, run.interrupted) == (3, True)
    np.testing.assert_array_equal(load_poses(tmp_path / "poses.npz")["frame"], [0, 1, 2])


def test_retarget_picks_the_tracker_of_each_frame(tiny, tmp_path):
    """A camera dropped after two frames: the loop goes on with the tracker the hook rebuilt, in that camera alone."""
    rec, model, init = tiny
    tracker = Tracker(model, rec.cameras, init)
    read = _smoothed(rec, tracker)
    used = []

    def one_camera_late(current: Tracker) -> Tracker:
        if len(used) == 2:
            current = current.with_cameras(rec.cameras[:1])
        used.append(current)
        return current

    items = [(index, images if index < 2 else images[:1]) for index, images in read]
    run = track_frames(tracker, items, tmp_path / "poses.npz", fps=rec.fps, retarget=one_camera_late)
    assert run.frames == rec.frame_count and used[0] is used[1] is tracker
    assert all(len(later.rig.names) == 1 for later in used[2:]) and used[2] is used[-1]


def test_rows_tracked_before_are_written_first_and_not_counted(tiny, tmp_path):
    """The frames tracked back from a first pose (rows of a poses.npz, in frame order) lead the file, its times
    counted from the first of them; the loop counts only the frames it tracked."""
    rec, model, init = tiny
    tracker = Tracker(model, rec.cameras, init)
    read = _smoothed(rec, tracker)
    track_frames(Tracker(model, rec.cameras, init), read[:2], tmp_path / "back.npz", fps=rec.fps)
    before = load_poses(tmp_path / "back.npz")
    run = track_frames(tracker, read[2:], tmp_path / "poses.npz", fps=rec.fps, before=before)
    written = load_poses(tmp_path / "poses.npz")
    assert run.frames == rec.frame_count - 2
    np.testing.assert_array_equal(written["frame"], np.arange(rec.frame_count))
    assert written["poses"][:2].tobytes() == before["poses"].tobytes()
    np.testing.assert_array_equal(written["status"][:2], before["status"])
    np.testing.assert_allclose(written["time"], np.arange(rec.frame_count) / rec.fps)
    at = {index: 0.5 + 0.04 * index**2 for index in range(rec.frame_count)}  # a live capture's times, carried
    timed = dict(before, time=np.array([at[index] for index in before["frame"]]))
    again = Tracker(model, rec.cameras, init)
    track_frames(again, read[2:], tmp_path / "timed.npz", fps=rec.fps, before=timed, times=at.__getitem__)
    np.testing.assert_array_equal(load_poses(tmp_path / "timed.npz")["time"], list(at.values()))
