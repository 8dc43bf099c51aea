"""Live capture: pairing by time, the newest-set slot, replayed and V4L2 sources, dropped cameras.

Nothing here asserts on wall-clock timing: sources either replay in real time (a tenth of a
second) or deliver scripted frames at once, and the assertions are about what was paired and
counted, which the capture times alone decide.
"""

import threading

import cv2
import numpy as np
import pytest

from tracker.errors import TrackerInputError
from tracker.io.capture import MJPG, Capture, CaptureError, Frame, Pairing, ReplayClock, ReplaySource, V4L2Source
from tracker.io.readers import grey_frames

PERIOD = 1 / 60
WAIT = 10.0  # seconds a test waits for threads before it fails (never reached when things work)


def _frame(time: float) -> Frame:
    return Frame(time, np.zeros(0, np.uint8), np.zeros((1, 1), np.uint8))


def _feed(pairing: Pairing, arrivals: list[tuple[int, float]]) -> list[tuple[tuple[int, ...], tuple[float, ...]]]:
    """Add (camera, time) frames in this order; the sets completed, as (cameras, times)."""
    sets = []
    for camera, time in arrivals:
        sets += pairing.add(camera, _frame(time))
    return [(s.cameras, tuple(round(f.time, 4) for f in s.frames)) for s in sets]


def test_frames_within_half_a_period_are_paired_in_capture_order():
    pairing = Pairing(2, PERIOD / 2)
    arrivals = [(0, k * PERIOD) for k in range(5)] + [(1, k * PERIOD + 0.003) for k in range(5)]
    sets = _feed(pairing, arrivals)
    assert [times[0] for _, times in sets] == [round(k * PERIOD, 4) for k in range(5)]
    assert all(cameras == (0, 1) and abs(times[1] - times[0] - 0.003) < 1e-4 for cameras, times in sets)
    assert pairing.paired == [5, 5] and pairing.unpaired == [0, 0]


def test_a_frame_without_a_partner_is_dropped_and_counted():
    pairing = Pairing(2, PERIOD / 2)
    # camera 1 misses frame 2 and delivers a frame 10 ms off frame 4, beyond half a period
    arrivals = [(1, 0.0), (1, PERIOD), (1, 3 * PERIOD), (1, 4 * PERIOD + 0.010), (1, 5 * PERIOD)]
    arrivals += [(0, k * PERIOD) for k in range(6)]
    sets = _feed(pairing, arrivals)
    assert [round(times[0] / PERIOD) for _, times in sets] == [0, 1, 3, 5]
    assert pairing.unpaired == [2, 1]  # camera 0's frames 2 and 4; camera 1's frame near 4
    assert [p + u for p, u in zip(pairing.paired, pairing.unpaired)] == [6, 5]


def test_the_nearest_frame_is_taken_and_the_one_passed_over_is_counted():
    pairing = Pairing(2, PERIOD / 2)
    sets = _feed(pairing, [(1, -0.006), (1, 0.002), (0, 0.0)])
    assert sets == [((0, 1), (0.0, 0.002))]
    assert pairing.unpaired == [0, 1]


def test_frames_wait_for_a_late_camera_up_to_a_bound():
    pairing = Pairing(2, PERIOD / 2, max_pending=4)
    assert _feed(pairing, [(0, k * PERIOD) for k in range(6)]) == []  # camera 1 has delivered nothing yet
    assert pairing.unpaired == [2, 0]  # the two oldest gave way
    sets = _feed(pairing, [(1, k * PERIOD) for k in range(2, 6)])
    assert [round(times[0] / PERIOD) for _, times in sets] == [2, 3, 4, 5]


def test_removing_a_camera_completes_the_sets_that_waited_for_it():
    pairing = Pairing(3, PERIOD / 2)
    _feed(pairing, [(0, 0.0), (2, 0.0), (0, PERIOD), (2, PERIOD), (1, 0.0)])
    sets = pairing.remove(1)
    assert [(s.cameras, [f.time for f in s.frames]) for s in sets] == [((0, 2), [PERIOD, PERIOD])]
    assert pairing.paired == [2, 1, 2] and pairing.unpaired == [0, 0, 0]


