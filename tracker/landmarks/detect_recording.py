"""The detector over frames of a recording, one landmarker per camera, and the cache that keeps its output.

A cache (``keypoints.npz``) belongs to one recording: its fingerprint names each camera's video by
size and a hash of its first bytes.  A recording whose cameras' frames are paired by time (docs/sync.md)
keeps its detections, made on the paired frames, in ``keypoints-paired.npz``, its fingerprint naming the
pairing too; one of the same videos paired otherwise (a new sync.toml) is detected again and replaced.  A pick of
the cameras (``--cameras cam1,cam2``) keeps its own, ``keypoints-cam1,cam2.npz``, beside every camera's.  Each landmark
model's detections are kept apart too: the default model's (:data:`tracker.landmarks.landmark_models.RECORDED`) in
``keypoints.npz``, another's with its name, ``keypoints-lite.npz`` (``keypoints-paired-lite-cam1,cam2.npz``), so that
switching models (``--landmark-model``) detects anew and switching back reuses what was detected.  A cache of another
recording is an error rather than something to overwrite silently; one made by another detector (an older version)
is detected again and replaced; one that lacks some of the wanted frames is completed and written back with every
frame it held.  The detector then starts at
the last of the leading wanted frames the cache holds (at the first when it holds none), so that it follows the person
on from a frame it has seen (a landmarker in video mode follows its person from frame to frame); its new reading of
that frame replaces nothing, while the frames it detects after it are its own.  What was detected is written
also when the run is interrupted (Ctrl-C, SIGTERM, SIGHUP), so that a run stopped partway goes on from where it
stopped.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Generator, Iterable
from concurrent.futures import Executor
from contextlib import ExitStack, closing
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError
from tracker.io.recording import Recording, frames
from tracker.landmarks.crop import CROP, scaled
from tracker.landmarks.detector import Detection, Detector, detect_views, detector_name, native_logs_muted
from tracker.landmarks.landmark_models import RECORDED
from tracker.landmarks.store import Keypoints, load_keypoints, save_keypoints

_HASHED = 1 << 16
"""Bytes of each video (or first image) hashed into a recording's fingerprint."""


def cache_file(folder: Path, recording: Recording, landmark_model: str) -> Path:
    """Where the detections of ``recording`` by ``landmark_model`` are kept in the output ``folder``: keypoints.npz;
    keypoints-paired.npz when its cameras' frames are paired by time; either with the model's name when it is not
    the default (:data:`tracker.landmarks.landmark_models.RECORDED`), then with the cameras' names when they are a
    pick (``--cameras``) other than every camera, e.g. keypoints-lite-cam1,cam2.npz: each set of detections is kept
    apart (module docstring)."""
    picked = [camera.name for camera in recording.cameras] if recording.picked else None
    return folder / cache_name(landmark_model, paired=_paired(recording), cameras=picked)


def cache_name(landmark_model: str, *, paired: bool = False, cameras: list[str] | None = None) -> str:
    """The name of :func:`cache_file`: keypoints, then -paired, -<landmark_model> unless it is the default, and
    -<cameras> (comma-separated) for a pick of the cameras (None: every camera), then .npz."""
    parts = ["keypoints", *(["paired"] if paired else [])]
    if landmark_model != RECORDED:
        parts.append(landmark_model)
    if cameras is not None:
        parts.append(",".join(cameras))
    return f"{'-'.join(parts)}.npz"


def _paired(recording: Recording) -> bool:
    return recording.pairing is not None and not recording.pairing.identity


def fingerprint(recording: Recording) -> str:
    """The recording's identity for caches: per camera its name, its video's size and a hash of its start
    (an image folder: its first image's), and a hash of the frames paired when its cameras' are paired by time."""
    parts = []
    for camera, source in zip(recording.cameras, recording.sources):
        file = min(path for path in source.iterdir() if path.is_file()) if source.is_dir() else source
        with open(file, "rb") as handle:
            digest = hashlib.sha1(handle.read(_HASHED)).hexdigest()[:12]
        parts.append(f"{camera.name}={file.stat().st_size}:{digest}")
    if _paired(recording):
        assert recording.pairing is not None  # paired
        frames = np.ascontiguousarray(recording.pairing.frames, np.int64)
        parts.append(f"paired={hashlib.sha1(frames.tobytes()).hexdigest()[:12]}")
    return " ".join(parts)


