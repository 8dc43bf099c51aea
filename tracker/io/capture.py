"""Live capture: camera sources, one capture thread per camera, sets paired by time, the newest set.

Sources
    :class:`V4L2Source` opens a V4L2 device through OpenCV, asks for Motion-JPEG at a size and
    frame rate and keeps what the driver granted (``size``, ``fps``; it warns when the rate or the
    format is not the one asked for).  :class:`ReplaySource` plays a video file at its own frame
    rate (or one given), as a camera would deliver it.  Both hand out each frame as JPEG bytes with its capture
    time on the monotonic clock (``time.monotonic()``, seconds; for a device, the moment the
    driver handed the frame over, for a file the frame's due time): a camera's Motion-JPEG frame is
    kept as the driver gave it, so what the tracker decodes is exactly what a recording stores, and
    decoding the recording gives the same images again.  A device that does not give Motion-JPEG
    has its frames JPEG-encoded in the capture thread for the same reason.  ``read()`` returns
    None at the end of a replayed file and raises :class:`CaptureError` when the camera fails.

Capture threads
    One thread per camera reads its source, decodes each JPEG straight to grey and runs
    ``prepare`` on it (the tracker's smoothing), so this work runs beside the tracker (OpenCV
    releases the GIL), and checks that the frame has the size the source was opened at.

Pairing (:class:`Pairing`)
    The first camera still captured is the reference.  Its oldest waiting frame is paired with
    the frame of every other camera nearest to it in time (of those arrived; with cameras at one
    rate there is at most one), when that frame is within half a frame period (of the fastest
    camera) of it, as soon as every camera has one; frames that can no longer be paired are dropped and
    counted as *unpaired*: a reference frame that some camera has no frame near, and frames too
    old for any later reference frame.  Sets come out in capture order.  At most
    ``MAX_PENDING`` frames per camera wait for their partners; older ones are dropped as unpaired.

Newest set
    Completed sets go into a one-set slot.  A set that arrives before the tracker took the one in
    the slot replaces it and the older one counts as *stale*, so the tracker always takes the newest
    complete set and never works through a backlog: its lag behind the cameras is at most one
    tracking step and never grows, at the cost of the frames it had no time for.

Dropouts and the end
    A camera whose source raises, delivers a frame that does not decode or has another size, or
    delivers nothing for ``stall_timeout`` seconds is dropped, with a message on stderr: its waiting
    frames count as unpaired and the other cameras are paired without it from then on (sets
    carry the cameras they hold).  A source that ends (a replayed file) ends the capture once
    its frames are used up.

Counters (:class:`Counts`)
    Per camera, frames captured, frames in sets (paired) and frames dropped unpaired; sets
    completed, taken by the tracker and dropped stale.  After :meth:`Capture.close` the frames
    still waiting count as unpaired and an untaken set as stale, so ``captured == paired +
    unpaired`` for every camera and ``sets == taken + stale``.
"""

from __future__ import annotations

import sys
import threading
import time
import warnings
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from tracker.errors import TrackerInputError
from tracker.io.readers import MJPG, WithChroma, half_size, open_video
from tracker.io.recording import DEFAULT_FPS

STALL_TIMEOUT = 2.0  # seconds without a frame after which a camera is dropped
MAX_PENDING = 30  # frames per camera waiting for their partners
JOIN_WAIT = 1.0  # seconds close() waits for the capture threads (one stuck in a driver call is left behind)
_JPEG_QUALITY = 90  # for devices that do not give Motion-JPEG


class CaptureError(Exception):
    """A camera failed while capturing (unplugged, stalled, a frame that does not decode)."""


class Source(Protocol):
    """What the capture threads read: one camera, or a file played as one."""

    name: str  # the device or file, for messages
    size: tuple[int, int]  # (width, height) of its frames
    fps: float  # its frame rate

    def read(self) -> tuple[np.ndarray, float] | None:
        """The next frame as JPEG bytes (uint8, 1-D) and its monotonic capture time; None at the end."""

    def close(self) -> None:
        """Release the device or file (called by the thread that reads it, once it is done)."""


def encode_jpeg(image: np.ndarray) -> np.ndarray:
    """A decoded frame as JPEG bytes (uint8, 1-D), for sources that do not deliver Motion-JPEG."""
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, _JPEG_QUALITY])
    if not ok:
        raise CaptureError("a frame could not be encoded as JPEG")
    return data.reshape(-1)


def _fourcc_text(code: int) -> str:
    return code.to_bytes(4, "little").decode("ascii", "replace").strip("\0") or "unknown"