class Scripted:
    """A source double: JPEG frames with the given capture times, delivered at once; then, once ``after``
    (an event) is set, the end (None), a failure (``then="fail"``) or a stall until ``released`` is set."""

    def __init__(self, times, then=None, after=None, size=(32, 24), frame_size=None):
        self.name, self.size, self.fps, self.then, self.after = "scripted", size, 60.0, then, after
        self.frame_size = frame_size or size
        self.times = list(times)
        self.done = threading.Event()  # every frame delivered
        self.released = threading.Event()
        self.closed = False

    def read(self):
        if self.times:
            time = self.times.pop(0)
            image = np.full((self.frame_size[1], self.frame_size[0]), int(time * 600) % 256, np.uint8)
            return cv2.imencode(".jpg", image)[1].reshape(-1), time
        self.done.set()
        if self.after is not None:
            self.after.wait(WAIT)
        if self.then == "fail":
            raise CaptureError("was unplugged")
        if self.then == "stall":
            self.released.wait(WAIT)
        return None

    def close(self):
        self.closed = True


def _settled(capture: Capture) -> None:
    """Counters agree once the capture is closed: every frame paired or unpaired, every set taken or stale."""
    capture.close()
    counts = capture.counts()
    assert [p + u for p, u in zip(counts.paired, counts.unpaired)] == list(counts.captured)
    assert counts.sets == counts.taken + counts.stale


def _drain(capture: Capture) -> list:
    """Take sets until the capture is finished."""
    taken = []
    for _ in range(int(WAIT / 0.05)):
        if capture.finished:
            return taken
        frame_set = capture.take(0.05)
        if frame_set is not None:
            taken.append(frame_set)
    raise AssertionError("the capture did not finish")


def test_the_tracker_gets_the_newest_set_and_older_ones_count_as_stale():
    sources = [Scripted([k * PERIOD for k in range(8)]), Scripted([k * PERIOD + 0.002 for k in range(8)])]
    capture = Capture(sources, ["a", "b"])
    capture.start()
    for thread in capture.threads:
        thread.join(WAIT)
    newest = capture.take(0.0)
    assert [round(frame.time / PERIOD) for frame in newest.frames] == [7, 7]
    assert capture.take(0.0) is None and capture.finished
    _settled(capture)
    counts = capture.counts()
    assert (counts.sets, counts.taken, counts.stale) == (8, 1, 7)
    assert counts.captured == (8, 8) and counts.unpaired == (0, 0)
    assert all(source.closed for source in sources)


def test_a_failing_camera_is_dropped_and_the_others_go_on(capsys):
    first = Scripted([k * PERIOD for k in range(10)])
    sources = [first, Scripted([k * PERIOD for k in range(4)], then="fail", after=first.done)]
    capture = Capture(sources, ["cam0", "cam1"])
    capture.start()
    taken = _drain(capture)
    _settled(capture)
    assert "camera cam1 (scripted) was unplugged; going on with cam0" in capsys.readouterr().err
    counts = capture.counts()
    assert counts.live == ("cam0",)
    assert counts.sets == 10 and counts.paired == (10, 4)  # 4 sets of both cameras, then 6 of cam0 alone
    assert taken[-1].cameras == (0,)
    times = [frame_set.frames[0].time for frame_set in taken]
    assert times == sorted(times)


def test_a_camera_that_stops_delivering_is_dropped_after_the_stall_timeout(capsys):
    first = Scripted([k * PERIOD for k in range(6)])
    stalled = Scripted([k * PERIOD for k in range(3)], then="stall", after=first.done)
    sources = [first, stalled]
    capture = Capture(sources, ["cam0", "cam1"], stall_timeout=0.3)
    capture.start()
    try:
        taken = _drain(capture)
    finally:
        stalled.released.set()  # lets its thread end, so close() need not wait for it
    assert "camera cam1 (scripted) delivered no frame for 0.3 s; going on with cam0" in capsys.readouterr().err
    assert taken[-1].cameras == (0,)
    _settled(capture)
    assert capture.counts().paired == (6, 3)


def test_frames_of_another_size_drop_the_camera(capsys):
    sources = [Scripted([0.0, PERIOD]), Scripted([0.0, PERIOD], frame_size=(16, 16))]
    capture = Capture(sources, ["cam0", "cam1"])
    capture.start()
    _drain(capture)
    _settled(capture)
    assert "camera cam1 (scripted) delivered a 16x16 frame, not 32x24" in capsys.readouterr().err


@pytest.mark.parametrize("fps", [None, 240.0])
def test_replay_sources_deliver_the_stored_jpegs_at_the_file_rate_on_one_clock(tiny_recording, fps):
    """At the file's rate (60 fps), or at the rate given."""
    clock = ReplayClock()
    sources = [ReplaySource(tiny_recording / f"cam{k}.avi", clock, fps) for k in range(2)]
    rate = fps or 60.0
    delivered = [[], []]
    for _ in range(6):
        for source, frames in zip(sources, delivered):
            frames.append(source.read())
    assert all(source.read() is None for source in sources)
    for camera, (source, frames) in enumerate(zip(sources, delivered)):
        assert source.size == (320, 240) and source.fps == rate
        expected = grey_frames(tiny_recording / f"cam{camera}.avi")
        for k, (jpeg, time) in enumerate(frames):
            assert time == clock.start() + k / rate  # frame k of every source shares its capture time
            np.testing.assert_array_equal(cv2.imdecode(jpeg, cv2.IMREAD_GRAYSCALE), next(expected))
        expected.close()
        source.close()