def _videos(fingerprint: str) -> str:
    """The part of a :func:`fingerprint` that names the videos, without their pairing."""
    return " ".join(part for part in fingerprint.split() if not part.startswith("paired="))


def cached(path: Path, recording: Recording, landmark_model: str) -> Keypoints | None:
    """The keypoints of ``recording`` by ``landmark_model`` held in ``path`` (None when there is no file, an unreadable
    one, one made by another detector, or one of the same videos paired otherwise: each is detected again and
    replaced); a file of another recording is a one-line error naming the fix."""
    if not path.is_file():
        return None
    try:
        found = load_keypoints(path)
    except TrackerInputError:
        return None
    names = tuple(camera.name for camera in recording.cameras)
    now = fingerprint(recording)
    if found.camera_names != names or (found.recording and _videos(found.recording) != _videos(now)):
        raise TrackerInputError(
            f"{path}: holds the keypoints of another recording (cameras {', '.join(found.camera_names)}); "
            "delete it, or keep this one's in another folder: --out DIR (fit-model and init: --cache DIR)"
        )
    if found.detector != detector_name(landmark_model):
        return None  # another version of the detector: detected again, the file replaced
    if found.recording and found.recording != now:
        return None  # the same videos paired otherwise (a new sync.toml): detected again, the file replaced
    return found


def holding(keypoints: Keypoints | None, wanted: np.ndarray) -> Keypoints | None:
    """``keypoints`` cut to the frames ``wanted`` if it holds every one of them, else None."""
    if keypoints is None or not np.isin(wanted, keypoints.frame).all():
        return None
    return keypoints.at_frames(wanted)


def merged(old: Keypoints | None, new: Keypoints) -> Keypoints:
    """The frames of both, sorted; ``new``'s rows where both hold a frame."""
    if old is None:
        return new
    both = stacked([new, old.rows(~np.isin(old.frame, new.frame))])
    return both.rows(np.argsort(both.frame, kind="stable"))


def detections(
    recording: Recording,
    start: int,
    stop: int,
    *,
    step: int = 1,
    landmark_model: str,
    pool: Executor | None = None,
) -> Generator[tuple[int, Keypoints], None, None]:
    """(frame, that frame's keypoints) for frames start, start + step, ... before stop, one landmarker of
    ``landmark_model`` per camera in video mode (so each follows its person from detected frame to detected frame),
    the views side by side in ``pool``'s threads if given (:func:`tracker.landmarks.detector.detect_views`).
    MediaPipe's native logs are muted the whole time (:func:`tracker.landmarks.detector.native_logs_muted`): a
    progress bar over it writes to its own copy of standard error (:func:`tracker.commands.options.bar`)."""
    names = tuple(camera.name for camera in recording.cameras)
    identity = fingerprint(recording)
    with ExitStack() as stack:
        stack.enter_context(native_logs_muted())  # the graphs' threads log while they run
        detectors = [Detector(landmark_model=landmark_model) for _ in recording.cameras]
        for detector in detectors:
            stack.callback(detector.close)
        for index, images in frames(recording, start, stop, colour=True, step=step):
            found = detect_views(detectors, images, cameras=recording.cameras, pool=pool)
            yield index, frame_keypoints(index, found, names=names, identity=identity, landmark_model=landmark_model)


