"""Benchmarks: per-stage costs, end-to-end frames per second, and the decode-only floor.

Every figure is a median over ``repeats`` passes over the same recording in the
same process, after the numba kernels are compiled (or loaded from the cache):

* ``decode``: CPU milliseconds per frame to decode every camera's frame to grey,
  one camera after the other in one thread;
* the tracker's stages (:data:`tracker.tracking.workspace.STAGES`) and ``output`` (joint
  centres and the poses.npz writer), milliseconds per frame;
* end to end: frames per second of the whole ``tracker track`` loop (reader
  threads, tracking, writing) with the first camera only and with all cameras;
* decode only: frames per second of the same reader threads with no tracking,
  the floor that tracking is compared with (``ratio_all_views``);
* the keypoint cue: the detector's milliseconds per image (one camera's frames after the other,
  in this process, reduced as the tracker feeds them to its worker), and frames per second end to
  end with the detector beside the tracker at its default rate (a worker process started afresh in
  each pass, as ``tracker track`` does, so its start-up counts; and from its first landmarks on);
* the loop's three stages with the cue, each alone (:class:`Stage`: frames a second and CPU milliseconds a frame):
  the tracker's readers, the detector with each landmark model installed, the tracker with landmarks read
  beforehand; and the bounds they set: one after the other, the cores over their CPU, the slowest
  (docs/speed.md, "Overlap");
* a long run (:func:`long_run`): thousands of frames, the recording read in a loop, and the resident
  memory before, after the first :data:`SETTLED` frames and at the end (a live session must not grow).
"""

from __future__ import annotations

import contextlib
import os
import statistics
import tempfile
import time
import tomllib
from collections.abc import Generator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker.apps.keypoint_stream import (
    KeypointStream,
    beside,
    default_step,
    schedule,
    schedule_words,
    tracked_frames,
)
from tracker.apps.loop import Tracked, track_frames
from tracker.camera import look_at_camera
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.posefile import load_pose_file, pose_frame
from tracker.io.poses import load_poses
from tracker.io.readers import ColourCopies, grey_frames, reduced
from tracker.io.recording import Recording, frames, open_recording
from tracker.landmarks.consistency import consistent
from tracker.landmarks.detect_recording import frame_keypoints
from tracker.landmarks.detector import Detector, detect_views, native_logs_muted, view_threads
from tracker.landmarks.landmark_models import FILES, MODELS, RECORDED, model_folder
from tracker.model import Model, load_model, model_from_dict, rest_poses
from tracker.synthetic.render import Renderer
from tracker.tracking.edge_cue import reductions
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings
from tracker.tracking.workspace import STAGES, StageTimes

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"
HUMAN = Path(__file__).resolve().parents[2] / "models" / "human.toml"


@dataclass(frozen=True)
class TrackRun:
    fps: float
    stage_ms: dict  # stage -> milliseconds per frame
    iterations: int
    views: int
    frames: int = 0
    seconds: float = 0.0  # the loop's
    first: float = 0.0  # seconds from the start of the loop until the first frame's landmarks came (0 without them)

    @property
    def fps_after_first(self) -> float:
        """Frames a second from the first frame's landmarks on: the loop's pace once the detector's worker is up."""
        return self.frames / (self.seconds - self.first)


@dataclass
class Stage:
    """A stage of the loop timed alone: the frames it went through, and the wall and CPU seconds (this process's, all
    its threads) that took."""

    frames: int = 0
    seconds: float = 0.0
    cpu: float = 0.0

    @contextlib.contextmanager
    def timing(self, frames: int) -> Generator[None, None, None]:
        """Count ``frames`` and the seconds the block takes."""
        wall, cpu = time.perf_counter(), time.process_time()
        yield
        self.seconds += time.perf_counter() - wall
        self.cpu += time.process_time() - cpu
        self.frames += frames

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("nan")

    @property
    def cpu_ms(self) -> float:
        """CPU milliseconds a frame."""
        return 1e3 * self.cpu / self.frames if self.frames else float("nan")


def _median(values) -> float:
    return float(statistics.median(values))


def decode_cpu_ms(recording: Recording) -> float:
    """Milliseconds per frame to decode every camera's frame to grey in one thread."""
    started = time.perf_counter()
    for source in recording.sources:
        for _ in grey_frames(source, range(recording.frame_count)):
            pass
    return (time.perf_counter() - started) * 1e3 / recording.frame_count