def test_capture_of_replayed_files_gives_prepared_images_in_order(tiny_recording):
    clock = ReplayClock()
    sources = [ReplaySource(tiny_recording / f"cam{k}.avi", clock) for k in range(2)]
    capture = Capture(sources, ["cam0", "cam1"])
    blur = lambda image: cv2.GaussianBlur(image, (0, 0), 1.0)  # noqa: E731
    capture.start(blur)
    taken = _drain(capture)
    _settled(capture)
    assert taken, "no set was taken"
    expected = [
        [blur(image) for _, image in zip(range(6), grey_frames(tiny_recording / f"cam{k}.avi"))] for k in range(2)
    ]
    numbers = []
    for frame_set in taken:
        assert frame_set.cameras == (0, 1)
        k = round((frame_set.frames[0].time - clock.start()) * 60.0)
        numbers.append(k)
        for camera, frame in enumerate(frame_set.frames):
            np.testing.assert_array_equal(frame.image, expected[camera][k])
    assert numbers == sorted(set(numbers)) and numbers[-1] == 5  # in order, and the last set is always taken
    assert capture.counts().sets == 6


def test_a_missing_device_is_a_one_line_error():
    with pytest.raises(TrackerInputError) as error:
        V4L2Source("/dev/video99")
    assert "/dev/video99" in str(error.value) and "\n" not in str(error.value)


class FakeDevice:
    """Stands in for cv2.VideoCapture on a V4L2 device whose driver grants ``granted`` whatever is asked."""

    def __init__(self, fourcc: int, size, fps: float, frames: int = 2):
        self.fourcc, self.size, self.fps, self.frames = fourcc, size, fps, frames
        self.asked: dict[int, float] = {}
        self.released = False

    def isOpened(self):
        return True

    def set(self, prop, value):
        self.asked[prop] = value
        return True

    def get(self, prop):
        return {
            cv2.CAP_PROP_FOURCC: self.fourcc,
            cv2.CAP_PROP_FRAME_WIDTH: self.size[0],
            cv2.CAP_PROP_FRAME_HEIGHT: self.size[1],
            cv2.CAP_PROP_FPS: self.fps,
        }[prop]

    def grab(self):
        self.frames -= 1
        return self.frames >= 0

    def retrieve(self):
        image = np.full((self.size[1], self.size[0], 3), 90, np.uint8)
        if self.asked.get(cv2.CAP_PROP_CONVERT_RGB, 1) == 0:  # raw: the driver's JPEG bytes as one row
            return True, cv2.imencode(".jpg", image)[1].reshape(1, -1)
        return True, image

    def release(self):
        self.released = True


def _open_fake(monkeypatch, tmp_path, device: FakeDevice, **asked) -> V4L2Source:
    node = tmp_path / "video0"
    node.touch()
    monkeypatch.setattr(cv2, "VideoCapture", lambda name, api: device if api == cv2.CAP_V4L2 else None)
    return V4L2Source(str(node), **asked)


@pytest.mark.parametrize("fourcc", [MJPG, cv2.VideoWriter.fourcc(*"YUYV")])
def test_v4l2_source_asks_for_motion_jpeg_and_keeps_what_the_driver_granted(monkeypatch, tmp_path, fourcc):
    device = FakeDevice(fourcc, (320, 240), 15.0)
    with pytest.warns(UserWarning) as warned:
        source = _open_fake(monkeypatch, tmp_path, device, size=(640, 480), fps=30.0)
    messages = " ".join(str(w.message) for w in warned)
    assert "runs at 15 fps, not the 30 asked for" in messages
    assert ("not Motion-JPEG" in messages) == (fourcc != MJPG)
    assert device.asked[cv2.CAP_PROP_FOURCC] == MJPG
    assert (device.asked[cv2.CAP_PROP_FRAME_WIDTH], device.asked[cv2.CAP_PROP_FRAME_HEIGHT]) == (640, 480)
    assert (source.size, source.fps) == ((320, 240), 15.0)
    jpeg, _ = source.read()
    assert cv2.imdecode(jpeg, cv2.IMREAD_GRAYSCALE).shape == (240, 320)
    source.read()
    with pytest.raises(CaptureError, match="gave no frame"):
        source.read()
    source.close()
    assert device.released