def frame_keypoints(
    index: int,
    found: list[Detection],
    *,
    names: tuple[str, ...],
    identity: str,
    landmark_model: str,
    reduction: np.ndarray | None = None,
) -> Keypoints:
    """One frame's keypoints from its views' detections by ``landmark_model``; with ``reduction`` (one integer factor
    per camera) the
    detections were made in images reduced by it (:func:`tracker.io.readers.reduced`), and their pixels are taken
    back to full size, ``f p``: the detector gives a share of the image's width and height times that width and
    height (:func:`tracker.landmarks.detector._read`), and the reduced image spans the full one's whole blocks."""
    pixels = np.stack([detection.pixels for detection in found])
    factors = np.ones(len(found)) if reduction is None else np.asarray(reduction, float)
    mask = np.zeros((len(found), CROP, CROP), np.uint8)
    square = np.full((len(found), 3), np.nan)
    for view, (detection, factor) in enumerate(zip(found, factors)):
        if detection.mask is not None and detection.square is not None:
            mask[view] = detection.mask
            placed = scaled(detection.square, factor)
            square[view] = (*placed.centre, placed.side)
    return Keypoints(
        np.array([index]),
        names,
        (factors[:, None, None] * pixels)[None],
        np.stack([detection.confidence for detection in found])[None],
        np.stack([detection.world for detection in found])[None],
        detector=detector_name(landmark_model),
        recording=identity,
        mask=mask[None],
        square=square[None],
    )


def stacked(rows: list[Keypoints]) -> Keypoints:
    """One-frame (or several-frame) keypoints of the same cameras, one after the other."""
    first = rows[0]
    known = any(row.mask is not None for row in rows)
    return Keypoints(
        np.concatenate([row.frame for row in rows]),
        first.camera_names,
        np.concatenate([row.pixels for row in rows]),
        np.concatenate([row.confidence for row in rows]),
        np.concatenate([row.world for row in rows]),
        first.detector,
        first.recording,
        np.concatenate([row.masks()[0] for row in rows]) if known else None,
        np.concatenate([row.masks()[1] for row in rows]) if known else None,
    )


def detect_recording(
    recording: Recording,
    start: int = 0,
    stop: int | None = None,
    *,
    step: int = 1,
    cache: str | os.PathLike | None = None,
    progress: Callable[..., Iterable] = lambda iterable, total=None: iterable,
    landmark_model: str,
) -> tuple[Keypoints, int]:
    """The landmarks by ``landmark_model`` of frames start, start + step, ... before stop in every camera of
    ``recording``, and how many
    of those frames were detected now: none when ``cache`` (the recording's keypoints.npz) holds them all;
    otherwise they are detected from the last of the leading frames it holds on (module docstring) and, with ``cache``,
    written there beside the frames it held, also when the detection is interrupted: a frame detected again replaces
    the file's row, but for the one re-read only to follow the person on from it, which keeps the file's.
    ``progress(iterable, total=)`` wraps the frames detected (e.g. a tqdm bar)."""
    stop = recording.frame_count if stop is None else stop
    old = cached(Path(cache), recording, landmark_model) if cache is not None else None
    wanted = np.arange(start, stop, step)
    if (reused := holding(old, wanted)) is not None:
        return reused, 0
    kept = _resumed_at(old, wanted)
    rows: list[Keypoints] = []
    try:
        with closing(detections(recording, int(wanted[kept]), stop, step=step, landmark_model=landmark_model)) as found:
            for index, row in progress(found, total=len(wanted) - kept):
                if not (kept and index == wanted[kept]):  # re-read to follow the person on: the file's row stays
                    rows.append(row)
    finally:
        if cache is not None and rows:
            save_keypoints(cache, merged(old, stacked(rows)))
    new = stacked(rows)
    every = merged(old, new)
    added = len(new.frame) if old is None else int((~np.isin(new.frame, old.frame)).sum())
    return every.rows(np.isin(every.frame, wanted)), added


def _resumed_at(old: Keypoints | None, wanted: np.ndarray) -> int:
    """Where in ``wanted`` (frame numbers, not all of them in ``old``) the detector starts: at the last of the leading
    frames ``old`` holds, or at the first when it holds none."""
    if old is None:
        return 0
    leading = int(np.argmin(np.isin(wanted, old.frame)))  # the frames held before the first one lacking
    return max(leading - 1, 0)