class V4L2Source:
    """A V4L2 camera through OpenCV (``cv2.CAP_V4L2``), asked for Motion-JPEG at ``size`` and ``fps``.

    ``size`` and ``fps`` are what the driver granted; the caller compares the size with the
    calibration.  A frame rate other than the one asked for, or a device that does not give
    Motion-JPEG, gives a warning.  A missing or unopenable device raises TrackerInputError.
    """

    def __init__(self, device: str, size: tuple[int, int] | None = None, fps: float | None = None):
        self.name = device
        if not Path(device).exists():
            raise TrackerInputError(
                f"{device}: no such video device; plug the camera in or pick another "
                "(`v4l2-ctl --list-devices` lists them)"
            )
        capture = cv2.VideoCapture(device, cv2.CAP_V4L2)
        if not capture.isOpened():
            raise TrackerInputError(
                f"{device}: cannot be opened as a V4L2 camera (not a capture device, busy "
                f"or not permitted); check it with `v4l2-ctl -d {device} --all`"
            )
        capture.set(cv2.CAP_PROP_FOURCC, MJPG)
        if size is not None:
            capture.set(cv2.CAP_PROP_FRAME_WIDTH, size[0])
            capture.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])
        if fps is not None:
            capture.set(cv2.CAP_PROP_FPS, fps)
        # a stalled device makes grab() fail after this long instead of blocking its thread for good
        capture.set(cv2.CAP_PROP_READ_TIMEOUT_MSEC, 1000 * STALL_TIMEOUT)
        fourcc = int(capture.get(cv2.CAP_PROP_FOURCC))
        self.mjpeg = fourcc == MJPG and capture.set(cv2.CAP_PROP_CONVERT_RGB, 0)  # raw: retrieve() gives the JPEG
        if not self.mjpeg:
            warnings.warn(
                f"{device} gives {_fourcc_text(fourcc)}, not Motion-JPEG; its frames are JPEG-encoded "
                "in the capture thread (more CPU per frame)",
                stacklevel=2,
            )
        self.size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        granted = capture.get(cv2.CAP_PROP_FPS)
        if fps is not None and granted > 0 and abs(granted - fps) > 0.01 * fps:
            warnings.warn(f"{device} runs at {granted:g} fps, not the {fps:g} asked for", stacklevel=2)
        self.fps = granted if granted > 0 else fps or DEFAULT_FPS
        self.capture = capture

    def read(self) -> tuple[np.ndarray, float]:
        if not self.capture.grab():
            raise CaptureError("the device gave no frame (unplugged, or stalled)")
        stamp = time.monotonic()
        ok, data = self.capture.retrieve()
        if not ok or data is None or data.size == 0:
            raise CaptureError("the device's frame could not be retrieved")
        return (data.reshape(-1) if self.mjpeg else encode_jpeg(data)), stamp

    def close(self) -> None:
        self.capture.release()


class ReplayClock:
    """The common start of replayed sources: frame k of each is due at ``start + k / fps``.

    Set by the first read of any source sharing it, so sources replayed together have the
    same capture times for the same frame numbers however their threads are scheduled.
    """

    def __init__(self) -> None:
        self._start: float | None = None
        self._lock = threading.Lock()

    def start(self) -> float:
        with self._lock:
            if self._start is None:
                self._start = time.monotonic()
            return self._start


class ReplaySource:
    """A video file delivered as a camera would: frame k at ``clock.start() + k / fps``, stamped with that time;
    ``fps`` is the file's own rate unless one is given (a slower one gives a slow machine time for every frame).

    Reading ahead of time waits until the frame is due; reading late (a busy thread) gets the frame at
    once with its due time, as a camera's driver buffer would.  Motion-JPEG files are read without
    decoding (the JPEG of each frame as stored); other codecs are decoded and JPEG-encoded.
    """

    def __init__(self, path: str | Path, clock: ReplayClock, fps: float | None = None):
        self.name = str(path)
        capture, self.mjpeg = open_video(Path(path))
        if not capture.isOpened():
            raise TrackerInputError(f"{path}: not a readable video file; give a camera device or a video")
        self.size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        own = capture.get(cv2.CAP_PROP_FPS)
        self.fps = fps or (own if np.isfinite(own) and own > 0 else DEFAULT_FPS)
        self.capture, self.clock, self.count = capture, clock, 0

    def read(self) -> tuple[np.ndarray, float] | None:
        ok, data = self.capture.read()
        if not ok:
            return None
        due = self.clock.start() + self.count / self.fps
        self.count += 1
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        return (data.reshape(-1) if self.mjpeg else encode_jpeg(data)), due

    def close(self) -> None:
        self.capture.release()


@dataclass(frozen=True)
class Frame:
    """One captured frame: monotonic capture time, the JPEG as delivered, the grey image after ``prepare`` (with its
    half-size colour, :class:`~tracker.io.readers.WithChroma`, when the capture was started with ``chroma``)."""

    time: float
    jpeg: np.ndarray
    image: Any


