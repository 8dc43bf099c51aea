"""Recording folders (formats.md): the calibration, one video or image folder per camera, optional extras.

    NAME/calibration.toml                 required
    NAME/<camera name>.mp4|.avi|.mkv      a video per camera ...
    NAME/<camera name>/000000.png ...     ... or a folder of numbered .png/.jpg images
    NAME/model.toml, init.toml, truth.npz optional
    NAME/timestamps.csv                   optional: capture times (``tracker live --record``, caliscope)
    NAME/sync.toml                        optional: the cameras' time offsets (``tracker sync``)

Every camera of the calibration that has a video is tracked (a warning names
those without one), unless a list of camera names picks some. All videos must
have the same number of frames and the image size the calibration gives.  A
recording whose cameras are not frame-locked (sync.toml, else timestamps.csv) is
read with each camera's frame nearest in time to each frame of the first camera
(:mod:`tracker.io.pairing`).
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from tracker.camera import Camera, load_calibration
from tracker.errors import TrackerInputError
from tracker.io.pairing import Pairing, by_offsets, by_times
from tracker.io.readers import ColourCopies, image_files, read_frames, read_image
from tracker.io.sync_file import FILE as SYNC
from tracker.io.sync_file import load_offsets
from tracker.io.timestamps import camera_times

VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv")
DEFAULT_FPS = 30.0  # for image folders, videos and camera devices that do not state a frame rate


@dataclass
class Recording:
    """An opened recording folder; ``cameras`` and ``sources`` (video file or image folder) are parallel."""

    path: Path
    cameras: list[Camera]
    model_path: Path | None
    init_path: Path | None
    truth_path: Path | None
    frame_count: int
    fps: float
    sources: list[Path]
    timestamps_path: Path | None = None
    calibration_path: Path | None = None
    pairing: Pairing | None = None  # each camera's frame read for each frame, when the cameras are not frame-locked
    picked: bool = False  # the cameras are a pick (--cameras), not every camera with a video in calibration order


def open_recording(
    path: str | os.PathLike,
    cameras: list[str] | None = None,
    calibration: str | os.PathLike | None = None,
    *,
    paired: bool = True,
) -> Recording:
    """Open a recording folder, checking that its videos decode and agree with the calibration.

    ``cameras`` picks cameras by name (in that order), each of which must have a
    video; by default every camera in calibration.toml that has a video, in
    calibration order, with a warning naming those that have none. The first frame
    of every video is decoded here, so a corrupt file fails now rather than
    mid-run. ``calibration`` replaces the folder's calibration.toml (e.g. a rig
    refined by ``tracker refine``). With ``paired`` (default) each camera's frames are paired with the first
    camera's by the folder's sync.toml, else by its timestamps.csv (:func:`pairing`); ``tracker sync``, which
    finds the offsets, reads them as recorded. Problems raise TrackerInputError naming the file.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise TrackerInputError(
            f"{folder}: recording folder not found; give a folder holding calibration.toml and one video per camera"
        )
    if calibration is None:
        calibration = folder / "calibration.toml"
        if not calibration.is_file():
            raise TrackerInputError(
                f"{calibration}: not found; a recording folder needs the calibration of its cameras"
            )
    calibration = Path(calibration)
    rig = {camera.name: camera for camera in load_calibration(calibration)}
    sources = {name: _find_source(folder, name) for name in rig}
    available = [name for name, source in sources.items() if source is not None]
    available_text = ", ".join(available) or "none"
    if cameras is None:
        if not available:
            raise TrackerInputError(
                f"{folder}: no camera of {calibration.name} ({', '.join(rig)}) has a video; "
                f"add <name>{'|'.join(VIDEO_SUFFIXES)} or a folder <name>/ of numbered images"
            )
        chosen = available
        absent = [name for name in rig if sources[name] is None]
        if absent:
            which = f"camera {absent[0]} has" if len(absent) == 1 else f"cameras {', '.join(absent)} have"
            warnings.warn(
                f"{folder}: {which} no video, leaving {available_text} of {calibration.name}; add "
                f"<name>{'|'.join(VIDEO_SUFFIXES)} or a folder <name>/ of numbered images, or pick the cameras with "
                "--cameras to say so",
                stacklevel=2,
            )
    else:
        chosen = list(dict.fromkeys(cameras))
        if not chosen:
            raise TrackerInputError(
                f"{folder}: the list of cameras names none; pick cameras with a video from: {available_text}, "
                "or leave --cameras out to track them all"
            )
        for name in chosen:
            if name not in rig:
                raise TrackerInputError(
                    f"{calibration}: has no camera {name!r}; pick cameras with a video from: {available_text}"
                )
            if sources[name] is None:
                raise TrackerInputError(
                    f"{folder / name}{'|'.join(VIDEO_SUFFIXES)}: no video for camera {name!r}; "
                    f"add it or pick cameras with a video from: {available_text}"
                )

    chosen_sources = cast(list[Path], [sources[name] for name in chosen])  # each has a source: checked above
    probes = [_probe(source, rig[name]) for name, source in zip(chosen, chosen_sources)]
    counts = [count for count, _, _ in probes]
    for source, count in zip(chosen_sources, counts):
        if count != counts[0]:
            raise TrackerInputError(
                f"{chosen_sources[0]} has {counts[0]} frames but {source} has {count}; "
                "cut the videos to the same synchronised frames"
            )
    fps = next((rate for _, rate, _ in probes if rate is not None), DEFAULT_FPS)

    def optional(name: str) -> Path | None:
        return folder / name if (folder / name).is_file() else None

    recording = Recording(
        path=folder,
        calibration_path=calibration,
        cameras=[camera for _, _, camera in probes],
        model_path=optional("model.toml"),
        init_path=optional("init.toml"),
        truth_path=optional("truth.npz"),
        frame_count=counts[0],
        fps=fps,
        sources=chosen_sources,
        timestamps_path=optional("timestamps.csv"),
        picked=chosen != available,
    )
    return dataclasses.replace(recording, pairing=pairing(recording)) if paired else recording