def decode_only(recording: Recording) -> Stage:
    """The reader threads alone (all of the recording's cameras), decoding to grey."""
    stage = Stage()
    with stage.timing(recording.frame_count):
        sum(1 for _ in frames(recording))
    return stage


def decode_only_fps(recording: Recording) -> float:
    """Frames per second of the reader threads alone (all of the recording's cameras)."""
    return decode_only(recording).fps


def detector_ms(recording: Recording, settings: Settings, *, landmark_model: str, count: int = 40) -> float:
    """Median milliseconds per image of the keypoint detector's pass (``landmark_model``) on the whole image, which
    every view gets,
    over the first ``count`` frames of each camera (one landmarker per camera in video mode, as the tracker's
    worker runs them), each image reduced as the tracker's readers reduce what they feed the worker
    (:func:`tracker.tracking.frame_loop.reductions`: a 1080x1920 view at half size)."""
    seconds = []
    for source, factor in zip(recording.sources, reductions(settings, recording.cameras)):
        detector, images = (
            Detector(landmark_model=landmark_model),
            grey_frames(source, range(min(count, recording.frame_count)), colour=True),
        )
        try:
            for image in images:
                image = reduced(image, int(factor))
                started = time.perf_counter()
                detector.whole(image)
                seconds.append(time.perf_counter() - started)
        finally:
            images.close()
            detector.close()
    return 1e3 * _median(seconds)


def _stream(
    recording: Recording,
    stop: int,
    keypoint_step: int,
    settings: Settings,
    *,
    cache: Path | None = None,
    landmark_model: str,
) -> KeypointStream | None:
    """The detector (``landmark_model``) beside the tracker on frames 0..stop-1, fed the tracker's images
    as ``tracker track`` feeds it, its detections kept in ``cache`` if given; None for ``keypoint_step`` 0."""
    if not keypoint_step:
        return None
    reduction = reductions(settings, recording.cameras)
    return KeypointStream(recording, 0, stop, keypoint_step, cache, reduction, landmark_model=landmark_model)


def track_run(
    recording: Recording,
    model: Model,
    start: np.ndarray,
    *,
    settings: Settings,
    out: Path,
    keypoint_step: int = 0,
    landmark_model: str = RECORDED,
    cache: Path | None = None,
) -> TrackRun:
    """One end-to-end pass from the poses ``start`` (N, 4, 4): reader threads, tracking and the poses.npz writer;
    with ``keypoint_step`` the detector's worker (``landmark_model``) on every keypoint_step-th frame beside
    them, started before the kernels load, its detections kept in ``cache`` if given (a cache that holds them is read
    instead: no worker)."""
    stream = _stream(
        recording, recording.frame_count, keypoint_step, settings, cache=cache, landmark_model=landmark_model
    )
    first: list[float] = []
    try:
        tracker = Tracker(model, recording.cameras, start, settings)
        tracker.warm_up()
        tracker.work.times = StageTimes()
        landmarks = None if stream is None else beside(stream, tracker)

        def timed(index: int) -> tuple[np.ndarray, np.ndarray] | None:
            """The frame's landmarks, the time the first came noted."""
            assert landmarks is not None
            found = landmarks(index)
            if not first:
                first.append(time.perf_counter() - started)
            return found

        started = time.perf_counter()
        run = track_frames(
            tracker,
            tracked_frames(
                stream,
                recording,
                start=0,
                stop=recording.frame_count,
                prepare=tracker.smooth,
                chroma=tracker.bin_colours if settings.region.on else False,
            ),
            out / "poses.npz",
            fps=recording.fps,
            keypoints=None if landmarks is None else timed,
        )
    finally:
        if stream is not None:
            stream.close()
    if run.interrupted:
        raise KeyboardInterrupt  # the benchmark stops at Ctrl-C
    elapsed = time.perf_counter() - started
    count = recording.frame_count
    stage_ms = {stage: seconds * 1e3 / count for stage, seconds in tracker.work.times.seconds.items()}
    stage_ms["output"] = run.writing * 1e3 / count
    views = len(recording.cameras)
    return TrackRun(count / elapsed, stage_ms, settings.solve.iterations, views, count, elapsed, (first or [0.0])[0])


CHUNK = 50
"""Frames read into memory at a time when the tracker is timed alone (:func:`track_stage`)."""


