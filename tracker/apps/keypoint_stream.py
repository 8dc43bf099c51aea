"""The detector beside the tracker: a worker process detects every ``step``-th frame ahead of it.

The worker either reads the recording itself or is fed by the tracker's reader threads
(:meth:`KeypointStream.copies`, :meth:`KeypointStream.feed`), runs one landmarker per camera, checks the views
against each other (:mod:`tracker.landmarks.consistency`) and hands each frame's landmarks over a queue, in frame
order.  Fed (large views only, :class:`KeypointStream`), it decodes nothing: the readers decode each video once and
give the scheduled frames also in colour, reduced as the edge search reduces them
(:func:`tracker.tracking.frame_loop.reductions`), written to shared memory that the worker reads in place
(:mod:`tracker.io.shared_frames`), and the landmarks are taken back to full-size pixels.  On 1080x1920 H.264 that
saves the second decoding of every frame of every view, and the pickling of each frame set through a pipe
(docs/speed.md).  Colour it must be: in grey the
detector takes the demo's backdrop photograph of a player for the body it should find (docs/keypoints.md).  The tracker
reads its frames ``step + LAG`` frames ahead of the one it tracks (:func:`tracked_frames`), so the worker detects a
frame while the tracker is still on earlier ones.  It is a process, not a thread, so the detector's Python glue never
holds the tracker's interpreter lock; on a machine with two cores the two run side by side.  The tracker asks for a
frame's landmarks when it reaches that frame and waits only if the worker has not got there yet, so a run's result
does not depend on timing.  A frame between two detected ones gets their landmarks interpolated (so the tracker
waits for the later one): at 60 frames a second a body moves little in a few frames, and a cue in every frame holds
it far better than one in every fourth.

A cache (``keypoints.npz``, :mod:`tracker.landmarks.detect_recording`) that already holds the scheduled
frames is used instead of the worker; otherwise what the worker detected is added to it when the
stream closes, also after Ctrl-C, SIGTERM or SIGHUP (the worker ignores them, :mod:`tracker.stop_signals`).  Frames
the cache holds are always taken from it, not from the worker (a landmarker in video mode reads a frame a little
differently after other frames), so a second run over the same output folder gives the same result as the first.
"""

from __future__ import annotations

import multiprocessing
import queue
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator
from concurrent.futures import Executor, ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tracker import stop_signals
from tracker.errors import TrackerInputError
from tracker.io.readers import ColourCopies, WithColour
from tracker.io.recording import Recording, frames
from tracker.io.shared_frames import SharedFrames
from tracker.landmarks.consistency import CONFIDENT, consistent, sided_with
from tracker.landmarks.detect_recording import (
    cached,
    detections,
    fingerprint,
    frame_keypoints,
    holding,
    merged,
    stacked,
)
from tracker.landmarks.detector import (
    Detector,
    detect_views,
    native_logs_muted,
    require_detector,
    view_threads,
)
from tracker.landmarks.hips import lowered, proportions
from tracker.landmarks.store import Keypoints, save_keypoints

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker

RATE = 15.0
"""Frames a second the detector sees by default (``--keypoints``; docs/keypoints.md: its cost and what it buys):
every 4th frame at 60 fps, every 2nd at 30, every frame below 22.5."""


def default_step(fps: float) -> int:
    """The detector's default step for a recording or camera of ``fps`` frames a second: ``fps / RATE`` rounded (halves
    up), at least 1; every frame for a rate that is not a positive finite number."""
    return max(1, int(fps / RATE + 0.5)) if fps > 0 and np.isfinite(fps) else 1


def schedule_words(step: int) -> str:
    """How often a ``step`` sees frames, in words: "every frame" or "one frame in N"."""
    return "every frame" if step == 1 else f"one frame in {step}"


_POLL = 0.5
"""Seconds between checks that the worker is still alive while waiting for it."""

LAG = 6
"""Frames a fed worker gets to detect a frame in before the tracker reaches the frames it is interpolated for
(six frames at 60 fps is 100 ms, longer than the detector takes on four HD views, docs/speed.md)."""


