"""timestamps.csv (tracker.io.timestamps, tracker.io.recording.capture_times): the project's layout and caliscope's,
and the one-line errors for a file that names an unknown camera, goes backwards or does not fit the videos."""

import shutil

import numpy as np
import pytest
from conftest import SHARED_DATA, needs_shared

from tracker.errors import TrackerInputError
from tracker.io.recording import capture_times, open_recording
from tracker.io.timestamps import camera_times

RIG = ["cam0", "cam1", "cam2"]


def _write(tmp_path, text):
    path = tmp_path / "timestamps.csv"
    path.write_text(text)
    return path


def test_the_projects_layout_gives_every_cameras_column(tmp_path):
    path = _write(tmp_path, "frame,cam0,cam1\n0,0.000,0.004\n1,0.033,0.036\n2,0.067,0.071\n")
    times = camera_times(path, ["cam1", "cam0", "cam2"], rig=RIG, frames=3)
    np.testing.assert_array_equal(times[:, 0], [0.004, 0.036, 0.071])
    np.testing.assert_array_equal(times[:, 1], [0.0, 0.033, 0.067])
    assert np.isnan(times[:, 2]).all()  # a camera the file does not name has no times


def test_caliscopes_layout_pairs_its_sets_by_sync_index(tmp_path):
    rows = ["sync_index,cam_id,frame_index,frame_time", "7,1,3,10.105", "5,0,1,10.001", "5,1,1,10.004", "7,0,3,10.100"]
    rows += ["6,0,2,10.050"]  # camera 1 dropped the middle set
    times = camera_times(_write(tmp_path, "\n".join(rows) + "\n"), ["cam0", "cam1"], rig=RIG, frames=3)
    np.testing.assert_array_equal(times[:, 0], [10.001, 10.050, 10.100])
    np.testing.assert_array_equal(times[[0, 2], 1], [10.004, 10.105])
    assert np.isnan(times[1, 1])
    numbered = camera_times(
        _write(tmp_path, "sync_index,cam_id,frame_time\n0,1,1.0\n"), ["b"], rig=["a", "b"], frames=1
    )
    assert numbered[0, 0] == 1.0  # no camera named cam1, cam_1 or port_1: camera 1 is the calibration's second


@needs_shared("caliscope-4cam", "extrinsic", "timestamps.csv")
def test_caliscopes_own_file(tmp_path):
    """caliscope's sample session: 48 sets of four 720p webcams at about 6 fps, read as its numbered cameras."""
    path = SHARED_DATA / "caliscope-4cam" / "extrinsic" / "timestamps.csv"
    names = ["cam_0", "cam_1", "cam_2", "cam_3"]
    times = camera_times(path, names, rig=names, frames=48)
    assert np.isfinite(times).all() and (np.diff(times, axis=0) > 0.1).all()  # about 6 frames a second
    spread = 1e3 * (times.max(axis=1) - times.min(axis=1))
    assert 5 < np.median(spread) < 10 and 40 < spread.max() < 50  # ms between a set's first and last capture


@pytest.mark.parametrize(
    "text, frames, message",
    [
        ("frame,cam0,cam9\n0,0,0\n", 1, "names camera 'cam9', which the calibration does not have"),
        ("sync_index,cam_id,frame_time\n0,7,0.5\n", 1, "names camera '7', which the calibration does not have"),
        (
            "frame,cam0\n0,0.1\n1,0.05\n",
            2,
            r"camera cam0's time goes backwards at frame 1 \(0.100000 then 0.050000 s\)",
        ),
        ("sync_index,cam_id,frame_time\n0,0,1.0\n1,0,0.9\n", 2, "camera cam0's time goes backwards at frame 1"),
        ("frame,cam0\n0,0.1\n", 2, "has 1 rows for 2 frames; give one row per frame"),
        ("sync_index,cam_id,frame_time\n0,0,1.0\n", 2, "has 1 frame sets for 2 frames"),
        ("frame,cam0\n0,soon\n", 1, "row 2's cam0 is 'soon', not a finite number"),
        ("time,cam0\n0,0\n", 1, "is neither frame,<camera>,... nor sync_index,cam_id"),
        ("", 1, "empty"),
    ],
)
def test_a_bad_timestamps_file_is_a_one_line_error(tmp_path, text, frames, message):
    path = _write(tmp_path, text)
    with pytest.raises(TrackerInputError, match=message) as raised:
        camera_times(path, ["cam0"], rig=RIG, frames=frames)
    assert str(path) in str(raised.value) and "\n" not in str(raised.value)


def test_a_recording_takes_its_first_cameras_times(tiny_recording, tmp_path):
    """tracker track's frame times: the first camera's capture times; where a set lacks it, the others' median."""
    rec = tmp_path / "rec"
    shutil.copytree(tiny_recording, rec)
    rows = ["sync_index,cam_id,frame_time"] + [f"{n},0,{n / 60 + 0.002}" for n in range(6) if n != 3]
    rows += [f"{n},1,{n / 60}" for n in range(6)]
    (rec / "timestamps.csv").write_text("\n".join(rows) + "\n")
    times = capture_times(open_recording(rec))
    np.testing.assert_allclose(times, [n / 60 + (0.0 if n == 3 else 0.002) for n in range(6)])