def track_stage(
    recording: Recording,
    model: Model,
    start: np.ndarray,
    *,
    settings: Settings,
    keypoint_step: int,
    cache: Path,
    landmark_model: str,
) -> Stage:
    """The tracker alone with the keypoint cue: the frames read beforehand, :data:`CHUNK` at a time (not timed), as
    ``tracker track``'s readers give them, and the landmarks of every keypoint_step-th frame read from ``cache`` (a
    keypoints.npz that holds them), so that neither decoding nor detection runs beside it."""
    tracker = Tracker(model, recording.cameras, start, settings)
    tracker.warm_up()
    chroma = tracker.bin_colours if settings.region.on else False
    stage = Stage()
    with (
        tempfile.TemporaryDirectory() as folder,
        KeypointStream(
            recording, 0, recording.frame_count, keypoint_step, cache, landmark_model=landmark_model
        ) as stream,
    ):
        if stream.reused is None:
            raise RuntimeError(f"{cache} does not hold the landmarks the tracker is timed with")
        landmarks = beside(stream, tracker)
        for first in range(0, recording.frame_count, CHUNK):
            last = min(recording.frame_count, first + CHUNK)
            chunk = list(frames(recording, first, last, prepare=tracker.smooth, chroma=chroma))
            with stage.timing(len(chunk)):
                run = track_frames(
                    tracker, chunk, Path(folder) / f"{first}.npz", fps=recording.fps, keypoints=landmarks
                )
            if run.interrupted:
                raise KeyboardInterrupt  # the benchmark stops at Ctrl-C
    return stage


def read_stage(
    recording: Recording, model: Model, start: np.ndarray, *, settings: Settings, keypoint_step: int
) -> Stage:
    """``tracker track``'s reader threads alone: each frame decoded, smoothed and its colours binned, and every
    keypoint_step-th frame's colour copy made for a fed detector (views the edge search reduces), nothing tracked."""
    stage = Stage()
    tracker = Tracker(model, recording.cameras, start, settings)
    reduction = reductions(settings, recording.cameras)
    copies = None
    if keypoint_step and reduction.max() > 1:
        wanted = frozenset(int(frame) for frame in schedule(0, recording.frame_count, keypoint_step))
        copies = [ColourCopies(wanted, int(factor)) for factor in reduction]
    chroma = tracker.bin_colours if settings.region.on else False
    with stage.timing(recording.frame_count):
        sum(1 for _ in frames(recording, prepare=tracker.smooth, chroma=chroma, copies=copies))
    return stage


SETS = 30
"""Frame sets the detector is timed on alone (:func:`detect_stage`), after the first."""


def installed_models() -> list[str]:
    """The landmark models whose weights are installed: the detector never fetches one."""
    folder = model_folder()
    return [name for name in MODELS if (folder / FILES[name].file).is_file()]


def detect_stage(recording: Recording, settings: Settings, *, keypoint_step: int, landmark_model: str) -> Stage:
    """The detector alone (``landmark_model``) at ``keypoint_step``: every view of up to :data:`SETS` + 1 of
    the frames it is scheduled on, read beforehand as its worker gets them (reduced as the edge search reduces them),
    detected (the views side by side in threads) and checked across the views as the worker does, in this process,
    each set counting for the ``keypoint_step`` frames it stands for; the first set (the landmarkers' start and a first
    search for the body) is not timed."""
    reduction = reductions(settings, recording.cameras)  # all 1 where the worker reads the videos itself
    read = frames(recording, 0, min(recording.frame_count, (SETS + 1) * keypoint_step), colour=True, step=keypoint_step)
    sets = [[reduced(image, int(factor)) for image, factor in zip(images, reduction)] for _, images in read]
    names = tuple(camera.name for camera in recording.cameras)
    detectors = [Detector(landmark_model=landmark_model) for _ in recording.cameras]
    stage, untimed = Stage(), Stage()
    try:
        with native_logs_muted(), ThreadPoolExecutor(view_threads(len(recording.cameras)), "view") as pool:
            for count, images in enumerate(sets):
                with (stage if count else untimed).timing(keypoint_step):
                    found = detect_views(detectors, images, cameras=recording.cameras, reduction=reduction, pool=pool)
                    raw = frame_keypoints(
                        0, found, names=names, identity="", landmark_model=landmark_model, reduction=reduction
                    )
                    consistent(raw, recording.cameras)
    finally:
        for detector in detectors:
            detector.close()
    return stage


