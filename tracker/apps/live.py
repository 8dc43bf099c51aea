"""Live tracking (``tracker live``): track a body in the cameras' frames as they are captured.

Cameras are matched to the calibration's cameras in order (``--camera cam1=/dev/video2`` names
one instead) and tracked in calibration order.  A ``--camera`` that is a video file is played
at its frame rate as if a camera delivered it (several files share one clock).  Every camera
must give the size it is calibrated at.

Capture (:mod:`tracker.io.capture`): one thread per camera stamps, decodes and smooths each
frame; frames are paired into sets by capture time, and the tracker always takes the newest
complete set, so it never falls behind the cameras: frames it had no time for are dropped and
counted (stale sets), as are frames that found no partner (unpaired).  A status line on stderr
gives, every second, the tracked and captured frame rates and the drops.

A camera that fails or stops delivering is dropped with a message, and tracking goes on with
the others: the tracker is rebuilt for the remaining cameras at its current poses and motion,
with the same pixel settings.  When no camera is left the run stops; its output is kept.

Outputs: ``DIR/poses.npz`` (default ``out/live``) as ``tracker track`` writes it, frames numbered
0, 1, ... in the order they were tracked (capture order), written atomically as it grows.
``--record DIR`` writes a recording folder of exactly the frames the tracker took, in order:
``<camera>.avi`` per camera holding each frame's JPEG byte for byte as the camera gave it,
``calibration.toml``, ``model.toml`` and ``init.toml`` (copies), and ``timestamps.csv`` (frame and
each camera's capture time in seconds since capture started; the videos state the cameras' nominal
frame rate).  So ``tracker track DIR --keypoints off`` with the same settings decodes the same images and
computes the same poses as the live run (which tracks the edges and the colours, without the keypoints).  A recording
needs every camera in every frame: when a camera drops, the recording ends there (tracking
goes on), and it still replays identically.

Ctrl-C (or SIGTERM, or SIGHUP: :mod:`tracker.stop_signals`) stops the run after the frame in hand, so poses.npz,
the videos and timestamps.csv hold the same frames, and exits with 130 (143, 129); a second one interrupts at once
(the files are still valid).
"""

from __future__ import annotations

import shutil
import signal
import sys
import time
from collections.abc import Iterator, Mapping
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from tracker import stop_signals
from tracker.apps.loop import Tracked, track_frames
from tracker.atomic import ensure_writable_folder
from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.io.avi import MjpegAviWriter
from tracker.io.capture import Capture, Counts, FrameSet, ReplayClock, ReplaySource, Source, V4L2Source
from tracker.io.readers import WithChroma
from tracker.io.recording import VIDEO_SUFFIXES
from tracker.landmarks.hips import Proportions, lowered, proportions
from tracker.landmarks.live_detection import LiveDetector, transferred
from tracker.tracking.frame_loop import Tracker

DEFAULT_OUT = Path("out") / "live"
STATUS_PERIOD = 1.0  # seconds between status lines
TAKE_WAIT = 0.1  # seconds the loop waits for a set before it looks at the status and the stop request
HISTORY = 120  # frames whose tracked poses are kept, to move late landmarks to the present


def assign_cameras(specs: list[str], calibration: list[Camera], path: Path) -> list[tuple[Camera, str]]:
    """(camera, device) for each ``--camera``, in calibration order: by position, or ``NAME=DEVICE`` by name."""
    names = [camera.name for camera in calibration]
    named = [spec for spec in specs if "=" in spec]
    if named and len(named) != len(specs):
        raise TrackerInputError(
            "--camera: name every camera (cam0=/dev/video0) or none (then they are matched "
            f"to {path}'s cameras in order)"
        )
    if named:
        pairs = [cast(tuple[str, str], tuple(spec.split("=", 1))) for spec in specs]
        for name, device in pairs:
            if name not in names:
                raise TrackerInputError(f"{path}: has no camera {name!r}; name one of {', '.join(names)}")
            if not device:
                raise TrackerInputError(f"--camera {name}=: give the device, e.g. {name}=/dev/video0")
    else:
        if len(specs) > len(names):
            raise TrackerInputError(
                f"{path}: has {len(names)} camera(s) ({', '.join(names)}) but {len(specs)} "
                "--camera were given; use a calibration of every camera"
            )
        pairs = list(zip(names, specs))
    for kind, values in (("camera", [name for name, _ in pairs]), ("device", [device for _, device in pairs])):
        repeated = sorted({value for value in values if values.count(value) > 1})
        if repeated:
            raise TrackerInputError(f"--camera: {kind} {repeated[0]!r} is given twice; give each once")
    by_name = dict(pairs)
    return [(camera, by_name[camera.name]) for camera in calibration if camera.name in by_name]


