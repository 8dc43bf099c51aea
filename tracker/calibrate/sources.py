"""The cameras of a calibration folder and the board corners found in their frames.

A calibration folder holds one video (``<cam>.mp4|.avi|.mkv``) or one folder of numbered images
(``<cam>/``) per camera, frame-synchronous: frame i of every camera was taken at the same moment.
Cameras are named after their files and sorted by name. Long recordings are subsampled: every
k-th frame is searched, k = ceil(frames / max_frames), the same frames in every camera.
"""

from __future__ import annotations

import math
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
from tqdm import tqdm

from tracker.calibrate.board import Board, Detection
from tracker.errors import TrackerInputError
from tracker.io.readers import IMAGE_SUFFIXES, grey, image_files, read_image
from tracker.io.recording import VIDEO_SUFFIXES


@dataclass
class CameraViews:
    """One camera's source, image size and board detections by frame index."""

    name: str
    source: Path
    size: tuple[int, int] = (0, 0)  # width, height
    searched: int = 0  # frames searched for the board
    detections: dict[int, Detection] = field(default_factory=dict)


def find_sources(folder: str | Path) -> list[CameraViews]:
    """The cameras of a calibration folder, sorted by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise TrackerInputError(f"{folder}: not a folder; give the folder holding one video or image folder per camera")
    found: dict[str, list[Path]] = {}
    for path in sorted(folder.iterdir()):
        if path.name.startswith("."):
            continue
        if path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES:
            found.setdefault(path.stem, []).append(path)
        elif path.is_dir() and any(child.suffix.lower() in IMAGE_SUFFIXES for child in path.iterdir()):
            found.setdefault(path.name, []).append(path)
    if not found:
        raise TrackerInputError(
            f"{folder}: no camera videos (.mp4, .avi, .mkv) or image folders; put one per camera there, "
            "named after the camera"
        )
    for name, paths in found.items():
        if len(paths) > 1:
            raise TrackerInputError(
                f"{folder}: camera {name!r} has several sources ({', '.join(p.name for p in paths)}); keep one"
            )
    return [CameraViews(name, paths[0]) for name, paths in sorted(found.items())]


def frame_count(source: Path) -> int:
    """Frames in a video (as its container says) or image folder."""
    if source.is_dir():
        return len(image_files(source))
    capture = cv2.VideoCapture(str(source))
    try:
        if not capture.isOpened():
            raise TrackerInputError(f"{source}: cannot open the video; re-encode it (e.g. as H.264 .mp4)")
        return int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        capture.release()


def _frames(source: Path, stride: int):
    """(index, grey image) of frames 0, stride, 2 stride, ... of a source."""
    if source.is_dir():
        for index, file in enumerate(image_files(source)):
            if index % stride == 0:
                yield index, read_image(file, index, cv2.IMREAD_GRAYSCALE)
        return
    capture = cv2.VideoCapture(str(source))
    try:
        index = 0
        while True:
            if index % stride == 0:
                ok, image = capture.read()
                if not ok:
                    return
                yield index, grey(image)
            elif not capture.grab():
                return
            index += 1
    finally:
        capture.release()


def detect_all(
    board: Board, cameras: list[CameraViews], *, max_frames: int = 300, workers: int = 2, progress: bool = True
) -> None:
    """Search every camera's frames for the board (subsampled to about ``max_frames`` per camera),
    filling in each CameraViews; cameras run in parallel threads (OpenCV releases the GIL).  An error in
    one camera or Ctrl-C stops the others after their current frame."""
    counts = [frame_count(camera.source) for camera in cameras]
    stride = max(1, math.ceil(max(counts) / max_frames)) if counts else 1
    bar = tqdm(
        total=sum(math.ceil(count / stride) for count in counts),
        unit="frame",
        desc="board search",
        disable=not progress,
        leave=False,
    )
    lock = threading.Lock()
    stop = threading.Event()

    def work(camera: CameraViews) -> None:
        try:
            search(camera)
        except BaseException:
            stop.set()  # at once: the pool's thread may take up the next camera before the caller sees the error
            raise

    def search(camera: CameraViews) -> None:
        detector = board.detector()
        for index, image in _frames(camera.source, stride):
            if stop.is_set():
                return
            if camera.searched == 0:
                camera.size = (image.shape[1], image.shape[0])
            elif (image.shape[1], image.shape[0]) != camera.size:
                raise TrackerInputError(
                    f"{camera.source}: frame {index} is {image.shape[1]}x{image.shape[0]} but frame 0 is "
                    f"{camera.size[0]}x{camera.size[1]}; give every frame of a camera the same size"
                )
            camera.searched += 1
            detection = detector.detect(image)
            if detection is not None:
                camera.detections[index] = detection
            with lock:
                bar.update(1)
        if camera.searched == 0:
            raise TrackerInputError(f"{camera.source}: no frames could be read; re-encode the video or add images")

    pool = ThreadPoolExecutor(max_workers=max(1, workers))
    try:
        for future in [pool.submit(work, camera) for camera in cameras]:
            future.result()
    finally:
        stop.set()
        pool.shutdown(wait=True, cancel_futures=True)
        bar.close()