def _subject(path: Path, model_path: Path | None, init_path: Path | None) -> tuple[Recording, Model, np.ndarray]:
    """The recording at ``path``, the body model and the first pose (``model_path`` and ``init_path``, else the
    recording's own; the pose at frame 0, where the runs start); a one-line error naming the option when one is
    missing."""
    recording = open_recording(path)
    model_path = model_path or recording.model_path
    init_path = init_path or recording.init_path
    if model_path is None or init_path is None:
        missing, option = ("model.toml", "--model") if model_path is None else ("init.toml", "--init")
        raise TrackerInputError(
            f"{path}: no {missing}; tracker bench needs a model and a first pose: pass {option} "
            "(tracker fit-model and tracker init write them)"
        )
    model = load_model(model_path)
    frame = pose_frame(init_path)
    if frame != 0:
        raise TrackerInputError(
            f"{init_path}: is the pose at frame {frame}, but tracker bench starts at frame 0; pass --init with a pose "
            f"at frame 0 (tracker init {path} --out FILE writes one)"
        )
    return recording, model, load_pose_file(init_path, model)


def run(
    path: Path = DEMO,
    settings: Settings = Settings(),
    *,
    repeats: int = 3,
    keypoint_step: int | None = None,
    model_path: Path | None = None,
    init_path: Path | None = None,
    landmark_model: str = RECORDED,
) -> dict:
    """All figures of the benchmark as one dictionary (the keys of ``tracker bench --json``); the keypoint
    cue's at ``keypoint_step`` (0: not timed; None: the default for the recording's frame rate), with
    ``landmark_model`` beside the tracker (the detector alone is timed with every model installed).  The body
    model and the first pose are ``model_path`` and ``init_path``, else the recording's own.  The passes of the
    figures compared are taken in turn, one of each per repeat, so that a machine whose load drifts weighs on all
    alike."""
    every, model, start = _subject(path, model_path, init_path)
    if keypoint_step is None:
        keypoint_step = default_step(every.fps)
    first = open_recording(path, [every.cameras[0].name])
    decode_ms, floors, floor_one, read = [], [], [], []
    runs_all, runs_one, runs_cue, alone = [], [], [], []
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        cache = out / "keypoints.npz"  # the last pass's detections: the landmarks the tracker is timed alone with
        for repeat in range(repeats):
            decode_ms.append(decode_cpu_ms(every))
            floors.append(decode_only(every))
            floor_one.append(decode_only_fps(first))
            runs_all.append(track_run(every, model, start, settings=settings, out=out))
            runs_one.append(track_run(first, model, start, settings=settings, out=out))
            if keypoint_step:
                kept = cache if repeat == repeats - 1 else None
                runs_cue.append(
                    track_run(
                        every,
                        model,
                        start,
                        settings=settings,
                        out=out,
                        keypoint_step=keypoint_step,
                        landmark_model=landmark_model,
                        cache=kept,
                    )
                )
                read.append(read_stage(every, model, start, settings=settings, keypoint_step=keypoint_step))
        if keypoint_step:
            alone = [
                track_stage(
                    every,
                    model,
                    start,
                    settings=settings,
                    keypoint_step=keypoint_step,
                    cache=cache,
                    landmark_model=landmark_model,
                )
                for _ in range(repeats)
            ]
        detector = detector_ms(every, settings, landmark_model=landmark_model) if keypoint_step else float("nan")
    stage_ms = {"decode": _median(decode_ms)}
    for stage in (*STAGES, "output"):
        stage_ms[stage] = _median([r.stage_ms[stage] for r in runs_all])
    stage_cue = {stage: _median([r.stage_ms[stage] for r in runs_cue]) for stage in (*STAGES, "output") if runs_cue}
    core = sum(stage_ms[s] for s in ("outline", "ownership", "measure", "solve"))
    fps_all = _median([r.fps for r in runs_all])
    decode_all = _median([floor.fps for floor in floors])
    result = {
        "recording": str(path),
        "views": len(every.cameras),
        "frames": every.frame_count,
        "iterations": settings.solve.iterations,
        "spacing_px": settings.outline.spacing,
        "repeats": repeats,
        "stage_ms_per_frame_all_views": stage_ms,
        "stage_ms_per_frame_with_keypoints": stage_cue,
        "core_ms_per_view_iteration": core / (len(every.cameras) * settings.solve.iterations),
        "fps_one_view": _median([r.fps for r in runs_one]),
        "fps_all_views": fps_all,
        "decode_only_fps_one_view": _median(floor_one),
        "decode_only_fps_all_views": decode_all,
        "ratio_one_view": _median([r.fps for r in runs_one]) / _median(floor_one),
        "ratio_all_views": fps_all / decode_all,
        "keypoint_step": keypoint_step,
        "detector_ms_per_view": detector,
        "fps_all_views_with_keypoints": _median([r.fps for r in runs_cue]) if runs_cue else float("nan"),
    }
    if not keypoint_step:
        return result
    models = [name for name in MODELS if name in installed_models() or name == landmark_model]
    detect = {name: detect_stage(every, settings, keypoint_step=keypoint_step, landmark_model=name) for name in models}
    stages = {"read": read, "detect": [detect[landmark_model]], "track": alone}
    fps = {name: _median([stage.fps for stage in timed]) for name, timed in stages.items()}
    cpu_ms = {name: _median([stage.cpu_ms for stage in timed]) for name, timed in stages.items()}
    cores = os.cpu_count() or 1
    overlapped = _median([r.fps for r in runs_cue])
    return result | {
        "landmark_model": landmark_model,
        "stage_fps_with_keypoints": {
            "decode_only": decode_all,
            "read": fps["read"],
            "detect": {name: stage.fps for name, stage in detect.items()},
            "track": fps["track"],
        },
        "stage_cpu_ms_per_frame_with_keypoints": {
            "decode_only": _median([floor.cpu_ms for floor in floors]),
            "read": cpu_ms["read"],
            "detect": {name: stage.cpu_ms for name, stage in detect.items()},
            "track": cpu_ms["track"],
        },
        "cores": cores,
        "bound_serial_fps": 1.0 / sum(1.0 / value for value in fps.values()),
        "bound_cores_fps": 1e3 * cores / sum(cpu_ms.values()),
        "ratio_bound_cores": _median([floor.cpu_ms for floor in floors]) / sum(cpu_ms.values()),
        "bound_slowest_stage_fps": min(fps.values()),
        "slowest_stage": min(fps, key=lambda name: fps[name]),
        "first_landmarks_s": _median([r.first for r in runs_cue]),
        "fps_all_views_with_keypoints_after_first": _median([r.fps_after_first for r in runs_cue]),
        "ratio_with_keypoints": overlapped / decode_all,
    }