@dataclass(frozen=True)
class FrameSet:
    """Frames captured together, one per camera in ``cameras`` (indices into the capture's sources, ascending)."""

    cameras: tuple[int, ...]
    frames: tuple[Frame, ...]


class Pairing:
    """Pairs the frames of several cameras by capture time (module docstring); not thread-safe.

    ``add`` and ``remove`` return the sets they complete, oldest first.
    """

    def __init__(self, cameras: int, tolerance: float, max_pending: int = MAX_PENDING):
        self.tolerance, self.max_pending = tolerance, max_pending
        self.active = list(range(cameras))
        self.pending: list[deque[Frame]] = [deque() for _ in range(cameras)]
        self.paired = [0] * cameras
        self.unpaired = [0] * cameras

    def add(self, camera: int, frame: Frame) -> list[FrameSet]:
        waiting = self.pending[camera]
        waiting.append(frame)
        if len(waiting) > self.max_pending:
            waiting.popleft()
            self.unpaired[camera] += 1
        return self._match()

    def remove(self, camera: int) -> list[FrameSet]:
        """Stop pairing ``camera`` (its waiting frames count as unpaired); sets that waited for it complete."""
        self.active.remove(camera)
        self.flush(camera)
        return self._match()

    def flush(self, camera: int) -> None:
        """Drop the waiting frames of ``camera`` as unpaired."""
        self.unpaired[camera] += len(self.pending[camera])
        self.pending[camera].clear()

    def _match(self) -> list[FrameSet]:
        sets = []
        while self.active and self.pending[self.active[0]]:
            reference = self.active[0]
            anchor = self.pending[reference][0].time
            chosen = {reference: 0}
            waiting = unmatched = False
            for camera in self.active[1:]:
                queue = self.pending[camera]
                while queue and queue[0].time < anchor - self.tolerance:  # too old for this or any later anchor
                    queue.popleft()
                    self.unpaired[camera] += 1
                near = [
                    (abs(frame.time - anchor), k)
                    for k, frame in enumerate(queue)
                    if frame.time <= anchor + self.tolerance
                ]
                if near:
                    chosen[camera] = min(near)[1]
                elif queue:
                    unmatched = True  # its next frame is already past the anchor: nothing will pair with it
                else:
                    waiting = True
            if unmatched:
                self.pending[reference].popleft()
                self.unpaired[reference] += 1
                continue
            if waiting:
                break
            frames = []
            for camera in self.active:
                queue = self.pending[camera]
                for _ in range(chosen[camera]):  # passed over for a nearer frame
                    queue.popleft()
                    self.unpaired[camera] += 1
                frames.append(queue.popleft())
                self.paired[camera] += 1
            sets.append(FrameSet(tuple(self.active), tuple(frames)))
        return sets


@dataclass(frozen=True)
class Counts:
    """Capture counters (module docstring), per camera in the order of the sources."""

    names: tuple[str, ...]
    captured: tuple[int, ...]
    paired: tuple[int, ...]
    unpaired: tuple[int, ...]
    sets: int
    taken: int
    stale: int
    live: tuple[str, ...]  # cameras still captured


