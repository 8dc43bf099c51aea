"""Decoding the frames of a recording: grey (or colour) images, one reader thread per camera.

Each camera's video (or image folder) is decoded by its own thread into a
bounded queue, so decoding runs beside the tracker (OpenCV releases the GIL
while it decodes) and never runs more than ``queue_size`` frames ahead.
Motion-JPEG videos are decoded straight to grey: the compressed frame is taken
from the container as it is and libjpeg decodes only its luma plane, about
twice as fast as decoding colour and converting.  Other codecs are decoded in
colour and converted.  Readers asked for colour (the foreground cue needs it) decode BGR.
"""

from __future__ import annotations

import itertools
import queue
import re
import threading
from collections.abc import Callable, Generator, Iterator
from pathlib import Path

import cv2
import numpy as np

from tracker.errors import TrackerInputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
MJPG = int.from_bytes(b"MJPG", "little")  # the Motion-JPEG fourcc as OpenCV gives it
_PUT_WAIT = 0.1  # seconds between checks of the stop flag while a queue is full


def image_files(folder: Path) -> list[Path]:
    """The .png/.jpg files of an image folder, sorted by the (last) number in their names."""
    files = [path for path in folder.iterdir() if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES]

    def number(path: Path) -> int:
        digits = re.findall(r"\d+", path.stem)
        if not digits:
            raise TrackerInputError(f"{path}: image name has no frame number; name images 000000.png, 000001.png, ...")
        return int(digits[-1])

    return sorted(files, key=number)