def resident_mb() -> float:
    """This process's resident memory in MB (Linux's /proc/self/statm), or NaN where the system does not say."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return float("nan")
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


SETTLED = 500
"""The frame after which a long run's memory should stay flat: the caches, queues and buffers are full by then."""


def long_run(
    path: Path,
    total: int,
    settings: Settings = Settings(),
    *,
    keypoint_step: int | None = None,
    model_path: Path | None = None,
    init_path: Path | None = None,
    landmark_model: str = RECORDED,
    progress=lambda iterable, total=None: iterable,
) -> dict:
    """A long run for memory: ``total`` frames tracked and written to a poses.npz, the recording read again
    and again from its first frame (each pass with a fresh keypoint worker of ``landmark_model``, at
    ``keypoint_step``: 0 for none, None for the default), and this process's resident memory before the first
    frame, after frame :data:`SETTLED` and at the end.  The body jumps where a pass starts again, as a cut in a live
    session would make it; the figures are about memory and the file, not accuracy."""
    recording, model, start = _subject(path, model_path, init_path)
    if keypoint_step is None:
        keypoint_step = default_step(recording.fps)
    tracker = Tracker(model, recording.cameras, start, settings)
    tracker.warm_up()
    memory = {"start": resident_mb(), "settled": float("nan")}
    passes = _Passes(recording, total, keypoint_step, tracker, landmark_model)
    bar = iter(progress(range(total), total=total))

    def counted(frame: Tracked) -> None:
        """Advance the bar; take the memory after frame :data:`SETTLED`."""
        next(bar, None)
        if frame.index + 1 == SETTLED:
            memory["settled"] = resident_mb()

    with tempfile.TemporaryDirectory() as folder, contextlib.closing(passes.frames()) as frames:
        out = Path(folder) / "poses.npz"
        run = track_frames(tracker, frames, out, fps=recording.fps, keypoints=passes.landmarks, each=counted)
        if run.interrupted:
            raise KeyboardInterrupt  # the benchmark stops at Ctrl-C
        memory["end"] = resident_mb()
        written = len(load_poses(out)["frame"])
    return {
        "recording": str(path),
        "views": len(recording.cameras),
        "frames": run.frames,
        "frames_written": written,
        "fps": run.frames / run.seconds,
        "keypoint_step": keypoint_step,
        "resident_mb_start": memory["start"],
        "settled_frame": SETTLED,
        "resident_mb_settled": memory["settled"],
        "resident_mb_end": memory["end"],
        "resident_mb_growth_after_settled": memory["end"] - memory["settled"],
    }