class Capture:
    """Capture threads over ``sources`` (camera ``names`` for messages), pairing and the newest-set slot.

    Owns the sources: :meth:`close` (or leaving a ``with`` block) stops the threads and releases them.
    """

    def __init__(self, sources: list[Source], names: list[str], stall_timeout: float = STALL_TIMEOUT):
        self.sources, self.names, self.stall_timeout = list(sources), list(names), stall_timeout
        self.fps = max(source.fps for source in sources)  # the nominal rate: of the fastest camera
        self.pairing = Pairing(len(sources), 0.5 / self.fps)
        self.captured = [0] * len(sources)
        self.last = [0.0] * len(sources)
        self.ended: set[int] = set()
        self.sets = self.taken = self.stale = 0
        self.slot: FrameSet | None = None
        self.started = 0.0
        self.closed = False
        self.lock = threading.Lock()
        self.changed = threading.Condition(self.lock)
        self.stopping = threading.Event()
        self.threads: list[threading.Thread] = []

    def start(
        self,
        prepare: Callable[[np.ndarray], np.ndarray] | None = None,
        *,
        chroma: bool | Callable[[np.ndarray], np.ndarray] = False,
    ) -> None:
        """Start one thread per camera; ``prepare`` (grey image -> image) runs in them on every frame.  With
        ``chroma`` each frame's image comes as :class:`~tracker.io.readers.WithChroma`, its colour at half size
        decoded from the same JPEG as the recording's readers decode it (and given to ``chroma`` in the thread, if
        that is a callable)."""
        self.started = time.monotonic()
        self.last = [self.started] * len(self.sources)
        self.threads = [
            threading.Thread(
                target=self._run, args=(camera, prepare, chroma), daemon=True, name=f"capture {self.names[camera]}"
            )
            for camera in range(len(self.sources))
        ]
        for thread in self.threads:
            thread.start()

    def _run(self, camera: int, prepare, chroma) -> None:
        source = self.sources[camera]
        try:
            while not self.stopping.is_set():
                delivered = source.read()
                if delivered is None:
                    self._end(camera)
                    return
                jpeg, stamp = delivered
                image = cv2.imdecode(jpeg, cv2.IMREAD_GRAYSCALE)
                if image is None:
                    raise CaptureError("delivered a frame that is not a decodable JPEG")
                if (image.shape[1], image.shape[0]) != source.size:
                    raise CaptureError(
                        f"delivered a {image.shape[1]}x{image.shape[0]} frame, not {source.size[0]}x{source.size[1]}"
                    )
                prepared = image if prepare is None else prepare(image)
                if chroma:
                    colour = cv2.imdecode(jpeg, cv2.IMREAD_REDUCED_COLOR_2)
                    if colour is None:
                        raise CaptureError("delivered a frame that is not a decodable JPEG")
                    half = half_size(colour, image.shape)
                    prepared = WithChroma(prepared, chroma(half) if callable(chroma) else half)
                self._arrive(camera, Frame(stamp, jpeg, prepared))
        except Exception as error:  # a failing camera is dropped; the others go on
            self.drop(camera, str(error) if isinstance(error, CaptureError) else f"failed: {error!r}")
        finally:
            source.close()

    def _arrive(self, camera: int, frame: Frame) -> None:
        with self.lock:
            if self.closed or camera not in self.pairing.active:
                return
            self.captured[camera] += 1
            self.last[camera] = time.monotonic()
            self._offer(self.pairing.add(camera, frame))

    def _offer(self, sets: list[FrameSet]) -> None:
        """Put completed sets in the slot (lock held): each replaces an untaken one, which is stale."""
        for frame_set in sets:
            self.sets += 1
            if self.slot is not None:
                self.stale += 1
            self.slot = frame_set
        self.changed.notify_all()

    def _end(self, camera: int) -> None:
        with self.lock:
            self.ended.add(camera)
            self.changed.notify_all()

    def drop(self, camera: int, reason: str) -> None:
        """Stop capturing ``camera`` (says so on stderr); the others are paired without it from now on."""
        with self.lock:
            if self.closed or camera not in self.pairing.active:
                return
            self._offer(self.pairing.remove(camera))
            left = [self.names[c] for c in self.pairing.active]
        going_on = f"going on with {', '.join(left)}" if left else "no camera is left"
        print(
            f"tracker: camera {self.names[camera]} ({self.sources[camera].name}) {reason}; {going_on}",
            file=sys.stderr,
            flush=True,
        )

    def _stalled(self, now: float) -> list[int]:
        with self.lock:
            return [
                camera
                for camera in self.pairing.active
                if camera not in self.ended and now - self.last[camera] > self.stall_timeout
            ]

    def _finished(self) -> bool:
        """No set is in the slot and none can come any more (lock held)."""
        if self.slot is not None:
            return False
        active = self.pairing.active
        return not active or any(camera in self.ended and not self.pairing.pending[camera] for camera in active)

    @property
    def finished(self) -> bool:
        with self.lock:
            return self._finished()

    def take(self, timeout: float) -> FrameSet | None:
        """The newest complete set, waiting up to ``timeout`` seconds for one; None if none came.

        Also drops the cameras that delivered nothing for ``stall_timeout`` seconds.
        """
        for camera in self._stalled(time.monotonic()):
            self.drop(camera, f"delivered no frame for {self.stall_timeout:g} s")
        with self.changed:
            if self.slot is None and not self._finished():
                self.changed.wait(timeout)
            taken, self.slot = self.slot, None
            if taken is not None:
                self.taken += 1
            return taken

    def counts(self) -> Counts:
        with self.lock:
            return Counts(
                tuple(self.names),
                tuple(self.captured),
                tuple(self.pairing.paired),
                tuple(self.pairing.unpaired),
                self.sets,
                self.taken,
                self.stale,
                tuple(self.names[camera] for camera in self.pairing.active),
            )

    def close(self) -> None:
        """Stop the threads (waiting up to JOIN_WAIT seconds in all) and settle the counters; idempotent."""
        self.stopping.set()
        deadline = time.monotonic() + JOIN_WAIT
        for thread in self.threads:
            thread.join(max(0.0, deadline - time.monotonic()))
        with self.lock:
            if self.closed:
                return
            self.closed = True
            for camera in range(len(self.sources)):
                self.pairing.flush(camera)
            if self.slot is not None:
                self.stale += 1
                self.slot = None
        if not self.threads:  # never started: nothing else will release the sources
            for source in self.sources:
                source.close()

    def __enter__(self) -> Capture:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
