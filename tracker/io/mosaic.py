"""Videos of several cameras side by side (``tracker track --overlay``).

Each frame is one row of tiles, one per camera, scaled to a common height so
that the row is at most ``max_width`` pixels wide.  The video is written to a
temporary file beside the target and renamed over it when closed (also after
Ctrl-C), so the target is either absent or a complete, playable video of the
frames written.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from tracker.atomic import ensure_writable_folder, replace_with, temporary_beside
from tracker.errors import TrackerInputError

CODECS = {".mp4": "mp4v", ".avi": "MJPG", ".mkv": "MJPG"}


class MosaicWriter:
    """Writes rows of RGB camera images as one video at ``fps``."""

    def __init__(self, path: str | os.PathLike, sizes: list[tuple[int, int]], fps: float, max_width: int = 1920):
        self.path = Path(path)
        codec = CODECS.get(self.path.suffix.lower())
        if codec is None:
            raise TrackerInputError(f"{self.path}: unknown video type; name it .mp4, .avi or .mkv")
        ensure_writable_folder(self.path.parent)
        height = min(h for _, h in sizes)
        widths = [round(w * height / h) for w, h in sizes]
        scale = min(1.0, max_width / sum(widths))
        self.height = max(2, int(height * scale) // 2 * 2)
        self.widths = [max(2, int(w * scale) // 2 * 2) for w in widths]
        self.temp = temporary_beside(self.path)
        self.writer = cv2.VideoWriter(
            str(self.temp), cv2.VideoWriter.fourcc(*codec), fps, (sum(self.widths), self.height)
        )
        if not self.writer.isOpened():
            raise TrackerInputError(f"{self.path}: OpenCV cannot write this video type here; try .avi")
        self.frames = 0

    def write(self, images: list[np.ndarray]) -> None:
        """One frame: RGB uint8 images in camera order."""
        row = np.hstack(
            [cv2.resize(image, (w, self.height), interpolation=cv2.INTER_AREA) for image, w in zip(images, self.widths)]
        )
        self.writer.write(cv2.cvtColor(row, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> None:
        """Finish the video and put it in place (nothing is left behind if no frame was written)."""
        self.writer.release()
        if not self.frames:
            self.temp.unlink(missing_ok=True)
            return
        replace_with(self.temp, self.path)