def open_sources(
    devices: list[str], cameras: list[Camera], *, size: tuple[int, int] | None, fps: float | None, calibration: Path
) -> list[Source]:
    """One source per camera: a video file is replayed (all files on one clock, at ``fps`` if given, else at
    the file's rate), anything else is opened as a V4L2 device asked for ``size`` (default: the camera's) and
    ``fps``.  Each must give its camera's calibrated size."""
    clock = ReplayClock()
    sources: list[Source] = []
    try:
        for device, camera in zip(devices, cameras):
            if Path(device).is_file():
                source: Source = ReplaySource(device, clock, fps)
            elif Path(device).suffix.lower() in VIDEO_SUFFIXES:
                raise TrackerInputError(f"{device}: no such video file; check the path")
            else:
                source = V4L2Source(device, size or camera.size, fps)
            sources.append(source)
            if source.size != camera.size:
                width, height = source.size
                raise TrackerInputError(
                    f"{device}: gives {width}x{height} images but camera {camera.name!r} in {calibration} is "
                    f"calibrated at {camera.size[0]}x{camera.size[1]}; ask for that size (--size) or use a "
                    f"calibration made at {width}x{height}"
                )
    except BaseException:
        for source in sources:
            source.close()
        raise
    return sources


class Recorder:
    """Writes the sets the tracker took as a recording folder (module docstring); ``copies`` maps file names
    in the folder (calibration.toml, model.toml, init.toml) to the files to copy there, or to their bytes."""

    def __init__(self, folder: Path, cameras: list[Camera], fps: float, copies: Mapping[str, Path | bytes]):
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise TrackerInputError(f"{folder}: already exists; give a new folder for the recording")
        ensure_writable_folder(folder)
        for name, source in copies.items():
            if isinstance(source, bytes):
                (folder / name).write_bytes(source)
            else:
                shutil.copyfile(source, folder / name)
        self.frames = 0
        self.videos = [MjpegAviWriter(folder / f"{camera.name}.avi", fps, camera.size) for camera in cameras]
        self.times = open(folder / "timestamps.csv", "w", buffering=1)
        self.times.write(",".join(["frame"] + [camera.name for camera in cameras]) + "\n")

    def write(self, frame_set: FrameSet, origin: float) -> bool:
        """Append one set (every camera's frame) and its capture times, in seconds since ``origin``; False,
        writing nothing, when a video cannot take it (AVI 1.0 files end at 1 GiB)."""
        jpegs = [frame.jpeg.tobytes() for frame in frame_set.frames]
        if not all(video.fits(len(data)) for video, data in zip(self.videos, jpegs)):
            return False
        for video, data in zip(self.videos, jpegs):
            video.write_jpeg(data)
        self.times.write(
            ",".join([str(self.frames)] + [f"{frame.time - origin:.6f}" for frame in frame_set.frames]) + "\n"
        )
        self.frames += 1
        return True

    def close(self) -> None:
        for video in self.videos:
            video.close()
        self.times.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class Summary:
    """How a live run went: frames tracked (rows of poses.npz), frames recorded, the capture counters,
    seconds from the start of capture to the end, and the number of the stop signal that stopped it (SIGINT for
    Ctrl-C; 0 when none did)."""

    frames: int
    recorded: int
    counts: Counts
    seconds: float
    stopped_by: int


