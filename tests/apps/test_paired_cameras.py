"""Cameras that are not frame-locked, end to end: a render whose cameras were captured late or early, tracked with
its offsets in sync.toml, comes out as well as the same render with every camera on time, and worse without them;
replayed live by cameras whose clocks carry their lateness, its views are paired by capture time."""

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import HUMAN

from tracker.apps.live import Recorder, track_live
from tracker.camera import load_calibration, look_at_camera, save_calibration
from tracker.cli import main
from tracker.evaluate import evaluate
from tracker.io.capture import Capture, ReplayClock, ReplaySource
from tracker.io.poses import load_poses
from tracker.io.recording import open_recording
from tracker.model import load_model
from tracker.synthetic.synth import Staging, synthesize
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings

FPS = 30.0
OFFSETS = (("cam1", 2 / FPS), ("cam2", -3 / FPS))  # whole frames: the pairing leaves nothing to carry


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> dict[str, Path]:
    """The same athletic motion seen by three 320x240 cameras, on time and with cam1 two frames late and cam2 three
    early (``offset``), and the latter again beside its true sync.toml (``synced``)."""
    folder = tmp_path_factory.mktemp("paired")
    rig = [
        look_at_camera("cam0", (0.5, -3.8, 1.4), (0.0, 0.0, 0.9), size=(320, 240), focal=260.0),
        look_at_camera("cam1", (3.6, 0.9, 1.6), (0.0, 0.0, 0.9), size=(320, 240), focal=260.0),
        look_at_camera("cam2", (-3.0, 2.2, 1.2), (0.0, 0.0, 0.9), size=(320, 240), focal=260.0),
    ]
    save_calibration(rig, folder / "rig.toml")
    render = dict(motion="athletic", frames=30, fps=FPS, seed=3, progress=False)
    synthesize(HUMAN, folder / "rig.toml", folder / "on_time", staging=Staging(texture="stripes"), **render)
    late = Staging(texture="stripes", time_offsets=OFFSETS)
    synthesize(HUMAN, folder / "rig.toml", folder / "offset", staging=late, **render)
    shutil.copytree(folder / "offset", folder / "synced")
    lines = "\n".join(f"{name} = {seconds!r}" for name, seconds in OFFSETS)
    (folder / "synced" / "sync.toml").write_text(f"[offsets]\n{lines}\n")
    return {name: folder / name for name in ("on_time", "offset", "synced")}


def _mpjpe(recording: Path, out: Path) -> float:
    assert main(["track", str(recording), "--out", str(out), "--keypoints", "off", "--quiet"]) == 0
    return evaluate(load_poses(out / "poses.npz"), load_poses(recording / "truth.npz")).mpjpe_mm


def test_views_paired_by_their_offsets_track_as_well_as_views_on_time(renders, tmp_path):
    on_time = _mpjpe(renders["on_time"], tmp_path / "on_time")
    synced = _mpjpe(renders["synced"], tmp_path / "synced")
    offset = _mpjpe(renders["offset"], tmp_path / "offset")
    # the first two and last three frames of a shifted camera repeat its first or last one: a little worse there
    assert synced < 1.3 * on_time + 5.0
    assert offset > 1.5 * synced


def test_caliscopes_capture_times_pair_the_views(renders, tmp_path):
    """The offset render beside a caliscope-style timestamps.csv (one row per camera and set, each time 3 ms of
    jitter off the camera's true capture time) and no sync.toml: each camera is read at its frame captured nearest
    cam0's, cam1's frame n - 2 and cam2's n + 3, and tracks as the render with its sync.toml does."""
    rec = tmp_path / "caliscope"
    shutil.copytree(renders["offset"], rec)
    rng = np.random.default_rng(5)
    late = dict(OFFSETS)
    rows = ["sync_index,cam_id,frame_index,frame_time"]
    for n in range(30):
        for k, name in enumerate(("cam0", "cam1", "cam2")):
            rows.append(f"{n},{k},{n},{10.0 + n / FPS + late.get(name, 0.0) + rng.uniform(-0.003, 0.003):.6f}")
    (rec / "timestamps.csv").write_text("\n".join(rows) + "\n")
    pairing = open_recording(rec).pairing
    frames = np.arange(30)
    np.testing.assert_array_equal(pairing.frames[3:27, 1], frames[3:27] - 2)
    np.testing.assert_array_equal(pairing.frames[3:27, 2], frames[3:27] + 3)
    assert np.abs(pairing.late[3:27]).max() < 0.007  # each view within its jitter of cam0's time
    synced = _mpjpe(renders["synced"], tmp_path / "synced")
    assert _mpjpe(rec, tmp_path / "out") < 1.3 * synced + 5.0
    times = load_poses(tmp_path / "out" / "poses.npz")["time"]
    np.testing.assert_allclose(np.diff(times), 1 / FPS, atol=0.007)  # cam0's capture times, written with the poses


