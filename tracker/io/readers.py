"""Decoding the frames of a recording: grey (or colour) images, one reader thread per camera.

Each camera's video (or image folder) is decoded by its own thread into a
bounded queue, so decoding runs beside the tracker (OpenCV and PyAV release the
GIL while they decode) and never runs more than ``queue_size`` frames ahead.
Grey images are the video's own luma, never a colour image converted back:

* Motion-JPEG: the compressed frame is taken from the container as it is (OpenCV)
  and libjpeg decodes only its luma plane, about twice as fast as colour;
* other codecs (H.264, ...): PyAV decodes each frame in the calling thread alone
  (one FFmpeg thread: the readers already run one per camera) and the grey image
  is the decoded frame's Y plane, stretched from the video range 16-235 to 0-255
  unless the video says it is full range: less than half the CPU of OpenCV's colour
  frame made grey (docs/speed.md has the measurements).

Readers asked for colour (the foreground cue and the keypoint detector need it) decode BGR.  Readers asked for
chroma (the region cue needs it) give each grey frame with a half-size colour image (:class:`WithChroma`) at
little extra cost: PyAV's decoded planes as they are (4:2:0 video: the chroma planes are already half size), or
libjpeg's decoding of the JPEG at half scale.
"""

from __future__ import annotations

import itertools
import queue
import re
import threading
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import av
import cv2
import numpy as np

from tracker.errors import TrackerInputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
MJPG = int.from_bytes(b"MJPG", "little")  # the Motion-JPEG fourcc as OpenCV gives it
LUMA_FIRST = ("yuv", "yuvj", "nv12", "nv21", "gray")  # pixel formats (name prefixes) whose plane 0 is the luma
# video-range luma (16 black, 235 white) to full range, as a colour decoder's RGB made grey would give it
VIDEO_TO_FULL = np.clip(np.round((np.arange(256) - 16) * 255 / 219), 0, 255).astype(np.uint8)
_PUT_WAIT = 0.1  # seconds between checks of the stop flag while a queue is full


@dataclass(frozen=True)
class ColourCopies:
    """Frames whose colour image a reader also gives (e.g. to the keypoint detector), reduced by ``factor``
    (f x f block means, :func:`reduced`)."""

    frames: frozenset[int]
    factor: int = 1


@dataclass(frozen=True)
class WithColour:
    """A frame as a reader gives it (grey, or what ``prepare`` made of it) with its reduced BGR colour image."""

    image: Any
    colour: np.ndarray


@dataclass(frozen=True)
class WithChroma:
    """A grey frame (or what ``prepare`` made of it) with its colour at half size, ``chroma`` (H // 2, W // 2, 3)
    uint8, in the video's own colour space (YUV from PyAV, BGR from JPEG and image files): each pixel the colour of
    a block of 2 x 2 full-size pixels (or what the reader's ``chroma`` callable made of it, :func:`read_frames`)."""

    image: Any
    chroma: np.ndarray


def half_size(image: np.ndarray, full_shape: tuple[int, ...]) -> np.ndarray:
    """``image`` (already about half of ``full_shape``, or full size) as exactly (H // 2, W // 2, 3)."""
    height, width = full_shape[0] // 2, full_shape[1] // 2
    if image.shape[0] >= 2 * height and image.shape[1] >= 2 * width:
        image = reduced(image, 2)
    if image.shape[:2] != (height, width):
        image = image[:height, :width]
    return np.ascontiguousarray(image)


def reduced(image: np.ndarray, factor: int) -> np.ndarray:
    """``image`` reduced by the integer ``factor``: each pixel the mean of a block of factor x factor, the rows and
    columns past the last whole block dropped (the image itself for 1)."""
    if factor <= 1:
        return image
    height, width = image.shape[0] // factor, image.shape[1] // factor
    return cv2.resize(image[: height * factor, : width * factor], (width, height), interpolation=cv2.INTER_AREA)


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


def split_kept(frame) -> tuple[np.ndarray, Any]:
    """A frame that :func:`keeping_grey`'s preparation made, as (the grey frame as recorded, what ``prepare`` made),
    the latter :class:`WithChroma` when the frame came with its colour."""
    if isinstance(frame, WithChroma):
        grey_frame, searched = frame.image
        return grey_frame, WithChroma(searched, frame.chroma)
    return frame


