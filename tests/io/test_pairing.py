"""Cameras' frames paired by time (tracker.io.pairing): hand-worked offsets, capture times against a brute-force
nearest search, a camera that dropped a frame, and a recording read with its sync.toml or timestamps.csv."""

import shutil

import numpy as np
import pytest

from tracker.io.pairing import by_offsets, by_times
from tracker.io.readers import grey_frames
from tracker.io.recording import camera_frames, capture_times, frames, open_recording


def test_offsets_pair_whole_frames_and_leave_the_rest_late():
    # 30 fps: cam1 captured 0.1 s (3 frames) late, cam2 1.55 frames early
    pairing = by_offsets(np.array([0.0, 0.1, -0.0517]), count=8, fps=30.0)
    np.testing.assert_array_equal(pairing.frames[:, 0], np.arange(8))
    np.testing.assert_array_equal(pairing.frames[:, 1], [0, 0, 0, 0, 1, 2, 3, 4])  # its frame n - 3
    np.testing.assert_array_equal(pairing.frames[:, 2], [2, 3, 4, 5, 6, 7, 7, 7])  # its frame n + 2
    # what is left: camera k's frame m is captured at m / 30 + offset, frame n is at n / 30
    expected = (pairing.frames - np.arange(8)[:, None]) / 30.0 + np.array([0.0, 0.1, -0.0517])
    np.testing.assert_allclose(pairing.late, expected, atol=1e-12)
    assert np.abs(pairing.late[3:6]).max() <= 0.5 / 30 + 1e-12  # within half a frame where every camera has one
    assert pairing.late[0, 1] == pytest.approx(0.1)  # the first frames of a late camera show its first frame
    assert by_offsets(np.zeros(3), count=5, fps=30.0).identity
    assert not pairing.identity


def test_times_pair_each_frame_with_the_nearest_capture():
    rng = np.random.default_rng(4)
    count = 40
    reference = np.arange(count) / 25.0 + rng.normal(0.0, 0.002, count)
    times = np.column_stack(
        [
            reference,
            np.arange(count) / 25.0 + 0.013 + rng.normal(0.0, 0.002, count),  # half a frame and a little late
            np.sort(np.arange(count) / 25.0 - 0.05 + rng.uniform(-0.004, 0.004, count)),  # 1.25 frames early
        ]
    )
    times[17:, 2] += 0.04  # the third camera dropped a frame after its 17th: every later one a frame later
    times[5, 1] = np.nan  # a frame without a time is never picked
    pairing = by_times(times, reference)
    for n in range(count):
        for k in range(3):
            known = np.flatnonzero(np.isfinite(times[:, k]))
            nearest = known[np.argmin(np.abs(times[known, k] - reference[n]))]
            assert pairing.frames[n, k] == nearest
            assert pairing.late[n, k] == pytest.approx(times[nearest, k] - reference[n])
    np.testing.assert_array_equal(pairing.frames[:, 0], np.arange(count))
    assert (np.diff(pairing.frames, axis=0) >= 0).all()
    assert pairing.frames[30, 2] == 30  # after the drop, the frame of the same index is nearest again
    assert pairing.frames[10, 2] == 11  # before it, the next frame


def test_a_camera_without_times_is_read_frame_by_frame():
    times = np.column_stack([np.arange(5) / 10.0, np.full(5, np.nan)])
    pairing = by_times(times, times[:, 0])
    np.testing.assert_array_equal(pairing.frames[:, 1], np.arange(5))
    np.testing.assert_array_equal(pairing.late, 0.0)


@pytest.fixture
def recording(tiny_recording, tmp_path):
    target = tmp_path / "rec"
    shutil.copytree(tiny_recording, target)
    return target


def _sources_read(rec, index):
    """Each camera's frame ``index`` as one reader reads it."""
    return [next(grey_frames(source, [index])) for source in rec.sources]


def test_a_recording_with_sync_toml_reads_each_camera_at_its_time(recording):
    fps = open_recording(recording).fps
    (recording / "sync.toml").write_text(f"[offsets]\ncam1 = {2 / fps}\n")  # cam1 two frames late
    rec = open_recording(recording)
    np.testing.assert_array_equal(rec.pairing.frames[:, 1], [0, 0, 0, 1, 2, 3])
    raw = open_recording(recording, paired=False)
    assert raw.pairing is None
    for index, images in frames(rec, 1, 6, step=2):
        wanted = camera_frames(rec, index)
        assert wanted == [index, max(index - 2, 0)]
        for image, camera, frame in zip(images, range(2), wanted):
            np.testing.assert_array_equal(image, _sources_read(raw, frame)[camera])


def test_cameras_picked_from_a_recording_keep_their_offsets(recording):
    fps = open_recording(recording).fps
    (recording / "sync.toml").write_text(f"[offsets]\ncam0 = 0.0\ncam1 = {2 / fps}\n")
    picked = open_recording(recording, ["cam1"])  # the file names cam0 too, a camera of the rig not picked
    np.testing.assert_array_equal(picked.pairing.frames[:, 0], [0, 0, 0, 1, 2, 3])
    np.testing.assert_allclose(picked.pairing.late[3:, 0], 0.0, atol=1e-12)


def test_a_recording_with_timestamps_reads_the_nearest_frames(recording):
    fps = open_recording(recording).fps
    times = np.arange(6) / fps
    rows = ["frame,cam0,cam1"] + [f"{n},{times[n]:.6f},{times[n] - 1.2 / fps:.6f}" for n in range(6)]
    (recording / "timestamps.csv").write_text("\n".join(rows) + "\n")
    rec = open_recording(recording)
    np.testing.assert_array_equal(rec.pairing.frames[:, 1], [1, 2, 3, 4, 5, 5])  # cam1 1.2 frames early
    np.testing.assert_allclose(rec.pairing.late[:5, 1], -0.2 / fps, atol=1e-6)
    np.testing.assert_allclose(capture_times(rec), times, atol=1e-6)
    on_time = ["frame,cam0,cam1"] + [f"{n},{times[n]:.6f},{times[n] + 0.001:.6f}" for n in range(6)]
    (recording / "timestamps.csv").write_text("\n".join(on_time) + "\n")
    assert open_recording(recording).pairing.identity  # a millisecond late: frame n still shows frame n
