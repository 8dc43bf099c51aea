"""`tracker live`: tracking cameras as they capture, fed here by video files replayed in real time.

The runs take as long as their videos (0.1 s for the tiny recording, 2.7 s for the demo); how
many frames the tracker keeps up with depends on the machine, so the assertions are about what
must hold whatever it is: counters that agree, a recording that replays to the same poses, the
messages of a dropped camera.
"""

import _thread
import argparse
import os
import re
import signal
import tomllib
from pathlib import Path

import numpy as np
import pytest

from tracker.apps.live import Recorder, assign_cameras, track_live
from tracker.camera import load_calibration
from tracker.cli import build_parser, main
from tracker.commands.live import run
from tracker.errors import TrackerInputError
from tracker.io.capture import Capture, CaptureError, ReplayClock, ReplaySource
from tracker.io.posefile import load_pose_file
from tracker.io.poses import load_poses
from tracker.io.recording import open_recording
from tracker.model import load_model
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def _args(rec: Path, cameras: list[str], *extra: str) -> argparse.Namespace:
    options = [item for camera in cameras for item in ("--camera", camera)]
    return build_parser().parse_args(
        ["live"]
        + options
        + [
            "--calib",
            str(rec / "calibration.toml"),
            "--model",
            str(rec / "model.toml"),
            "--init",
            str(rec / "init.toml"),
            "--keypoints",  # edges only, as `tracker track --keypoints off` replays it; a later one overrides
            "off",
            *extra,
        ]
    )


def _replayed(recording: Path, out: Path, *extra: str) -> dict:
    """poses.npz of `tracker track` on a recording folder, with the live run's cues (edges only), frame by frame as
    live tracks (``--smooth none``)."""
    args = ["track", str(recording), "--out", str(out), "--quiet", "--keypoints", "off", "--smooth", "none", *extra]
    assert main(args) == 0
    return load_poses(out / "poses.npz")


def _assert_same(live: dict, replay: dict, frames: int) -> None:
    for key in ("frame", "time", "poses", "joints", "status", "residual"):
        np.testing.assert_array_equal(live[key][:frames], replay[key][:frames], err_msg=key)


def _consistent(counts, frames: int) -> None:
    assert [p + u for p, u in zip(counts.paired, counts.unpaired)] == list(counts.captured)
    assert counts.sets == counts.taken + counts.stale
    assert counts.taken == frames


class Failing:
    """Wraps a source; after ``after`` frames it raises (a camera unplugged), or once calls ``then``."""

    def __init__(self, source, after: int, then=None):
        self.source, self.after, self.then, self.delivered = source, after, then, 0
        self.name, self.size, self.fps = source.name, source.size, source.fps

    def read(self):
        if self.delivered == self.after:
            if self.then is None:
                raise CaptureError("was unplugged")
            self.then()
        self.delivered += 1
        return self.source.read()

    def close(self):
        self.source.close()


def _live(rec: Path, tmp_path: Path, wrap=lambda camera, source: source, record: bool = True):
    """track_live over the videos of ``rec`` replayed as cameras (``wrap`` may replace a source); with a recorder."""
    cameras = load_calibration(rec / "calibration.toml")
    model = load_model(rec / "model.toml")
    init = load_pose_file(rec / "init.toml", model)
    clock = ReplayClock()
    sources = [wrap(camera.name, ReplaySource(rec / f"{camera.name}.avi", clock)) for camera in cameras]
    capture = Capture(sources, [camera.name for camera in cameras])
    copies = {name: rec / name for name in ("calibration.toml", "model.toml", "init.toml")}
    with Recorder(tmp_path / "rec", cameras, 60.0, copies) as recorder:
        tracker = Tracker(model, cameras, init, Settings())
        return track_live(capture, tracker, cameras=cameras, out=tmp_path / "out", recorder=recorder)