def schedule(start: int, stop: int, step: int) -> np.ndarray:
    """The frames the detector sees: start, start + step, ... before stop, and the last one (so that every
    frame lies between two detected ones)."""
    return np.unique(np.r_[np.arange(start, stop, step), stop - 1])


def _work(
    recording: Recording,
    start: int,
    stop: int,
    step: int,
    results,
    fed=None,
    reduction=None,
    *,
    landmark_model: str,
) -> None:
    """The worker process: detect and check each scheduled frame with ``landmark_model``, put (raw, checked) on
    ``results``, then None; an error is put instead and ends it.  With ``fed``, a queue, the frames are those the
    tracker's readers wrote to shared memory (:func:`_detect_fed`); else the worker reads them.  The stop signals are
    the parent's to handle (:mod:`tracker.stop_signals`)."""
    stop_signals.ignore()
    try:
        with native_logs_muted(), ThreadPoolExecutor(view_threads(len(recording.cameras)), "view") as pool:
            if fed is not None:
                _detect_fed(recording, fed, reduction, results, landmark_model, pool)
            else:
                runs = [(start, stop, step)] + ([(stop - 1, stop, 1)] if (stop - 1 - start) % step else [])
                for first, last, every in runs:  # the grid, then the last frame if it lies off the grid
                    found = detections(recording, first, last, step=every, landmark_model=landmark_model, pool=pool)
                    for _, raw in found:
                        results.put((raw, consistent(raw, recording.cameras)[0]))
        results.put(None)
    except BaseException as error:  # handed to the tracker, raised there
        results.put(error)


def _detect_fed(recording: Recording, fed, reduction, results, landmark_model: str, pool: Executor) -> None:
    """Detect in the frame sets named on ``fed`` (index, slot, :attr:`SharedFrames.spec
    <tracker.io.shared_frames.SharedFrames.spec>`), read in place in shared memory (one landmarker of
    ``landmark_model`` per camera, in video mode), until None; a set's result is put only once its images are no
    longer read, so that the tracker may write the slot again when it takes the result."""
    names, identity = tuple(camera.name for camera in recording.cameras), fingerprint(recording)
    detectors = [Detector(landmark_model=landmark_model) for _ in recording.cameras]
    shared: SharedFrames | None = None
    try:
        list(pool.map(Detector.warm_up, detectors))  # while the tracker's kernels load and its readers start
        while (item := fed.get()) is not None:
            index, slot, spec = item
            if shared is None:
                shared = SharedFrames.attach(spec)
            images = shared.images(slot)
            found = detect_views(detectors, images, cameras=recording.cameras, reduction=reduction, pool=pool)
            raw = frame_keypoints(
                index, found, names=names, identity=identity, landmark_model=landmark_model, reduction=reduction
            )
            results.put((raw, consistent(raw, recording.cameras)[0]))
    finally:
        for detector in detectors:
            detector.close()
        if shared is not None:
            shared.close()


def tracked_frames(
    stream: KeypointStream | None,
    recording: Recording,
    *,
    start: int,
    stop: int,
    prepare=None,
    colour: bool = False,
    chroma: bool | Callable[[np.ndarray], np.ndarray] = False,
) -> Iterator[tuple[int, list]]:
    """:func:`tracker.io.recording.frames` for the frame loop beside ``stream``: a fed stream gets the scheduled
    frames' colour images from the readers (:func:`_fed_ahead`)."""
    if stream is None or stream.fed is None:
        return frames(recording, start, stop, prepare=prepare, colour=colour, chroma=chroma)
    return _fed_ahead(
        stream,
        frames(recording, start, stop, prepare=prepare, colour=colour, copies=stream.copies(), chroma=chroma),
    )