@dataclass
class _Passes:
    """The frames of a long run: ``total`` frames numbered 0, 1, ..., the recording read again and again from its
    first frame (read as ``tracker`` reads them), each pass with a fresh keypoint worker at ``keypoint_step`` (0:
    none) beside it."""

    recording: Recording
    total: int
    keypoint_step: int
    tracker: Tracker
    landmark_model: str
    stream: KeypointStream | None = None  # the pass's worker
    first: int = 0  # the number of the pass's first frame

    def frames(self) -> Generator[tuple[int, list], None, None]:
        """(number, images) of every frame of every pass, each pass's worker closed as it ends."""
        done = 0
        while done < self.total:
            stop = min(self.recording.frame_count, self.total - done)
            tracker = self.tracker
            stream = _stream(
                self.recording, stop, self.keypoint_step, tracker.settings, landmark_model=self.landmark_model
            )
            self.stream, self.first = stream, done
            try:
                for _, images in tracked_frames(
                    self.stream,
                    self.recording,
                    start=0,
                    stop=stop,
                    prepare=tracker.smooth,
                    chroma=tracker.bin_colours if tracker.settings.region.on else False,
                ):
                    yield done, images
                    done += 1
            finally:
                if self.stream is not None:
                    self.stream.close()

    def landmarks(self, number: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The landmarks of frame ``number`` from its pass's worker, or None."""
        return None if self.stream is None else self.stream.get(number - self.first)


def format_long(result: dict) -> str:
    """A Markdown table of :func:`long_run`'s figures."""
    cue = schedule_words(result["keypoint_step"]) if result["keypoint_step"] else "off"
    return "\n".join(
        [
            f"Recording `{result['recording']}` read in a loop: {result['views']} views, {result['frames']} frames "
            f"tracked ({result['fps']:.0f} frames per second, keypoint cue {cue}); poses.npz holds "
            f"{result['frames_written']}.",
            "",
            "| resident memory | MB |",
            "| --- | --- |",
            f"| before the first frame | {result['resident_mb_start']:.0f} |",
            f"| after frame {result['settled_frame']} | {result['resident_mb_settled']:.0f} |",
            f"| at the end | {result['resident_mb_end']:.0f} |",
            f"| growth after frame {result['settled_frame']} | {result['resident_mb_growth_after_settled']:+.1f} |",
        ]
    )


def format_table(result: dict) -> str:
    """A Markdown table of :func:`run`'s figures."""
    names = {
        "decode": "decode to grey (CPU, all cameras, one thread)",
        "grey": "copy into the frame buffer (smoothing runs in the reader threads)",
        "outline": "outline sampling and visibility",
        "ownership": "search limits (edge ownership)",
        "measure": "edge search and Jacobians",
        "region": "region cue (colour along the lines, colours learnt)",
        "solve": "chain solve and coercion",
        "output": "output (joints, poses.npz)",
    }
    cue = result["stage_ms_per_frame_with_keypoints"]
    lines = [
        f"Recording `{result['recording']}`: {result['views']} views, {result['frames']} frames, "
        f"{result['iterations']} IRLS iterations, {result['spacing_px']:g} px spacing; "
        f"medians of {result['repeats']} passes.",
        "",
        "| stage | ms per frame (all views) |" + (" with the keypoint cue |" if cue else ""),
        "| --- | --- |" + (" --- |" if cue else ""),
    ]
    lines += [
        f"| {names[stage]} | {ms:.3f} |" + (f" {cue[stage]:.3f} |" if stage in cue else " |" if cue else "")
        for stage, ms in result["stage_ms_per_frame_all_views"].items()
    ]
    lines += [
        "",
        "| | one view | all views |",
        "| --- | --- | --- |",
        f"| tracking, frames per second | {result['fps_one_view']:.0f} | {result['fps_all_views']:.0f} |",
        f"| decode only, frames per second | {result['decode_only_fps_one_view']:.0f} | "
        f"{result['decode_only_fps_all_views']:.0f} |",
        f"| ratio tracking / decode only | {result['ratio_one_view']:.2f} | {result['ratio_all_views']:.2f} |",
        "",
        f"Tracker core (outline + ownership + measure + solve): {result['core_ms_per_view_iteration']:.3f} ms per view "
        "per IRLS iteration.",
    ]
    if result["keypoint_step"]:
        lines += [
            "",
            f"Keypoint cue: the detector takes {result['detector_ms_per_view']:.1f} ms per view; with it on "
            f"{schedule_words(result['keypoint_step'])} beside the tracker (a worker process, its start-up included), "
            f"{result['fps_all_views_with_keypoints']:.0f} frames per second with all views.",
            "",
            *format_stages(result),
        ]
    return "\n".join(lines)


def format_stages(result: dict) -> list[str]:
    """The lines of :func:`run`'s table of the stages with the keypoint cue: each alone, the bounds they set, and all
    three overlapped; each row's ratio to decoding alone by frames a second, but the cores' bound's by CPU a frame."""
    fps, cpu = result["stage_fps_with_keypoints"], result["stage_cpu_ms_per_frame_with_keypoints"]
    every, model, floor = schedule_words(result["keypoint_step"]), result["landmark_model"], fps["decode_only"]
    spent = cpu["read"] + cpu["detect"][model] + cpu["track"]
    rows: list[tuple[str, float, float | None, float]] = [  # name, frames a second, CPU ms a frame, ratio
        ("decode only (the floor)", floor, cpu["decode_only"], 1.0),
        (
            "read: decode, smoothing, colours and the detector's copies, as the tracker's readers do",
            fps["read"],
            cpu["read"],
            fps["read"] / floor,
        ),
        *(
            (
                f"detect {every}, {name} model{' (beside the tracker)' if name == model else ''}",
                rate,
                cpu["detect"][name],
                rate / floor,
            )
            for name, rate in fps["detect"].items()
        ),
        (
            "track with the landmarks (frames and landmarks read beforehand)",
            fps["track"],
            cpu["track"],
            fps["track"] / floor,
        ),
        (
            f"bound: read, detect ({model}) and track one after the other",
            result["bound_serial_fps"],
            None,
            result["bound_serial_fps"] / floor,
        ),
        (
            f"bound: the {result['cores']} cores over the three stages' CPU",
            result["bound_cores_fps"],
            spent,
            result["ratio_bound_cores"],
        ),
        (
            f"bound: the slowest stage ({result['slowest_stage']})",
            result["bound_slowest_stage_fps"],
            None,
            result["bound_slowest_stage_fps"] / floor,
        ),
        (
            "overlapped, the worker's start-up included",
            result["fps_all_views_with_keypoints"],
            None,
            result["ratio_with_keypoints"],
        ),
        (
            f"overlapped, from the first landmarks on ({result['first_landmarks_s']:.2f} s into the loop)",
            result["fps_all_views_with_keypoints_after_first"],
            None,
            result["fps_all_views_with_keypoints_after_first"] / floor,
        ),
    ]
    return [
        "| with the keypoint cue, all views | frames per second | CPU ms a frame | / decode only |",
        "| --- | --- | --- | --- |",
        *(
            f"| {name} | {rate:.1f} | {'' if ms is None else f'{ms:.1f}'} | {ratio:.2f} |"
            for name, rate, ms, ratio in rows
        ),
        "",
        "The cores' bound is compared with decoding alone by their CPU a frame, which the machine's other load changes "
        "little; the other rows by their frames a second.",
    ]


def _copies(data: dict, copies: int, keep=None) -> dict:
    """A model TOML document with ``copies`` bodies side by side: copy k's names get ``_k``, and
    every copy's root hangs on the first root by a free joint (independent bodies, one tree).
    ``keep`` limits each body to the named components."""
    components = []
    root = next(c["name"] for c in data["component"] if not c.get("parent"))
    for k in range(copies):
        for spec in data["component"]:
            if keep is not None and spec["name"] not in keep:
                continue
            spec = dict(spec, name=f"{spec['name']}_{k}")
            if spec.get("parent"):
                spec["parent"] = f"{spec['parent']}_{k}"
            elif k > 0:
                spec.update(parent=f"{root}_0", joint="free")
            components.append(spec)
    return {"name": f"{data.get('name', 'model')} x{copies}", "component": components}


def _core_ms(tracker: Tracker, repeats: int, poses) -> tuple[float, int]:
    """Median milliseconds of one IRLS iteration's core stages at fixed poses, and the sample count."""
    times = []
    for _ in range(repeats):
        tracker.poses = poses.copy()
        tracker.work.times = StageTimes()
        tracker.iterate()
        times.append(sum(v for k, v in tracker.work.times.seconds.items() if k != "grey") * 1e3)
    return _median(times), tracker.work.samples.count


def _side_by_side(model: Model, single: Model, copies: int) -> np.ndarray:
    """Rest poses of ``copies`` bodies standing 0.8 m apart along x, in ``model``'s order
    (``single`` is copy 0 alone, names ending in ``_0``)."""
    by_name = {}
    for k in range(copies):
        root = se3.from_rotvec([0.0, 0.0, 0.0], [0.8 * (k - (copies - 1) / 2), 0.0, 0.95])
        for name, pose in zip(single.names, rest_poses(single, root)):
            by_name[f"{name[:-2]}_{k}"] = pose
    return np.stack([by_name[name] for name in model.names])


def scaling(repeats: int = 50) -> dict:
    """Core cost of one IRLS iteration against the number of components (bodies side by side in the
    demo's three views) and against the number of cameras (1 to 8 around one body)."""
    data = tomllib.loads(HUMAN.read_text())
    demo = open_recording(DEMO)
    _, images = next(frames(demo))
    lower = {"pelvis", "thigh_l", "thigh_r", "shin_l", "shin_r", "foot_l", "foot_r"}
    rows_components = []
    for copies, keep in ((1, lower), (1, None), (2, None), (4, None), (8, None)):
        model = model_from_dict(_copies(data, copies, keep))
        single = model_from_dict(_copies(data, 1, keep))
        tracker = Tracker(model, demo.cameras, _side_by_side(model, single, copies))
        tracker.load_images(images)
        tracker.warm_up()
        ms, samples = _core_ms(tracker, repeats, tracker.poses)
        rows_components.append(
            {
                "components": model.size,
                "views": len(demo.cameras),
                "samples": samples,
                "ms_per_iteration": ms,
                "ms_per_component": ms / model.size,
            }
        )
    human = model_from_dict(data)
    body = rest_poses(human, se3.from_rotvec([0.0, 0.0, 0.0], [0.0, 0.0, 0.95]))
    ring = [
        look_at_camera(f"ring{k}", (4.0 * np.cos(a), 4.0 * np.sin(a), 1.2 + 0.3 * (k % 2)), (0.0, 0.0, 0.9))
        for k, a in enumerate(np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False))
    ]
    rng = np.random.default_rng(0)
    views = [cv2.cvtColor(Renderer(human, camera).render(body, rng), cv2.COLOR_BGR2GRAY) for camera in ring]
    rows_cameras = []
    for count in range(1, 9):
        tracker = Tracker(human, ring[:count], body)
        tracker.load_images(views[:count])
        tracker.warm_up()
        ms, samples = _core_ms(tracker, repeats, tracker.poses)
        rows_cameras.append(
            {
                "views": count,
                "components": human.size,
                "samples": samples,
                "ms_per_iteration": ms,
                "ms_per_view": ms / count,
            }
        )
    return {"components": rows_components, "cameras": rows_cameras, "repeats": repeats}


def format_scaling(result: dict) -> str:
    """Markdown tables of :func:`scaling`."""
    lines = [
        "Core of one IRLS iteration (outline, ownership, measurement, solve), median of "
        f"{result['repeats']} at fixed poses.",
        "",
        "| components | views | samples | ms per iteration | ms per component |",
        "| --- | --- | --- | --- | --- |",
    ]
    lines += [
        f"| {r['components']} | {r['views']} | {r['samples']} | {r['ms_per_iteration']:.3f} | "
        f"{r['ms_per_component']:.4f} |"
        for r in result["components"]
    ]
    lines += [
        "",
        "| views | components | samples | ms per iteration | ms per view |",
        "| --- | --- | --- | --- | --- |",
    ]
    lines += [
        f"| {r['views']} | {r['components']} | {r['samples']} | {r['ms_per_iteration']:.3f} | {r['ms_per_view']:.3f} |"
        for r in result["cameras"]
    ]
    return "\n".join(lines)