def test_a_live_run_records_what_it_tracked_and_tracker_track_replays_it(tiny_recording, tmp_path, capsys):
    """The recording holds what the live run tracked, and `tracker track` replays it to the same poses: its
    init.toml is the first pose given (here a pose file of another recording's frame 150) as that of its frame 0."""
    out, record = tmp_path / "out", tmp_path / "rec"
    given = tmp_path / "given.toml"
    given.write_text((tiny_recording / "init.toml").read_text().replace("frame = 0", "frame = 150"))
    cameras = [str(tiny_recording / "cam0.avi"), str(tiny_recording / "cam1.avi")]
    extra = ("--out", str(out), "--record", str(record), "--iterations", "4", "--init", str(given))
    assert run(_args(tiny_recording, cameras, *extra)) == 0
    paired, taken = (int(n) for n in re.findall(r"sets: (\d+) paired, (\d+) tracked", capsys.readouterr().out)[0])
    live = load_poses(out / "poses.npz")
    frames = len(live["frame"])
    assert frames >= 1 and taken == frames
    assert paired == open_recording(tiny_recording).frame_count  # replayed files share one clock: every frame pairs
    np.testing.assert_array_equal(live["frame"], np.arange(frames))
    recording = open_recording(record)
    assert recording.frame_count == frames and [camera.name for camera in recording.cameras] == ["cam0", "cam1"]
    for name in ("calibration.toml", "model.toml"):
        assert (record / name).read_bytes() == (tiny_recording / name).read_bytes()
    first, held = tomllib.loads((record / "init.toml").read_text()), tomllib.loads(given.read_text())
    assert first == held | {"frame": 0} and held["frame"] == 150
    rows = (record / "timestamps.csv").read_text().splitlines()
    assert rows[0] == "frame,cam0,cam1" and len(rows) == frames + 1
    # the time of every row is its capture time, whatever was dropped between rows
    captured = np.array([float(row.split(",")[1]) for row in rows[1:]])
    np.testing.assert_array_equal(live["time"], captured)
    times = np.array([[float(value) for value in row.split(",")] for row in rows[1:]])
    np.testing.assert_array_equal(times[:, 0], np.arange(frames))
    assert np.all(np.diff(times[:, 1]) > 0) and np.array_equal(times[:, 1], times[:, 2])
    _assert_same(live, _replayed(record, tmp_path / "replay", "--iterations", "4"), frames)


def test_a_dropped_camera_ends_the_recording_and_tracking_goes_on(tmp_path, capsys):
    summary = _live(DEMO, tmp_path, wrap=lambda name, source: Failing(source, 40) if name == "cam2" else source)
    err = capsys.readouterr().err
    assert "camera cam2 (" in err and "was unplugged; going on with cam0, cam1" in err
    assert "tracking goes on with cam0, cam1 from frame" in err and "the recording ends at its" in err
    status = re.findall(r"live (\d+) s: tracking ([\d.]+) fps \| capture cam0 ([\d.]+), cam1 ([\d.]+)", err)
    assert status and int(status[0][0]) == 1  # the status line, once a second (the demo plays 2.7 s)
    assert all(float(rate) > 0 for rate in status[0][1:])
    counts = summary.counts
    assert counts.live == ("cam0", "cam1") and counts.captured[2] == 40
    _consistent(counts, summary.frames)
    assert 1 <= summary.recorded <= 40 and summary.frames > summary.recorded
    live = load_poses(tmp_path / "out" / "poses.npz")
    assert len(live["frame"]) == summary.frames
    assert open_recording(tmp_path / "rec").frame_count == summary.recorded
    _assert_same(live, _replayed(tmp_path / "rec", tmp_path / "replay"), summary.recorded)


def test_when_no_camera_is_left_the_run_stops_and_keeps_its_output(tiny_recording, tmp_path, capsys):
    summary = _live(tiny_recording, tmp_path, wrap=lambda name, source: Failing(source, 3))
    assert "no camera is left" in capsys.readouterr().err
    assert summary.counts.live == ()
    _consistent(summary.counts, summary.frames)
    assert len(load_poses(tmp_path / "out" / "poses.npz")["frame"]) == summary.frames


