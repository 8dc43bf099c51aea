"""SIGTERM and SIGHUP stop a run as Ctrl-C does (its handlers in force only while it runs, a signal ignored left
ignored), a stop inside a numba kernel is told from an error, the keypoint detector's worker and multiprocessing's
resource tracker leave a stop to the run (no warning when every process of the run gets it), and a run whose terminal
closed ends without an error, its work saved."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import closing_terminal, stopping_after

from tracker import stop_signals
from tracker.landmarks.store import load_keypoints

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("number", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_raise_a_keyboard_interrupt_while_in_force(number):
    before = signal.getsignal(number)
    with pytest.raises(KeyboardInterrupt) as stop, stop_signals.like_ctrl_c() as received:
        os.kill(os.getpid(), number)
    assert isinstance(stop.value, stop_signals.Stopped) and stop.value.number == number
    assert received.number == number and received.exit_code(130) == 128 + number and received.exit_code(2) == 2
    assert signal.getsignal(number) is before


def test_a_signal_ignored_stays_ignored():
    """``nohup`` starts a run ignoring SIGHUP: a closed terminal must not stop it."""
    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with stop_signals.like_ctrl_c() as received:
            os.kill(os.getpid(), signal.SIGHUP)
        assert received.number is None and received.exit_code(130) == 130
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, previous)


def test_a_stop_inside_native_code_is_told_from_an_error():
    """numba's compiled functions call back into Python, and report a KeyboardInterrupt raised there as a SystemError
    caused by it (seen once in six Ctrl-C's of the demo's tracking)."""
    try:
        try:
            raise stop_signals.Stopped(signal.SIGTERM)
        except KeyboardInterrupt as stop:
            raise SystemError("CPUDispatcher(line_profiles) returned a result with an exception set") from stop
    except SystemError as error:
        reported = error
    assert stop_signals.stopped_within(reported)
    assert not stop_signals.stopped_within(SystemError("a real one"))


WORKER_STOPPED = """
import os, signal, sys
from pathlib import Path
from tracker import stop_signals
from tracker.apps.keypoint_stream import KeypointStream
from tracker.io.recording import open_recording

recording = open_recording(sys.argv[1])
with stop_signals.like_ctrl_c():
    stream = KeypointStream(recording, 0, recording.frame_count, 1, Path(sys.argv[2]), landmark_model="full")
    try:
        stream.get(1)  # the worker has detected frames 0 and 1
        os.killpg(0, signal.SIGHUP)  # as a service manager or a closed terminal: every process of the run
        raise AssertionError("SIGHUP did not stop the run")
    except stop_signals.Stopped as stop:
        sys.exit(stop_signals.exit_code(stop.number))
    finally:
        stream.close()
"""


def test_the_detector_worker_leaves_a_stop_to_the_run_which_keeps_its_detections(tiny_recording, tmp_path):
    """SIGHUP to every process of a run with the detector's worker: the run keeps what the worker detected and ends
    it, and exits 129 with no warning or error on standard error (the resource tracker, which SIGHUP would end, warns
    at exit that it died; a worker that SIGHUP ended would stop the run with an error)."""
    cache = tmp_path / "keypoints.npz"
    ended = subprocess.run(
        [sys.executable, "-c", WORKER_STOPPED, str(tiny_recording), str(cache)],
        capture_output=True,
        text=True,
        timeout=300,
        start_new_session=True,  # a process group of its own, which it signals whole
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert ended.returncode == 128 + signal.SIGHUP, ended.stderr
    complaints = ("leaked", "resource_tracker", "Traceback", "Error", "warning")  # not a library's own log lines
    assert not [line for line in ended.stderr.splitlines() if any(word in line for word in complaints)], ended.stderr
    assert np.isin([0, 1], load_keypoints(cache).frame).all()


def test_a_run_whose_terminal_closed_keeps_its_frames_and_exits_129(tiny_recording, tmp_path, monkeypatch):
    """SIGHUP from a terminal that closed after frame 2, writing to it failing from then on: the frames done are
    saved, and the run exits 129 without an error of its own (its last lines go nowhere)."""
    from tracker.cli import main
    from tracker.io.poses import load_poses

    close = closing_terminal(monkeypatch)
    monkeypatch.setattr("tracker.commands.options.bar", stopping_after(2, signal.SIGHUP, then=close))
    out = tmp_path / "out"
    assert main(["track", str(tiny_recording), "--out", str(out), "--keypoints", "off", "--quiet"]) == 129
    assert list(load_poses(out / "poses.npz")["frame"]) == [0, 1, 2]