def grey_frames(
    source: Path,
    indices: Iterable[int] | None = None,
    *,
    colour: bool = False,
    copies: ColourCopies | None = None,
    chroma: bool = False,
) -> Generator[Any, None, None]:
    """Grey (or, with ``colour``, BGR) frames ``indices`` (default 0, 1, ... until the caller stops) of one video file
    or image folder, in that order, which never goes back: a frame named again is given again, the frames passed over
    are skipped undecoded where the container allows.  With ``chroma`` each comes as :class:`WithChroma`.  The frames
    ``copies`` names come as :class:`WithColour`, their colour image decoded from the same frame (around the
    :class:`WithChroma` with ``chroma``)."""
    copies = copies or ColourCopies(frozenset())
    indices = itertools.count() if indices is None else indices
    if source.is_dir():
        flags = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
        files = image_files(source)
        for index in indices:
            if index >= len(files):
                raise TrackerInputError(
                    f"{source}: image folder ended before the recording's last frame; add the missing images"
                )
            image = read_image(files[index], index, flags)
            bgr = read_image(files[index], index) if chroma or index in copies.frames else image
            frame = WithChroma(image, half_size(bgr, bgr.shape)) if chroma else image
            yield WithColour(frame, reduced(bgr, copies.factor)) if index in copies.frames else frame
        return
    video = open_frames(source, colour)
    position = 0  # the frame the video gives next
    last: Any = None  # the frame given last
    try:
        for index in indices:
            if index == position - 1 and last is not None:
                yield last
                continue
            if index < position:
                raise ValueError(f"{source}: frame {index} asked for after frame {position - 1}; frames go forward")
            for skipped in range(position, index):
                video.skip(skipped)
            if index in copies.frames:
                image, bgr, half = video.read_with_colour(index)
                last = WithColour(WithChroma(image, half) if chroma else image, reduced(bgr, copies.factor))
            elif chroma:
                last = WithChroma(*video.read_with_chroma(index))
            else:
                last = video.read(index)
            position = index + 1
            yield last
    finally:
        video.close()


def open_video(source: Path) -> tuple[cv2.VideoCapture, bool]:
    """An OpenCV capture of the video (FFmpeg, else any OpenCV backend) and whether its frames come as raw
    Motion-JPEG: then each read gives the frame's JPEG bytes as stored."""
    capture = cv2.VideoCapture(str(source), cv2.CAP_FFMPEG)
    if not capture.isOpened():
        capture = cv2.VideoCapture(str(source))
    raw = int(capture.get(cv2.CAP_PROP_FOURCC)) == MJPG and capture.set(cv2.CAP_PROP_FORMAT, -1)
    return capture, bool(raw)