def pairing(recording: Recording) -> Pairing | None:
    """Which frame of each camera shows each frame of ``recording`` (:mod:`tracker.io.pairing`): by the offsets of
    its sync.toml, else by the capture times of its timestamps.csv; None when it has neither, or when every
    camera's frame n is read for frame n, captured at frame n's time."""
    names = [camera.name for camera in recording.cameras]
    if (recording.path / SYNC).is_file():
        duration = recording.frame_count / recording.fps
        offsets = load_offsets(recording.path / SYNC, rig_names(recording), duration)
        found = by_offsets(np.array([offsets[name] for name in names]), count=recording.frame_count, fps=recording.fps)
    elif recording.timestamps_path is not None:
        times = _camera_times(recording)
        found = by_times(times, _reference(times, recording.timestamps_path))
    else:
        return None
    return None if found.frame_locked else found


def frames(
    recording: Recording,
    start: int = 0,
    stop: int | None = None,
    *,
    prepare=None,
    colour: bool = False,
    step: int = 1,
    copies: list[ColourCopies] | None = None,
    chroma: bool | Callable[[np.ndarray], np.ndarray] = False,
) -> Iterator[tuple[int, list]]:
    """Yield (frame index, grey uint8 images (H, W), one per camera) for frames start..stop-1 (every
    ``step``-th of them: the others are skipped undecoded where the container allows).

    One reader thread per camera decodes ahead (see :mod:`tracker.io.readers`), in colour (BGR (H, W, 3))
    with ``colour``, and applies ``prepare`` (image -> anything; or one per camera) if given; the frames
    ``copies`` (one per camera) names also come with their reduced colour image (:class:`WithColour`), and with
    ``chroma`` every frame with its half-size colour image (:class:`WithChroma`; a callable ``chroma`` applied to
    it in the reader thread). A frame that
    fails to decode raises TrackerInputError naming the file and the index.
    """
    stop = recording.frame_count if stop is None else stop
    if not 0 <= start <= stop <= recording.frame_count:
        raise TrackerInputError(
            f"{recording.path}: frames {start}..{stop} are outside the recording's 0..{recording.frame_count}; "
            "pick a range inside it"
        )
    return read_frames(
        recording.sources,
        start,
        stop,
        prepare=prepare,
        colour=colour,
        step=step,
        copies=copies,
        chroma=chroma,
        pairing=None if recording.pairing is None else recording.pairing.frames,
    )


def camera_frames(recording: Recording, index: int) -> list[int]:
    """Each camera's frame that shows the recording's frame ``index`` (its own frame ``index``, unless the cameras'
    frames are paired by time: :attr:`Recording.pairing`)."""
    if recording.pairing is None:
        return [index] * len(recording.cameras)
    return [int(frame) for frame in recording.pairing.frames[index]]


def capture_times(recording: Recording) -> np.ndarray | None:
    """Each frame's capture time in seconds, the first camera's (:func:`tracker.io.timestamps.camera_times`; where it
    has none, the median of the other cameras'), or None when the recording has no timestamps.csv."""
    if recording.timestamps_path is None:
        return None
    return _reference(_camera_times(recording), recording.timestamps_path)