class _StopRequest:
    """While active, the first stop signal (Ctrl-C, SIGTERM or SIGHUP: :mod:`tracker.stop_signals`) only asks the loop
    to stop after the frame in hand, and :attr:`signal` is its number; a second one raises KeyboardInterrupt as
    usual.  A SIGTERM or SIGHUP that the process ignores stays ignored."""

    def __enter__(self) -> _StopRequest:
        self.signal = 0
        self.others = ExitStack()
        self.others.enter_context(stop_signals.handling((signal.SIGTERM, signal.SIGHUP), self._handle))
        self.previous = signal.signal(signal.SIGINT, self._handle)
        return self

    @property
    def requested(self) -> bool:
        return self.signal != 0

    def _handle(self, number: int, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt if number == signal.SIGINT else stop_signals.Stopped(number)
        self.signal = number

    def __exit__(self, *exc) -> None:
        signal.signal(signal.SIGINT, self.previous)
        self.others.close()


class _Status:
    """A status line on stderr every STATUS_PERIOD seconds: frame rates since the last line and the drops."""

    def __init__(self, capture: Capture):
        self.capture, self.frames = capture, 0
        self.time, self.counts = time.monotonic(), capture.counts()

    def tick(self, frames: int) -> None:
        now = time.monotonic()
        seconds = now - self.time
        if seconds < STATUS_PERIOD:
            return
        counts = self.capture.counts()
        rates = ", ".join(
            f"{name} {(now_count - then) / seconds:.1f}"
            for name, now_count, then in zip(counts.names, counts.captured, self.counts.captured)
        )
        print(
            f"live {now - self.capture.started:.0f} s: tracking {(frames - self.frames) / seconds:.1f} fps | "
            f"capture {rates} fps | {drops(counts)}",
            file=sys.stderr,
            flush=True,
        )
        self.time, self.counts, self.frames = now, counts, frames


def drops(counts: Counts) -> str:
    """The drop counters as the status line and the summary give them: stale sets, unpaired frames per camera."""
    unpaired = ", ".join(f"{name} {count}" for name, count in zip(counts.names, counts.unpaired))
    return f"dropped {counts.stale} stale sets, unpaired frames {unpaired}"


def _landmarks_now(
    detector: LiveDetector,
    history: dict[int, np.ndarray],
    tracker: Tracker,
    cameras: list[Camera],
    rig,
    *,
    body: Proportions | None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The detector's newest landmarks (if any arrived, of a frame still in ``history``), their hips lowered where
    they were read high (:func:`tracker.landmarks.hips.lowered`, for a model of proportions ``body``), moved to the
    frame about to be tracked by the motion tracked since their capture, for the cameras of ``rig``."""
    newest = detector.newest()
    if newest is None or newest[0] not in history:
        return None
    number, pixels, confidence = newest
    component, point = tracker.landmarks.component, tracker.landmarks.point
    pixels = lowered(pixels, confidence, cameras=cameras, body=body)  # in the frame they were detected in
    moved = transferred(pixels, history[number], tracker.poses, cameras=cameras, component=component, point=point)
    return moved[list(rig)], confidence[list(rig)]


class _Session:
    """What ``tracker live`` adds to the frame loop (:func:`tracker.apps.loop.track_frames`): the sets taken from
    ``capture`` until it ends or ``stop`` is requested, each recorded and offered to the detector (:meth:`sets`), the
    tracker rebuilt for the cameras still delivering (:meth:`retarget`), the set's capture time (:meth:`time`), the
    detector's newest landmarks moved to the present (:meth:`landmarks`), and each tracked frame kept and shown
    (:meth:`tracked`)."""

    def __init__(
        self,
        capture: Capture,
        cameras: list[Camera],
        stop: _StopRequest,
        recorder: Recorder | None,
        view,
        detector: LiveDetector | None,
        body: Proportions | None,
    ):
        self.capture, self.cameras, self.stop = capture, cameras, stop
        self.body = body  # the model's, for the detector's hips read high (tracker.landmarks.hips)
        self.recorder, self.view, self.detector = recorder, view, detector
        self.recording = recorder is not None
        self.rig = tuple(range(len(cameras)))  # the cameras of the set in hand
        self.blanks = [np.zeros((camera.size[1], camera.size[0]), np.uint8) for camera in cameras]  # dropped, viewer
        self.history: dict[int, np.ndarray] = {}  # tracked poses of the recent frames, by frame number
        self.frames = 0  # frames tracked
        self.taken: FrameSet | None = None  # the set in hand, and its capture time
        self.at = 0.0
        self.tracker: Tracker | None = None  # the tracker for the set in hand (retarget)

    def sets(self) -> Iterator[tuple[int, list[np.ndarray]]]:
        """(frame number, smoothed images of the cameras delivering) of each set taken, the newest complete one."""
        status = _Status(self.capture)
        cameras, recorder = self.cameras, self.recorder
        while not self.stop.requested:
            frame_set = self.capture.take(TAKE_WAIT)
            status.tick(self.frames)
            if frame_set is None:
                if self.capture.finished:
                    break
                continue
            if frame_set.cameras != self.rig:
                self.rig = frame_set.cameras
                print(
                    f"tracker: tracking goes on with {', '.join(cameras[camera].name for camera in self.rig)} "
                    f"from frame {self.frames} (tracker rebuilt at the current poses)",
                    file=sys.stderr,
                )
                if self.recording:
                    assert recorder is not None  # recording only with a recorder
                    print(
                        f"tracker: the recording ends at its {recorder.frames} frames: a recording "
                        "folder needs every camera in every frame",
                        file=sys.stderr,
                    )
                    self.recording = False
            self.taken = frame_set
            self.at = float(f"{frame_set.frames[0].time - self.capture.started:.6f}")  # as timestamps.csv has it
            if self.recording and recorder is not None and not recorder.write(frame_set, self.capture.started):
                print(
                    f"tracker: the recording ends at its {recorder.frames} frames: its videos reached "
                    "the 1 GiB an AVI file can hold; tracking goes on",
                    file=sys.stderr,
                )
                self.recording = False
            if self.detector is not None:
                jpegs: list[np.ndarray | None] = [None] * len(cameras)
                for camera, frame in zip(frame_set.cameras, frame_set.frames):
                    jpegs[camera] = frame.jpeg
                self.detector.offer(self.frames, jpegs)
            yield self.frames, [frame.image for frame in frame_set.frames]

    def retarget(self, tracker: Tracker) -> Tracker:
        """The tracker for the set in hand: ``tracker``, or when cameras dropped one for those still delivering that
        goes on from its poses, motion and learnt noise (:meth:`~tracker.tracking.frame_loop.Tracker.with_cameras`)."""
        delivering = [self.cameras[camera] for camera in self.rig]
        if tracker.rig.names != tuple(camera.name for camera in delivering):
            tracker = tracker.with_cameras(delivering)
        self.tracker = tracker
        return tracker

    def time(self, frame: int) -> float:
        """The capture time of the set in hand, frame ``frame``, in seconds since capture started."""
        return self.at

    def late(self, frame: int) -> np.ndarray:
        """Seconds each camera's image of the set in hand, frame ``frame``, was captured after the set's time (its first
        camera's): each view is tracked at its own capture time (docs/sync.md)."""
        assert self.taken is not None  # set by sets() before the frame is tracked
        return np.array([image.time - self.taken.frames[0].time for image in self.taken.frames])

    def landmarks(self, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The detector's newest landmarks for frame ``frame`` (:func:`_landmarks_now`), for the cameras of the set."""
        assert self.detector is not None and self.tracker is not None  # with a detector; after retarget
        return _landmarks_now(self.detector, self.history, self.tracker, self.cameras, self.rig, body=self.body)

    def tracked(self, frame: Tracked) -> None:
        """Keep the frame's poses for late landmarks, and show it (every camera, blank where one dropped)."""
        self.history[frame.index] = frame.result.poses
        self.history.pop(frame.index - HISTORY, None)
        if self.view is not None:
            assert self.taken is not None  # the set just tracked
            shown = list(self.blanks)
            for camera, image in zip(self.taken.cameras, frame.images):
                shown[camera] = image.image if isinstance(image, WithChroma) else image
            self.view.offer(frame.index, shown, frame.result, elapsed=frame.spent)
        self.frames += 1


def track_live(
    capture: Capture,
    tracker: Tracker,
    *,
    cameras: list[Camera],
    out: Path,
    recorder: Recorder | None = None,
    view=None,
    detector: LiveDetector | None = None,
) -> Summary:
    """Track the sets ``capture`` delivers with ``tracker`` (at its first pose) until its sources end, no camera is
    left, or a stop signal (Ctrl-C, SIGTERM, SIGHUP).

    ``cameras`` are the calibrated cameras of ``capture``'s sources, in the same order (``tracker``'s rig);
    ``recorder`` and ``view`` (a :class:`~tracker.viewer.live_view.LiveView`), if given, get every tracked frame (the
    recorder until a camera drops) and stay open for the caller to close.  ``detector``, if given, is offered every
    frame set and its newest landmarks are fused with the edges (moved to the frame by the tracked motion
    since their capture, :func:`tracker.landmarks.live_detection.transferred`); it stays open too.  Closes ``capture``.
    """
    try:
        print("preparing the numba kernels (compiled once, then cached)...", file=sys.stderr, flush=True)
        tracker.warm_up()
        with _StopRequest() as stop:
            capture.start(tracker.smooth, chroma=tracker.bin_colours if tracker.settings.region.on else False)
            session = _Session(capture, cameras, stop, recorder, view, detector, proportions(tracker.model))
            run = track_frames(
                tracker,
                session.sets(),
                out / "poses.npz",
                fps=capture.fps,
                keypoints=None if detector is None else session.landmarks,
                times=session.time,
                late=session.late,
                retarget=session.retarget,
                each=session.tracked,
            )
        seconds = time.monotonic() - capture.started
    finally:
        capture.close()  # also settles the counters
    recorded = recorder.frames if recorder is not None else 0
    stopped = stop.signal or (signal.SIGINT if run.interrupted else 0)
    return Summary(run.frames, recorded, capture.counts(), seconds, stopped)