def _fed_ahead(stream: KeypointStream, items: Iterable[tuple[int, list]]) -> Iterator[tuple[int, list]]:
    """The frames (index, images) of ``items``, each frame's colour images (:class:`WithColour`) handed to the
    fed ``stream`` (:meth:`KeypointStream.feed`) as it is read and the frame given out, without them,
    :attr:`KeypointStream.lead` frames later."""
    window: deque[tuple[int, list]] = deque()
    try:
        for index, images in items:
            if any(isinstance(image, WithColour) for image in images):  # a paired camera may repeat a fed frame
                if index in stream.to_feed:
                    stream.feed(index, [image.colour for image in images])
                images = [image.image if isinstance(image, WithColour) else image for image in images]
            window.append((index, images))
            if len(window) > stream.lead:
                yield window.popleft()
        yield from window
    finally:  # given up early (Ctrl-C): the reader threads stop now
        if isinstance(items, Generator):
            items.close()


class KeypointStream:
    """Checked landmarks by ``landmark_model`` of the scheduled frames, from the cache or from a worker process: one
    that reads the
    recording, or, with ``reduction`` (the tracker's, one factor per camera) that reduces some camera's images,
    one fed by the tracker's readers (the frame loop reads through :func:`tracked_frames`).

    Only reduced (large) views are fed: smaller ones decode cheaply (a 640x480 Motion-JPEG view costs a sixth of
    a 1080x1920 H.264 one), and a worker that reads them itself detects ahead while the tracker's kernels
    load, unbounded by the frames the tracker holds (docs/speed.md has what either way is worth end to end).  A fed
    worker reads the frame sets in shared memory (:mod:`tracker.io.shared_frames`), in a ring of as many slots as
    it can have frames to detect ahead of the tracker.  ``landmark_model`` picks the landmark model
    (:mod:`tracker.landmarks.landmark_models`)."""

    def __init__(
        self,
        recording: Recording,
        start: int,
        stop: int,
        step: int,
        cache: Path | None = None,
        reduction: np.ndarray | None = None,
        *,
        landmark_model: str,
    ):
        self.recording, self.cache, self.landmark_model = recording, cache, landmark_model
        self.wanted = schedule(start, stop, step)
        self.lead = step + LAG
        self.reduction = reduction
        self.fed = None
        self.to_feed: frozenset[int] = frozenset()  # the frames the readers give a fed worker (:meth:`copies`)
        self.sent: set[int] = set()
        self.shared: SharedFrames | None = None  # a fed worker's frame sets, made at the first one fed
        self.slots = -(-self.lead // step) + 2  # frame sets fed and not yet answered for: at most lead / step + 1
        self.free: list[int] = list(range(self.slots))
        self.slot_of: dict[int, int] = {}  # the slot of each frame fed and not yet answered for
        self.old = cached(cache, recording, landmark_model) if cache is not None else None
        self.raw: list[Keypoints] = []
        self.detected: dict[int, Keypoints] = {}  # each scheduled frame's landmarks as detected, before the check
        self.checked: dict[int, Keypoints] = {}
        self.settled: tuple[int, np.ndarray] | None = None  # the last detected frame :meth:`get` gave, its landmarks
        self.worker: multiprocessing.process.BaseProcess | None = None
        self.reused = holding(self.old, self.wanted)
        held = self.wanted[np.isin(self.wanted, self.old.frame)] if self.old is not None else self.wanted[:0]
        if len(held):  # the cache's rows win over a new detection of the same frame: a re-run gives the same
            assert self.old is not None
            detected = self.old.at_frames(held)
            checked = consistent(detected, recording.cameras)[0]
            self.checked = {int(frame): checked.at_frames(np.array([frame])) for frame in held}
            self.detected = {int(frame): detected.at_frames(np.array([frame])) for frame in held}
        if self.reused is not None:
            return
        require_detector(landmark_model)
        context = multiprocessing.get_context("spawn")
        with stop_signals.held():
            self.results = context.Queue()
            self.fed = context.Queue() if reduction is not None and np.max(reduction) > 1 else None
            self.worker = context.Process(
                target=_work,
                args=(recording, start, stop, step, self.results, self.fed, reduction),
                kwargs=dict(landmark_model=landmark_model),
                name="keypoint detector",
                daemon=True,
            )
            stop_signals.start(self.worker)
        self.finished = False

    def copies(self) -> list[ColourCopies] | None:
        """What the readers must give a fed worker, one per camera: the scheduled frames the cache does not hold,
        in colour, reduced as the tracker's images are; None for a stream that is not fed."""
        if self.fed is None:
            return None
        assert self.reduction is not None  # fed streams have one
        self.to_feed = frozenset(int(frame) for frame in self.wanted if frame not in self.checked)
        return [ColourCopies(self.to_feed, int(factor)) for factor in self.reduction]

    def feed(self, index: int, images: list[np.ndarray]) -> None:
        """Hand a fed worker frame ``index``'s colour images (BGR, one per camera, reduced by the stream's
        ``reduction``), copied into a free slot of the shared frame sets; when none is free, the worker's answers
        are taken (:meth:`_receive`) until one is."""
        assert self.fed is not None and index not in self.sent, f"frame {index} fed twice or to a reading stream"
        if self.shared is None:
            self.shared = SharedFrames([image.shape for image in images], self.slots)
        while not self.free:
            if self.finished:
                raise RuntimeError(f"frame {index} fed after the worker ended")
            self._receive()
        slot = self.free.pop()
        self.shared.write(slot, images)
        self.fed.put((index, slot, self.shared.spec))
        self.slot_of[index] = slot
        self.sent.add(index)

    def get(self, frame: int, *, settle: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
        """The checked landmarks of ``frame`` (pixels (C, 33, 2), confidence (C, 33)), waiting for the
        worker if need be.  Between two detected frames the landmarks are interpolated linearly (each
        where both frames hold it, at the lower confidence); None after the last detected frame.  With ``settle``,
        the disputes the views could not settle are given to the view that moved on steadily from the landmarks given
        at the last other detected frame asked for (:func:`tracker.landmarks.consistency.sided_with`; ask in frame
        order, or in reverse order when tracking back)."""
        checked = self._between(frame, self._checked)
        if checked is None or not settle:
            return checked
        detected = self._between(frame, self._detected)
        assert detected is not None  # every checked frame was detected
        last = self.settled[1] if self.settled is not None and self.settled[0] != frame else None
        pixels, confidence = sided_with(detected, checked, previous=last)
        if frame in self.checked:  # a detected frame: the next ones' own last frame
            self.settled = (frame, np.where((confidence >= CONFIDENT)[..., None], pixels, np.nan))
        return pixels, confidence

    def person(self, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The person's masks (C, S, S) and their squares (C, 3) of ``frame`` (after :meth:`get` of it), NaN squares
        in the views the check dropped or that found nobody; None for a frame the detector did not see (a mask even
        one frame old lies off a moving body: on the demo, tracked with its detections' masks on every other frame,
        the frames between went from 4 to 13 mm with the mask of the frame before), or a cache without masks."""
        found = self.checked.get(frame)
        if found is None or found.mask is None:
            return None
        mask, square = found.masks()
        seen = (found.confidence[0] > 0).any(axis=1)
        return mask[0], np.where(seen[:, None], square[0], np.nan)

    def _between(self, frame: int, landmarks) -> tuple[np.ndarray, np.ndarray] | None:
        """``landmarks`` (of a scheduled frame: pixels, confidence) of ``frame``, interpolated between scheduled
        frames (:meth:`get`)."""
        after = int(np.searchsorted(self.wanted, frame))
        if after < len(self.wanted) and self.wanted[after] == frame:
            return landmarks(frame)
        if after == 0 or after == len(self.wanted):
            return None
        before, next_frame = int(self.wanted[after - 1]), int(self.wanted[after])
        earlier, later = landmarks(before), landmarks(next_frame)
        if earlier is None or later is None:
            return None
        share = (frame - before) / (next_frame - before)
        pixels = (1.0 - share) * earlier[0] + share * later[0]
        confidence = np.minimum(earlier[1], later[1])
        return pixels, np.where(np.isfinite(pixels).all(axis=2), confidence, 0.0)

    def _detected(self, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The landmarks of a scheduled frame as detected, before the check (:meth:`_checked` waits for them)."""
        if self._checked(frame) is None:
            return None
        found = self.detected[frame]
        return found.pixels[0], found.confidence[0]

    def _checked(self, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The checked landmarks of a scheduled frame, waiting for the worker if need be."""
        if self.fed is not None and frame not in self.checked and frame not in self.sent:
            raise RuntimeError(f"frame {frame}'s landmarks asked for before it was fed: read through tracked_frames")
        while frame not in self.checked and self.worker is not None and not self.finished:
            self._receive()
        found = self.checked.get(frame)
        return None if found is None else (found.pixels[0], found.confidence[0])

    def _receive(self) -> None:
        """Take the worker's next frame (or its end, or its error) off the queue."""
        assert self.worker is not None
        try:
            item = self.results.get(timeout=_POLL)
        except queue.Empty:
            if not self.worker.is_alive():
                raise TrackerInputError(
                    f"{self.recording.path}: the keypoint detector stopped (exit code {self.worker.exitcode}); "
                    "run tracker keypoints on the recording to see why"
                ) from None
            return
        if item is None:
            self.finished = True
        elif isinstance(item, BaseException):
            self.finished = True
            raise item
        else:
            self._keep(item)

    def _keep(self, item: tuple[Keypoints, Keypoints]) -> None:
        """Keep a frame's landmarks from the worker, (raw, checked), unless the cache held that frame; a fed frame's
        slot is free again."""
        raw, checked = item
        if (slot := self.slot_of.pop(int(raw.frame[0]), None)) is not None:
            self.free.append(slot)
        if int(raw.frame[0]) not in self.checked:
            self.raw.append(raw)
            self.checked[int(raw.frame[0])] = checked
            self.detected[int(raw.frame[0])] = raw

    def _drain(self) -> None:
        """Keep the frames the worker has put on the queue ahead of the tracker, without waiting for more (its end
        and its error, the tracker's to raise, are left)."""
        while True:
            try:
                item = self.results.get_nowait()
            except queue.Empty:
                return
            if item is None or isinstance(item, BaseException):
                return
            self._keep(item)

    def close(self) -> None:
        """Stop the worker and add what it detected to the cache: also the frames it detected ahead of the tracker
        (a run stopped by Ctrl-C, SIGTERM or SIGHUP keeps them)."""
        if self.worker is not None:
            try:
                self._drain()
            finally:
                stop_signals.end(self.worker)
                self.worker = None
        if self.fed is not None:  # frames it will not take must not hold this process up, nor their memory
            self.fed.cancel_join_thread()
            self.fed.close()
        if self.shared is not None:
            self.shared.close()
            self.shared = None
        if self.cache is not None and self.raw:
            save_keypoints(self.cache, merged(self.old, stacked(self.raw)))
            self.raw = []

    def __enter__(self) -> KeypointStream:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def beside(stream: KeypointStream, tracker: Tracker) -> Callable[[int], tuple[np.ndarray, np.ndarray] | None]:
    """``stream``'s landmarks for the frames ``tracker`` tracks, the views' unsettled disputes settled by their own last
    frames (:meth:`KeypointStream.get`), hips read high lowered
    (:func:`tracker.landmarks.hips.lowered`); each call also hands ``tracker`` the person's masks of the frame, or
    none for a frame the detector did not see (:meth:`KeypointStream.person`,
    :meth:`Tracker.see_person <tracker.tracking.frame_loop.Tracker.see_person>`)."""
    body = proportions(tracker.model)

    def landmarks(frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        found = stream.get(frame, settle=True)
        tracker.see_person(stream.person(frame))
        if found is None:
            return None
        pixels, confidence = found
        return lowered(pixels, confidence, cameras=tracker.cameras, body=body), confidence

    return landmarks