def read_image(file: Path, index: int, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """One image file (colour by default); a corrupt one raises TrackerInputError naming it."""
    image = cv2.imread(str(file), flags)
    if image is None:
        raise TrackerInputError(f"{file}: frame {index} is a corrupt or unsupported image; replace it")
    return image


def _decode_error(video: Path, index: int) -> TrackerInputError:
    return TrackerInputError(
        f"{video}: frame {index} failed to decode; the video is truncated or corrupt, re-encode it"
    )


def grey(image: np.ndarray) -> np.ndarray:
    """Grey uint8 (H, W) from a BGR, BGRA or already grey frame."""
    if image.ndim == 2:
        return image
    code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
    return cv2.cvtColor(image, code)


def keeping_grey(prepare: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """A frame's preparation that also keeps the frame itself: frame -> (grey(frame), prepare(frame)), so it
    can still be shown (e.g. in an overlay video) after the edge search's image was made from it."""
    return lambda frame: (grey(frame), prepare(frame))


def _bgr(image: np.ndarray) -> np.ndarray:
    """BGR uint8 (H, W, 3) from a BGR, BGRA or grey frame."""
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    code = cv2.COLOR_GRAY2BGR if image.ndim == 2 else cv2.COLOR_BGRA2BGR
    return cv2.cvtColor(image, code)


def grey_frames(source: Path, start: int = 0, colour: bool = False, step: int = 1) -> Generator[np.ndarray, None, None]:
    """Grey (or, with ``colour``, BGR) frames start, start + step, ... of one video file or image folder (the
    caller stops); the frames between are skipped undecoded where the container allows."""
    if source.is_dir():
        flags = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
        files = image_files(source)
        for index in itertools.count(start, step):
            if index >= len(files):
                raise TrackerInputError(
                    f"{source}: image folder ended before the recording's last frame; add the missing images"
                )
            yield read_image(files[index], index, flags)
    capture, raw = open_video(source)
    try:
        for index in range(start):
            if not capture.grab():
                raise _decode_error(source, index)
        for index in itertools.count(start, step):
            yield _read_frame(capture, raw, source, index, colour)
            for skipped in range(index + 1, index + step):
                if not capture.grab():
                    raise _decode_error(source, skipped)
    finally:
        capture.release()


def open_video(source: Path) -> tuple[cv2.VideoCapture, bool]:
    """A capture of the video (FFmpeg, else any OpenCV backend) and whether its frames come as raw Motion-JPEG:
    then each read gives the frame's JPEG bytes as stored (the readers decode them to grey directly)."""
    capture = cv2.VideoCapture(str(source), cv2.CAP_FFMPEG)
    if not capture.isOpened():
        capture = cv2.VideoCapture(str(source))
    raw = int(capture.get(cv2.CAP_PROP_FOURCC)) == MJPG and capture.set(cv2.CAP_PROP_FORMAT, -1)
    return capture, bool(raw)


def _read_frame(capture: cv2.VideoCapture, raw: bool, source: Path, index: int, colour: bool = False) -> np.ndarray:
    """The next frame as grey uint8 (raw Motion-JPEG: libjpeg's luma plane; otherwise colour converted), or
    as BGR uint8 with ``colour``."""
    ok, data = capture.read()
    if not ok:
        raise _decode_error(source, index)
    if raw:
        image = cv2.imdecode(data, cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE)
    else:
        image = _bgr(data) if colour else grey(data)
    if image is None:
        raise _decode_error(source, index)
    return image


class _Reader:
    """A thread that decodes ``count`` frames of one source into a bounded queue (errors travel along)."""

    def __init__(
        self, source: Path, start: int, count: int, queue_size: int, prepare=None, colour: bool = False, step: int = 1
    ):
        self.source, self.start, self.count, self.prepare, self.colour = source, start, count, prepare, colour
        self.step = step
        self.queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, name=f"reader {source.name}", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        frames = grey_frames(self.source, self.start, self.colour, self.step)
        try:
            for image in itertools.islice(frames, self.count):
                if not self._put(image if self.prepare is None else self.prepare(image)):
                    return
        except BaseException as error:  # handed to the consumer, raised there
            self._put(error)
        finally:
            frames.close()

    def _put(self, item) -> bool:
        while not self.stopping.is_set():
            try:
                self.queue.put(item, timeout=_PUT_WAIT)
                return True
            except queue.Full:
                continue
        return False

    def get(self) -> np.ndarray:
        item = self.queue.get()
        if isinstance(item, BaseException):
            raise item
        return item

    def close(self) -> None:
        self.stopping.set()
        self.thread.join()


def read_frames(
    sources: list[Path], start: int, stop: int, queue_size: int = 4, prepare=None, colour: bool = False, step: int = 1
) -> Iterator[tuple[int, list]]:
    """(index, one grey image per source) for frames start, start + step, ... before stop, each source decoded
    by its own thread (BGR images with ``colour``); ``prepare`` (image -> anything), if given, runs in that
    thread too (e.g. the tracker's smoothing); a list of them gives each source its own."""
    preparers = prepare if isinstance(prepare, (list, tuple)) else [prepare] * len(sources)
    indices = range(start, stop, step)
    readers = [
        _Reader(source, start, len(indices), queue_size, each, colour, step) for source, each in zip(sources, preparers)
    ]
    try:
        for index in indices:
            yield index, [reader.get() for reader in readers]
    finally:
        for reader in readers:
            reader.close()


class FrameSeeker:
    """Random access to grey (or, with ``colour``, BGR) frames of one video or image folder (for viewers):
    reading the next frame continues decoding; any other index seeks.  Motion-JPEG AVIs seek exactly."""

    def __init__(self, source: Path, colour: bool = False):
        self.source, self.colour = source, colour
        self.files = image_files(source) if source.is_dir() else None
        self.capture: cv2.VideoCapture | None
        self.capture, self.raw = (None, False) if self.files is not None else open_video(source)
        self.next_index = 0

    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` decoded exactly as the tracker's readers decode it."""
        if self.files is not None:
            return read_image(self.files[index], index, cv2.IMREAD_COLOR if self.colour else cv2.IMREAD_GRAYSCALE)
        assert self.capture is not None  # a video: opened in __init__
        if index != self.next_index:
            self.capture.set(cv2.CAP_PROP_POS_FRAMES, index)
        image = _read_frame(self.capture, self.raw, self.source, index, self.colour)
        self.next_index = index + 1
        return image

    def close(self) -> None:
        if self.capture is not None:
            self.capture.release()