class _MotionJpeg:
    """A Motion-JPEG video through OpenCV: each frame's JPEG as stored, decoded by libjpeg (grey: luma only)."""

    def __init__(self, source: Path, capture: cv2.VideoCapture, colour: bool):
        self.source, self.capture, self.flags = source, capture, cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE

    def read(self, index: int) -> np.ndarray:
        return self._decoded(self._data(index), self.flags, index)

    def read_with_colour(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The frame as :meth:`read` gives it, in BGR colour, and in colour at half size, all decoded from its
        JPEG."""
        data = self._data(index)
        image, bgr = self._decoded(data, self.flags, index), self._decoded(data, cv2.IMREAD_COLOR, index)
        return image, bgr, half_size(bgr, bgr.shape)

    def read_with_chroma(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """The frame as :meth:`read` gives it and its colour at half size, which libjpeg decodes at half scale."""
        data = self._data(index)
        image = self._decoded(data, self.flags, index)
        return image, half_size(self._decoded(data, cv2.IMREAD_REDUCED_COLOR_2, index), image.shape)

    def _data(self, index: int) -> np.ndarray:
        ok, data = self.capture.read()
        if not ok:
            raise _decode_error(self.source, index)
        return data

    def _decoded(self, data: np.ndarray, flags: int, index: int) -> np.ndarray:
        image = cv2.imdecode(data, flags)
        if image is None:
            raise _decode_error(self.source, index)
        return image

    def skip(self, index: int) -> None:
        if not self.capture.grab():
            raise _decode_error(self.source, index)

    def seek(self, index: int) -> None:
        self.capture.set(cv2.CAP_PROP_POS_FRAMES, index)

    def close(self) -> None:
        self.capture.release()


class _Decoded:
    """Any other video through PyAV, one FFmpeg thread: grey is the frame's luma plane (module docstring)."""

    def __init__(self, source: Path, colour: bool):
        self.source, self.colour = source, colour
        unsupported = TrackerInputError(f"{source}: corrupt or unsupported video; re-encode it, e.g. as H.264 .mp4")
        try:
            self.container = av.open(str(source))
        except av.FFmpegError:
            raise unsupported from None
        if not self.container.streams.video:
            self.container.close()
            raise unsupported
        self.stream = self.container.streams.video[0]
        self.stream.thread_count = 1
        self.frames = self.container.decode(self.stream)

    def _next(self, index: int) -> av.VideoFrame:
        try:
            return next(self.frames)
        except (StopIteration, av.FFmpegError):
            raise _decode_error(self.source, index) from None

    def read(self, index: int) -> np.ndarray:
        frame = self._next(index)
        return frame.to_ndarray(format="bgr24") if self.colour else luma(frame)

    def read_with_colour(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The frame as :meth:`read` gives it, in BGR colour, and in colour at half size (:func:`half_colour`)."""
        frame = self._next(index)
        bgr = frame.to_ndarray(format="bgr24")
        return (bgr if self.colour else luma(frame)), bgr, half_colour(frame)

    def read_with_chroma(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """The frame as :meth:`read` gives it and its colour at half size (:func:`half_colour`)."""
        frame = self._next(index)
        return (frame.to_ndarray(format="bgr24") if self.colour else luma(frame)), half_colour(frame)

    def skip(self, index: int) -> None:
        self._next(index)

    def seek(self, index: int) -> None:
        """Make frame ``index`` the next one read: seek to the key frame before it, then decode up to it (its
        time stamp from the stream's frame rate)."""
        stream = self.stream
        rate, base = stream.average_rate or stream.guessed_rate, stream.time_base
        if not rate or not base:
            raise TrackerInputError(f"{self.source}: the video has no frame rate to seek by; re-encode it")
        target = (stream.start_time or 0) + round(index / (rate * base))
        half = round(0.5 / (rate * base))
        self.container.seek(target, stream=stream, backward=True)
        self.frames = self.container.decode(stream)
        while True:
            frame = self._next(index)
            if frame.pts is None:
                raise TrackerInputError(f"{self.source}: frames without time stamps cannot be sought; re-encode it")
            if frame.pts >= target - half:
                self.frames = itertools.chain([frame], self.frames)
                return

    def close(self) -> None:
        self.container.close()


def luma(frame: av.VideoFrame) -> np.ndarray:
    """The grey uint8 (H, W) image of a decoded frame: its luma plane where it has one, in full range."""
    if not frame.format.name.startswith(LUMA_FIRST) or frame.format.components[0].bits != 8:
        return frame.to_ndarray(format="gray")  # 10-bit and other formats: converted
    plane = frame.planes[0]
    rows = np.frombuffer(memoryview(plane), np.uint8).reshape(frame.height, plane.line_size)[:, : frame.width]
    full = frame.color_range == av.video.reformatter.ColorRange.JPEG or frame.format.name.startswith(("yuvj", "gray"))
    return rows.copy() if full else cv2.LUT(rows, VIDEO_TO_FULL)


def half_colour(frame: av.VideoFrame) -> np.ndarray:
    """A decoded frame's colour at half size (H // 2, W // 2, 3): for 8-bit 4:2:0 video its luma reduced and its
    two chroma planes as decoded (YUV); any other format converted to BGR and reduced."""
    height, width = frame.height, frame.width
    if frame.format.name not in ("yuv420p", "yuvj420p"):
        return half_size(frame.to_ndarray(format="bgr24"), (height, width))
    planes = []
    for plane, rows in zip(frame.planes, (height, (height + 1) // 2, (height + 1) // 2)):
        planes.append(np.frombuffer(memoryview(plane), np.uint8).reshape(rows, plane.line_size))
    y = reduced(planes[0][:, :width], 2)
    h2, w2 = height // 2, width // 2
    return np.ascontiguousarray(np.dstack([y[:h2, :w2], planes[1][:h2, :w2], planes[2][:h2, :w2]]))


def open_frames(source: Path, colour: bool = False) -> _MotionJpeg | _Decoded:
    """The frames of a video file, read in order (``read``/``skip`` each take the frame's index for errors) or
    from anywhere (``seek``), grey (or BGR with ``colour``)."""
    capture, raw = open_video(source)
    if raw:
        return _MotionJpeg(source, capture, colour)
    capture.release()
    return _Decoded(source, colour)


class _Reader:
    """A thread that decodes the frames ``indices`` of one source into a bounded queue (errors travel along)."""

    def __init__(
        self,
        source: Path,
        indices: Sequence[int],
        queue_size: int,
        prepare=None,
        colour: bool = False,
        copies: ColourCopies | None = None,
        chroma: bool | Callable[[np.ndarray], np.ndarray] = False,
    ):
        self.source, self.indices, self.prepare, self.colour = source, indices, prepare, colour
        self.copies, self.chroma = copies, chroma
        self.queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._run, name=f"reader {source.name}", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        frames = grey_frames(
            self.source, self.indices, colour=self.colour, copies=self.copies, chroma=bool(self.chroma)
        )
        try:
            for image in frames:
                if not self._put(self._prepared(image)):
                    return
        except BaseException as error:  # handed to the consumer, raised there
            self._put(error)
        finally:
            frames.close()

    def _prepared(self, image):
        if isinstance(image, WithColour):
            return WithColour(self._prepared(image.image), image.colour)
        if isinstance(image, WithChroma):
            colour = self.chroma(image.chroma) if callable(self.chroma) else image.chroma
            return WithChroma(self._prepared(image.image), colour)
        return image if self.prepare is None else self.prepare(image)

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
    sources: list[Path],
    start: int,
    stop: int,
    *,
    queue_size: int = 4,
    prepare=None,
    colour: bool = False,
    step: int = 1,
    copies: list[ColourCopies] | None = None,
    chroma: bool | Callable[[np.ndarray], np.ndarray] = False,
    pairing: np.ndarray | None = None,
) -> Iterator[tuple[int, list]]:
    """(index, one grey image per source) for frames start, start + step, ... before stop, each source decoded
    by its own thread (BGR images with ``colour``), source k's frame ``pairing[index, k]`` (F, C) int for frame
    ``index`` when given (:class:`tracker.io.pairing.Pairing`); ``prepare`` (image -> anything), if given, runs in that
    thread too (e.g. the tracker's smoothing); a list of them gives each source its own.  With ``copies`` (one
    per source) the frames they name come as :class:`WithColour` (``prepare`` applied to the image); with
    ``chroma`` every frame comes as :class:`WithChroma` (``prepare`` applied to its grey image; a callable
    ``chroma`` applied to its half-size colour image, in the reader's thread too).  The frames ``copies`` names are
    the recording's, not the sources'."""
    preparers = prepare if isinstance(prepare, (list, tuple)) else [prepare] * len(sources)
    indices = range(start, stop, step)
    copies = copies or [ColourCopies(frozenset())] * len(sources)
    readers = []
    for camera, (source, each, copy) in enumerate(zip(sources, preparers, copies)):
        read = list(indices) if pairing is None else [int(frame) for frame in pairing[indices, camera]]
        if pairing is not None:
            named = [index for index in copy.frames if start <= index < stop]
            copy = ColourCopies(frozenset(int(pairing[index, camera]) for index in named), copy.factor)
        readers.append(_Reader(source, read, queue_size, each, colour, copy, chroma))
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
        self.video = None if self.files is not None else open_frames(source, colour)
        self.next_index = 0

    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` decoded exactly as the tracker's readers decode it."""
        if self.files is not None:
            return read_image(self.files[index], index, cv2.IMREAD_COLOR if self.colour else cv2.IMREAD_GRAYSCALE)
        assert self.video is not None  # a video: opened in __init__
        if index != self.next_index:
            self.video.seek(index)
        image = self.video.read(index)
        self.next_index = index + 1
        return image

    def close(self) -> None:
        if self.video is not None:
            self.video.close()
