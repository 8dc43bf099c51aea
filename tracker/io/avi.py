"""A Motion-JPEG AVI writer with a quality setting (OpenCV's writers ignore it or compress poorly)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import cv2
import numpy as np

from tracker.errors import TrackerInputError


class MjpegAviWriter:
    """A minimal AVI 1.0 (RIFF) writer of Motion-JPEG frames encoded by libjpeg (``cv2.imencode``).

    OpenCV's built-in MJPEG writer compresses poorly (about twice the bytes at
    equal quality) and its FFMPEG writer ignores the quality property; this one
    writes baseline JPEGs with 4:2:0 chroma and optimised Huffman tables at
    ``quality`` (0..100), plus an ``idx1`` index, which OpenCV and ffmpeg read.
    Frames are written to ``path`` as they come; :meth:`close` patches the sizes.
    """

    _MAX_BYTES = 1 << 30  # AVI 1.0 RIFF limit (no OpenDML extension here)

    def __init__(self, path: str | os.PathLike, fps: float, size: tuple[int, int], quality: int = 70):
        self.path = Path(path)
        self.width, self.height = int(size[0]), int(size[1])
        self.rate, self.scale = (round(fps), 1) if abs(fps - round(fps)) < 1e-3 else (round(fps * 1000), 1000)
        self.params = [
            cv2.IMWRITE_JPEG_QUALITY,
            int(quality),
            cv2.IMWRITE_JPEG_OPTIMIZE,
            1,
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
        ]
        self.index: list[tuple[int, int]] = []  # (offset from 'movi', size) per frame
        self.max_frame = 0
        self.file = open(self.path, "wb")
        self._write_headers()

    def _write_headers(self) -> None:
        w, h = self.width, self.height
        avih = struct.pack("<14I", round(1e6 * self.scale / self.rate), 0, 0, 0x10, 0, 0, 1, 0, w, h, 0, 0, 0, 0)
        strh = struct.pack(
            "<4s4sIHHIIIIIIIIhhhh",
            b"vids",
            b"MJPG",
            0,
            0,
            0,
            0,
            self.scale,
            self.rate,
            0,
            0,
            0,
            0xFFFFFFFF,
            0,
            0,
            0,
            w,
            h,
        )
        strf = struct.pack("<IiiHH4sIiiII", 40, w, h, 1, 24, b"MJPG", w * h * 3, 0, 0, 0, 0)
        strl = b"strl" + _chunk(b"strh", strh) + _chunk(b"strf", strf)
        hdrl = b"hdrl" + _chunk(b"avih", avih) + _chunk(b"LIST", strl)
        self.file.write(b"RIFF\0\0\0\0AVI " + _chunk(b"LIST", hdrl))
        self.movi_at = self.file.tell()  # position of the movi LIST header
        self.file.write(b"LIST\0\0\0\0movi")

    def write(self, image: np.ndarray) -> None:
        """Append one BGR (or grey) uint8 frame of the writer's size."""
        if image.shape[0] != self.height or image.shape[1] != self.width:
            raise ValueError(f"frame {image.shape} does not match the video size {self.width}x{self.height}")
        ok, buffer = cv2.imencode(".jpg", image, self.params)
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        self.write_jpeg(buffer.tobytes())

    def fits(self, size: int) -> bool:
        """Whether a frame of ``size`` JPEG bytes still fits in the 1 GiB an AVI 1.0 file can hold."""
        return self.file.tell() + 8 + size + 1 + 16 * (len(self.index) + 1) <= self._MAX_BYTES

    def write_jpeg(self, data: bytes) -> None:
        """Append one frame that is already a JPEG of the writer's size, byte for byte (a camera's
        Motion-JPEG frame is stored as it came, so reading the video back decodes the same image)."""
        if not self.fits(len(data)):
            raise TrackerInputError(f"{self.path}: the video would pass 1 GiB (AVI 1.0 limit); render fewer frames")
        offset = self.file.tell() - (self.movi_at + 8)
        # header, data and padding written one by one, so the (large) JPEG is not copied into a chunk
        self.file.write(b"00dc" + struct.pack("<I", len(data)))
        self.file.write(data)
        if len(data) % 2:
            self.file.write(b"\0")
        self.index.append((offset, len(data)))
        self.max_frame = max(self.max_frame, len(data))

    def close(self) -> None:
        """Write the index and patch the header sizes and frame counts."""
        if self.file.closed:
            return
        f = self.file
        movi_end = f.tell()
        f.write(b"idx1" + struct.pack("<I", 16 * len(self.index)))
        for offset, size in self.index:
            f.write(struct.pack("<4sIII", b"00dc", 0x10, offset, size))
        end = f.tell()
        frames = len(self.index)
        f.seek(4)
        f.write(struct.pack("<I", end - 8))
        f.seek(self.movi_at + 4)
        f.write(struct.pack("<I", movi_end - self.movi_at - 8))
        # avih: RIFF(12) + LIST hdrl header(8) + 'hdrl'(4) + 'avih' chunk header(8) = 32
        f.seek(32 + 4 * 4)
        f.write(struct.pack("<I", frames))
        f.seek(32 + 4 * 7)
        f.write(struct.pack("<I", self.max_frame + 8))
        # strh: after avih (56) + LIST strl header (8) + 'strl' (4) + 'strh' chunk header (8)
        strh = 32 + 56 + 8 + 4 + 8
        f.seek(strh + 32)
        f.write(struct.pack("<II", frames, self.max_frame + 8))
        f.close()

    def __enter__(self) -> MjpegAviWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _chunk(fourcc: bytes, data: bytes) -> bytes:
    """A RIFF chunk: fourcc, little-endian size, data, padded to an even length."""
    return fourcc + struct.pack("<I", len(data)) + data + (b"\0" if len(data) % 2 else b"")