def test_ctrl_c_stops_after_the_frame_in_hand_with_every_output_agreeing(tmp_path):
    def interrupt(name, source):  # cam0 presses Ctrl-C (as a signal to the main thread) at its 21st frame
        return Failing(source, 20, then=_thread.interrupt_main) if name == "cam0" else source

    summary = _live(DEMO, tmp_path, wrap=interrupt)
    assert summary.stopped_by == signal.SIGINT and 1 <= summary.frames < 160
    _consistent(summary.counts, summary.frames)
    live = load_poses(tmp_path / "out" / "poses.npz")
    assert len(live["frame"]) == summary.recorded == summary.frames
    assert open_recording(tmp_path / "rec").frame_count == summary.frames
    assert len((tmp_path / "rec" / "timestamps.csv").read_text().splitlines()) == summary.frames + 1
    _assert_same(live, _replayed(tmp_path / "rec", tmp_path / "replay"), summary.frames)


def test_sigterm_stops_after_the_frame_in_hand_as_ctrl_c_does(tiny_recording, tmp_path):
    """SIGTERM (a service manager stopping the run) at cam0's third frame: the run ends after the frame in hand, says
    it was SIGTERM, and every output holds the same frames; the handler the process had is back."""

    def stop() -> None:
        assert signal.getsignal(signal.SIGTERM) not in (signal.SIG_DFL, signal.SIG_IGN), "it would end the tests"
        os.kill(os.getpid(), signal.SIGTERM)

    def stopping(name, source):
        return Failing(source, 2, then=stop) if name == "cam0" else source

    before = signal.getsignal(signal.SIGTERM)
    summary = _live(tiny_recording, tmp_path, wrap=stopping)
    assert summary.stopped_by == signal.SIGTERM and signal.getsignal(signal.SIGTERM) is before
    _consistent(summary.counts, summary.frames)
    assert len(load_poses(tmp_path / "out" / "poses.npz")["frame"]) == summary.recorded == summary.frames
    assert open_recording(tmp_path / "rec").frame_count == summary.frames


def test_a_missing_device_is_a_one_line_error(tiny_recording, tmp_path):
    with pytest.raises(TrackerInputError) as error:
        run(_args(tiny_recording, ["/dev/video99", str(tiny_recording / "cam1.avi")], "--out", str(tmp_path)))
    assert str(error.value).startswith("/dev/video99: no such video device") and "\n" not in str(error.value)


def test_a_camera_must_give_its_calibrated_size(tiny_recording, tmp_path):
    with pytest.raises(TrackerInputError, match="gives 640x480 images but camera 'cam0' .* is calibrated at 320x240"):
        run(_args(tiny_recording, [str(DEMO / "cam0.avi")], "--out", str(tmp_path)))


def test_cameras_are_matched_to_the_calibration_by_order_or_by_name(tiny_recording):
    path = tiny_recording / "calibration.toml"
    calibration = load_calibration(path)

    def matched(specs):
        return [(camera.name, device) for camera, device in assign_cameras(specs, calibration, path)]

    assert matched(["/dev/video0"]) == [("cam0", "/dev/video0")]
    assert matched(["/dev/video0", "/dev/video2"]) == [("cam0", "/dev/video0"), ("cam1", "/dev/video2")]
    # by name, tracked in calibration order whatever the order given
    assert matched(["cam1=/dev/video2", "cam0=/dev/video4"]) == [("cam0", "/dev/video4"), ("cam1", "/dev/video2")]
    assert matched(["cam1=/dev/video2"]) == [("cam1", "/dev/video2")]
    for specs, message in (
        (["a", "b", "c"], "has 2 camera"),
        (["cam9=/dev/video0"], "has no camera 'cam9'"),
        (["cam0=/dev/video0", "/dev/video2"], "name every camera"),
        (["/dev/video0", "/dev/video0"], "device '/dev/video0' is given twice"),
        (["cam0=/dev/video0", "cam0=/dev/video2"], "camera 'cam0' is given twice"),
        (["cam0="], "give the device"),
    ):
        with pytest.raises(TrackerInputError, match=message):
            matched(specs)


def test_size_is_width_x_height(tiny_recording):
    assert _args(tiny_recording, ["/dev/video0"], "--size", "640x480").size == (640, 480)
    with pytest.raises(SystemExit):
        _args(tiny_recording, ["/dev/video0"], "--size", "640")