class Late:
    """A replayed camera whose capture times are ``frames`` of its frame periods later than its frames' numbers
    say: its clock carries its lateness, as a free-running camera's does."""

    def __init__(self, source: ReplaySource, frames: float):
        self.source, self.delay = source, frames / source.fps
        self.name, self.size, self.fps = source.name, source.size, source.fps

    def read(self):
        delivered = self.source.read()
        return None if delivered is None else (delivered[0], delivered[1] + self.delay)

    def close(self):
        self.source.close()


def _video(path: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    images = []
    while (image := capture.read()[1]) is not None:
        images.append(image)
    return images


def _replayed(rec: Path, lateness: dict[str, float], start: np.ndarray, out: Path, recorder=None):
    """``rec`` replayed live at 15 fps (time for any machine) and tracked from the pose ``start``, each camera's
    clock that many frames late (``lateness``); the run's summary."""
    cameras = load_calibration(rec / "calibration.toml")
    clock = ReplayClock()
    sources = [Late(ReplaySource(rec / f"{c.name}.avi", clock, 15.0), lateness.get(c.name, 0.0)) for c in cameras]
    tracker = Tracker(load_model(rec / "model.toml"), cameras, start, Settings())
    capture = Capture(sources, [camera.name for camera in cameras])
    return track_live(capture, tracker, cameras=cameras, out=out, recorder=recorder)


def test_live_pairs_each_camera_by_its_capture_time(renders, tmp_path):
    """The offset render replayed live, each camera's clock carrying its offset: every recorded set holds cam0's
    frame n, cam1's n - 2 and cam2's n + 3, the frames captured together, and the tracking (from the true pose of the
    first set) is as good as the on-time render's replayed the same way, over the same frames."""
    rec = renders["offset"]
    shifts = dict(OFFSETS)
    cameras = load_calibration(rec / "calibration.toml")
    truth = load_poses(rec / "truth.npz")
    first = 2  # cam1 is 2 frames late: cam0's frames 0-1 have no partner
    copies = {name: rec / name for name in ("calibration.toml", "model.toml")}
    late = {name: seconds * FPS for name, seconds in shifts.items()}
    with Recorder(tmp_path / "rec", cameras, FPS, copies) as recorder:
        summary = _replayed(rec, late, truth["poses"][first], tmp_path / "out", recorder)
    rendered = {camera.name: _video(rec / f"{camera.name}.avi") for camera in cameras}
    recorded = {camera.name: _video(tmp_path / "rec" / f"{camera.name}.avi") for camera in cameras}
    numbers = {
        name: [next(n for n, image in enumerate(rendered[name]) if np.array_equal(image, shown)) for shown in images]
        for name, images in recorded.items()
    }
    assert summary.counts.paired == (27 - first,) * 3  # sets for cam0's frames 2..26 (cam2 is 3 early)
    assert len(numbers["cam0"]) == summary.recorded >= 1 and numbers["cam0"][0] >= first
    for name in ("cam1", "cam2"):
        np.testing.assert_array_equal(numbers[name], np.array(numbers["cam0"]) - round(shifts[name] * FPS))
    live = load_poses(tmp_path / "out" / "poses.npz")
    tracked = dict(live, frame=np.array(numbers["cam0"])[: len(live["frame"])])
    _replayed(renders["on_time"], {}, truth["poses"][0], tmp_path / "on_time")
    on_time = load_poses(tmp_path / "on_time" / "poses.npz")
    same = (on_time["frame"] >= tracked["frame"][0]) & (on_time["frame"] <= tracked["frame"][-1])
    locked = {"frame": on_time["frame"][same], "joint_names": on_time["joint_names"], "joints": on_time["joints"][same]}
    assert evaluate(tracked, truth).mpjpe_mm < 1.3 * evaluate(locked, truth).mpjpe_mm + 5.0