def _camera_times(recording: Recording) -> np.ndarray:
    """Each camera's capture time (F, C) of each frame, from the recording's timestamps.csv."""
    assert recording.timestamps_path is not None  # asked for by recordings that have one
    names = [camera.name for camera in recording.cameras]
    return camera_times(recording.timestamps_path, names, rig=rig_names(recording), frames=recording.frame_count)


def rig_names(recording: Recording) -> list[str]:
    """The names of every camera of the recording's calibration, also those not picked (``--cameras``): a file
    naming one of them is not wrong."""
    if recording.calibration_path is None:
        return [camera.name for camera in recording.cameras]
    return [camera.name for camera in load_calibration(recording.calibration_path)]


def _reference(times: np.ndarray, path: Path) -> np.ndarray:
    """The frames' times (F,): the first camera's, where it has none the median of the others' (``times`` (F, C) from
    the file at ``path``)."""
    reference = times[:, 0].copy()
    missing = ~np.isfinite(reference)
    if missing.any():
        if not np.isfinite(times[missing]).any(axis=1).all():
            frame = int(np.flatnonzero(missing & ~np.isfinite(times).any(axis=1))[0])
            raise TrackerInputError(f"{path}: no camera has a time for frame {frame}; fix it or remove it")
        reference[missing] = np.nanmedian(times[missing], axis=1)
    return reference


def _find_source(folder: Path, name: str) -> Path | None:
    """The video file or image folder of camera ``name``, None if there is none."""
    found = [folder / f"{name}{suffix}" for suffix in VIDEO_SUFFIXES if (folder / f"{name}{suffix}").is_file()]
    if (folder / name).is_dir() and image_files(folder / name):
        found.append(folder / name)
    if len(found) > 1:
        raise TrackerInputError(
            f"{folder}: camera {name!r} has several sources ({', '.join(path.name for path in found)}); keep one"
        )
    return found[0] if found else None


def _probe(source: Path, camera: Camera) -> tuple[int, float | None, Camera]:
    """Frame count, frame rate (None if unknown) and the camera fitted to the decoded size (:func:`_fit_size`)."""
    if source.is_dir():
        files = image_files(source)
        return len(files), None, _fit_size(files[0], read_image(files[0], 0), camera)
    capture = cv2.VideoCapture(str(source))
    try:
        ok, image = capture.read() if capture.isOpened() else (False, None)
        if not ok:
            raise TrackerInputError(
                f"{source}: corrupt or unsupported video (its first frame does not decode); "
                "re-encode it, e.g. as H.264 .mp4"
            )
        assert image is not None  # ok: the frame decoded
        camera = _fit_size(source, image, camera)
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if count <= 0:  # the container does not say: count by decoding
            count = 1
            while capture.grab():
                count += 1
        fps = capture.get(cv2.CAP_PROP_FPS)
        return count, fps if np.isfinite(fps) and fps > 0 else None, camera
    finally:
        capture.release()


def _fit_size(file: Path, image: np.ndarray, camera: Camera) -> Camera:
    """The camera as the file's frames show it.

    Video codecs work on 16 x 16 blocks: an encoder pads a frame to a multiple of 16
    and the container crops the padding away on the right and at the bottom, so a
    calibration made on the padded frames (1088 rows) may meet videos that decode
    to 1080.  Such a crop leaves every remaining pixel where it was, so when the
    decoded frame is smaller by less than 16 pixels in each direction the camera
    keeps its intrinsics and takes the decoded size (with a warning); any other
    difference is an error.
    """
    height, width = image.shape[:2]
    if (width, height) == camera.size:
        return camera
    cut_w, cut_h = camera.size[0] - width, camera.size[1] - height
    if 0 <= cut_w < 16 and 0 <= cut_h < 16:
        warnings.warn(
            f"{file}: decodes as {width}x{height} but camera {camera.name!r} is calibrated at "
            f"{camera.size[0]}x{camera.size[1]}; taking the difference for codec padding cropped at the "
            "right and bottom (intrinsics unchanged)",
            stacklevel=2,
        )
        return dataclasses.replace(camera, size=(width, height))
    raise TrackerInputError(
        f"{file}: image size {width}x{height} differs from size {camera.size[0]}x{camera.size[1]} of camera "
        f"{camera.name!r} in calibration.toml; use the calibration made for these videos"
    )


def recording_files(folder: str | os.PathLike) -> list[Path]:
    """What makes ``folder`` a recording, if it is one: its calibration.toml and the cameras' videos in it (none when
    it holds neither, or is not a folder; hidden files, such as a writer's unfinished ones, do not count)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(
        path
        for path in folder.iterdir()
        if path.is_file()
        and not path.name.startswith(".")
        and (path.name == "calibration.toml" or path.suffix.lower() in VIDEO_SUFFIXES)
    )