def test_a_recording_goes_to_a_new_folder(tiny_recording, tmp_path):
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "notes.txt").write_text("keep me")
    with pytest.raises(TrackerInputError, match="already exists"):
        Recorder(tmp_path / "rec", load_calibration(tiny_recording / "calibration.toml"), 60.0, {})
    assert (tmp_path / "rec" / "notes.txt").read_text() == "keep me"


def test_a_live_run_can_be_watched_in_the_viewer(tiny_recording, tmp_path, capsys):
    cameras = [str(tiny_recording / "cam0.avi"), str(tiny_recording / "cam1.avi")]
    assert run(_args(tiny_recording, cameras, "--out", str(tmp_path), "--view", "--port", "0")) == 0
    assert "viewer: http://127.0.0.1:" in capsys.readouterr().err
    assert len(load_poses(tmp_path / "poses.npz")["frame"]) >= 1


def test_a_full_video_ends_the_recording_and_tracking_goes_on(tiny_recording, tmp_path, capsys, monkeypatch):
    from tracker.io.avi import MjpegAviWriter

    monkeypatch.setattr(MjpegAviWriter, "_MAX_BYTES", 20_000)  # room for a frame or two of 320x240
    summary = _live(tiny_recording, tmp_path)
    assert "its videos reached the 1 GiB an AVI file can hold; tracking goes on" in capsys.readouterr().err
    assert summary.recorded < summary.frames
    rows = (tmp_path / "rec" / "timestamps.csv").read_text().splitlines()
    assert len(rows) == summary.recorded + 1  # videos and timestamps agree: the frame that did not fit is in neither


def test_the_keypoint_detector_runs_beside_the_live_tracker(tmp_path, capsys):
    """The demo replayed live with the detector offered every 2nd frame set: it takes those it is free for,
    its detections are fused (each once, moved to the frame it arrives in), and the body is held.  The demo's
    60 fps are played at 15, so that a slow machine with the detector beside the tracker has time for every
    frame, and what is tested is the fusion, not how many frames the machine skips."""
    cameras = ["cam0", "cam1", "cam2"]
    files = [str(DEMO / f"{name}.avi") for name in cameras]
    out = tmp_path / "out"
    assert run(_args(DEMO, files, "--out", str(out), "--keypoints", "2", "--fps", "15")) == 0
    printed = capsys.readouterr().out
    fused, taken, offered = (
        int(word)
        for word in re.findall(r"keypoints: (\d+) detections fused; the detector took (\d+) of the (\d+)", printed)[0]
    )
    assert 0 < fused <= taken <= offered
    live = load_poses(out / "poses.npz")
    truth = load_poses(DEMO / "truth.npz")
    shown = np.clip(np.rint(live["time"] * 15.0).astype(int), 0, 159)  # the demo's frame at each capture time
    error = np.linalg.norm(live["joints"] - truth["joints"][shown], axis=2).mean(axis=1)
    assert np.median(error) < 0.02 and not (live["status"] == 2).any()


def test_late_landmarks_move_with_the_tracked_body():
    from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
    from tracker.landmarks.live_detection import transferred

    recording = open_recording(DEMO)
    model = load_model(recording.model_path)
    truth = load_poses(DEMO / "truth.npz")
    component, point, _ = landmark_points(model, LANDMARKS)
    then, now = truth["poses"][10], truth["poses"][14]
    pixels = np.full((3, len(LANDMARKS), 2), np.nan)
    expected = pixels.copy()
    for k, camera in enumerate(recording.cameras):
        for j in np.flatnonzero(component >= 0):
            pixels[k, j] = camera.project(then[component[j], :3, 3]) + (3.0, -2.0)  # a misfit of (3, -2) px
            expected[k, j] = camera.project(now[component[j], :3, 3]) + (3.0, -2.0)
    moved = transferred(pixels, then, now, cameras=recording.cameras, component=component, point=point)
    np.testing.assert_allclose(moved, expected, atol=1e-9)
