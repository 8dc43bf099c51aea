"""Tracking results: the ``poses.npz`` writer and the loader for ``poses.npz`` and ``truth.npz``.

Arrays (formats.md), F frames, N components, J joints:

    frame (F,) int64            frame index in the recording
    time (F,) float64           (frame - frame[0]) / fps, seconds
    component_names (N,) str    unicode array, loads without pickle
    poses (F, N, 4, 4) float64  world_from_component
    joint_names (J,) str
    joints (F, J, 3) float64    joint centres in world, metres
    status (F,) int8            0 tracked, 1 uncertain, 2 lost, 3 re-seeded from the keypoints
    held (F, N) int8            per part 0 held by the images, 1 loosely held, 2 unseen: carried by the
                                prior and the joints alone (tracker.status; written by tracker track)
    residual (F,) float64       robust mean edge distance, pixels (tracker points: the RMS
                                marker-to-node distance, mm)

The writer rewrites the whole file atomically, after ``flush_every`` new frames
or a quarter more frames than the file holds (whichever is more), and on close,
so a reader, or a run stopped with Ctrl-C, always finds a valid file of the
frames done. Each flush rewrites every frame so far (about 2.3 kB a frame for 15
components), and the growing interval keeps the total written at about five
times the final file, however long the run.  The rows themselves wait on disk, in
one raw file per array in a temporary folder, and each flush streams them into the
archive in chunks: the writer's memory stays the same through a session of hours.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import weakref
import zipfile
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from tracker.atomic import atomic_write, ensure_writable_folder
from tracker.errors import TrackerInputError
from tracker.npzfile import read_npz
from tracker.status import HELD, LOOSE, LOST, RESEEDED, TRACKED, UNCERTAIN, UNSEEN

_BUFFER = 256
"""Rows a writer holds in memory before appending them to its raw files."""

_KEYS = (
    "frame",
    "time",
    "component_names",
    "poses",
    "joint_names",
    "joints",
    "status",
    "held",
    "residual",
    "elapsed",
)
"""The archive's arrays, in its order."""

_CHUNK = 1 << 22
"""Bytes of a raw file copied into the archive at a time."""


def flush_due(unflushed: int, count: int, every: int) -> bool:
    """Whether a writer that rewrites its whole file should flush, holding ``count`` frames of which
    ``unflushed`` are new: after a quarter more frames than the file holds (at least ``every``), which
    keeps the bytes written in a long run proportional to its length."""
    return unflushed >= max(every, (count - unflushed) // 4)


class PosesWriter:
    """Collects one row per tracked frame and keeps ``path`` (poses.npz) up to date.

    Use as a context manager: leaving the ``with`` block, also through an
    exception or KeyboardInterrupt, writes the frames done.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        component_names: list[str],
        joint_names: list[str],
        fps: float,
        flush_every: int = 25,
    ) -> None:
        if not fps > 0 or not np.isfinite(fps):
            raise ValueError(f"fps must be positive and finite, got {fps}")
        self.path = Path(path)
        ensure_writable_folder(self.path.parent)
        self.fps = float(fps)
        self.flush_every = flush_every
        self._component_names = np.array(component_names, dtype=str)
        self._joint_names = np.array(joint_names, dtype=str)
        n, j = len(component_names), len(joint_names)
        self._buffer: dict[str, np.ndarray] = {
            "frame": np.empty(_BUFFER, np.int64),
            "poses": np.empty((_BUFFER, n, 4, 4), np.float64),
            "joints": np.empty((_BUFFER, j, 3), np.float64),
            "status": np.empty(_BUFFER, np.int8),
            "held": np.empty((_BUFFER, n), np.int8),
            "residual": np.empty(_BUFFER, np.float64),
            "elapsed": np.empty(_BUFFER, np.float64),
            "time": np.empty(_BUFFER, np.float64),
        }
        self._rows = Path(tempfile.mkdtemp(prefix="poses-rows-"))
        self._removal = weakref.finalize(self, shutil.rmtree, self._rows, True)
        self._first_frame = 0
        self._timed: bool | None = None  # whether rows come with their own times (all or none)
        self._parted: bool | None = None  # whether rows say which parts the images hold (all or none)
        self._count = 0
        self._on_disk = 0
        self._buffered = 0
        self._unflushed = 0
        self._closed = False

    def __len__(self) -> int:
        return self._count

    def append(
        self,
        frame_index: int,
        poses: np.ndarray,
        joints: np.ndarray,
        *,
        status: int,
        residual: float,
        elapsed: float = np.nan,
        time: float | None = None,
        held: np.ndarray | None = None,
    ) -> None:
        """Add one frame: poses (N, 4, 4) world_from_component, joints (J, 3), status 0-3, residual px,
        the seconds the tracker spent on it (NaN if unknown), for frames taken at measured times (live
        capture) its time in seconds (without times, time = (frame - first frame) / fps), and which parts the
        images hold, ``held`` (N,) codes 0-2 (:data:`tracker.status.HELD`, ...), given for every frame or none."""
        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        if self._timed is None:
            self._timed = time is not None
        elif self._timed != (time is not None):
            raise ValueError(f"{self.path}: give every frame a time or none")
        if self._parted is None:
            self._parted = held is not None
        elif self._parted != (held is not None):
            raise ValueError(f"{self.path}: say which parts are held in every frame or in none")
        row: dict[str, Any] = {
            "frame": frame_index,
            "poses": poses,
            "joints": joints,
            "status": status,
            "held": self._buffer["held"][0] if held is None else held,
            "residual": residual,
            "elapsed": elapsed,
            "time": np.nan if time is None else time,
        }
        for key, value in row.items():
            if np.shape(value) != self._buffer[key].shape[1:]:
                raise ValueError(f"{key} has shape {np.shape(value)}, expected {self._buffer[key].shape[1:]}")
        if status not in (TRACKED, UNCERTAIN, LOST, RESEEDED):
            raise ValueError(f"status must be 0, 1, 2 or 3, got {status}")
        if held is not None and not np.isin(held, (HELD, LOOSE, UNSEEN)).all():
            raise ValueError(f"held must hold 0, 1 or 2, got {np.unique(held)}")
        if self._count == 0:
            self._first_frame = int(frame_index)
        if self._buffered == len(self._buffer["frame"]):
            self._spill()
        for key, value in row.items():
            self._buffer[key][self._buffered] = value
        self._buffered += 1
        self._count += 1
        self._unflushed += 1
        if flush_due(self._unflushed, self._count, self.flush_every):
            self.flush()

    def _spill(self) -> None:
        """Append the rows held in memory to the raw files.  Each file is first cut back to the rows written for
        certain, so a spill broken off (Ctrl-C) is simply done again."""
        try:
            for key, column in self._buffer.items():
                with open(self._rows / key, "ab") as file:
                    file.truncate(self._on_disk * column[0].nbytes)
                    file.write(column[: self._buffered].tobytes())
        except OSError as error:
            raise TrackerInputError(
                f"{self._rows}: cannot keep the tracked frames there ({error.strerror or error}); "
                "free some space, or point TMPDIR at a disk that has it"
            ) from None
        self._on_disk += self._buffered
        self._buffered = 0

    def _chunks(self, key: str):
        """The raw bytes of column ``key`` so far, a chunk at a time (the time computed from the frames when the
        rows came without times)."""
        self._spill()
        if key == "time" and not self._timed:
            rows = max(1, _CHUNK // 8)
            frames = np.memmap(self._rows / "frame", np.int64, "r") if self._count else np.empty(0, np.int64)
            for begin in range(0, self._count, rows):
                yield ((frames[begin : begin + rows] - self._first_frame) / self.fps).tobytes()
            return
        if not self._count:
            return
        with open(self._rows / key, "rb") as file:
            while chunk := file.read(_CHUNK):
                yield chunk

    def _header(self, key: str) -> dict:
        """The .npy header of column ``key`` with every frame so far."""
        column = self._buffer[key]
        shape = (self._count, *column.shape[1:])
        return {"descr": np.lib.format.dtype_to_descr(column.dtype), "fortran_order": False, "shape": shape}

    def _names(self, key: str) -> np.ndarray:
        return self._component_names if key == "component_names" else self._joint_names

    def _write(self, file) -> None:
        """The archive np.savez would write (stored .npy members), streamed from the raw files."""
        with zipfile.ZipFile(file, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
            for key in _KEYS:
                if key != "held" or self._parted:
                    self._member(archive, key)

    def _member(self, archive: zipfile.ZipFile, key: str) -> None:
        with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
            if key.endswith("_names"):
                np.lib.format.write_array(member, self._names(key), allow_pickle=False)
                return
            np.lib.format.write_array_header_2_0(member, self._header(key))
            for chunk in self._chunks(key):
                member.write(chunk)

    def flush(self) -> None:
        """Rewrite poses.npz atomically with every frame so far."""
        atomic_write(self.path, self._write)
        self._unflushed = 0

    def close(self) -> None:
        """Flush, stop accepting frames and remove the raw files; closing twice is harmless."""
        if not self._closed:
            self._closed = True
            try:
                self.flush()
            finally:
                self._removal()

    def __enter__(self) -> PosesWriter:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.close()


def load_poses(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Arrays of a poses.npz or truth.npz, validated and in their canonical dtypes.

    ``joint_names`` and ``joints`` are required; ``frame``, ``time``, ``status``,
    ``residual``, ``elapsed``, ``component_names``, ``poses`` and ``held`` are optional (truth files
    often hold only the joints, files of older runs no ``held``; a missing ``frame`` is filled in as 0..F-1), and
    so is any extra array, returned as is.
    Byte-string name arrays are decoded to unicode.
    """
    path = Path(path)
    fix = "give the poses.npz that tracker track wrote, or a truth.npz"
    return _validated(path, read_npz(path, "a poses or truth file", fix))


def _validated(path: Path, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Check keys, shapes and kinds of loaded arrays; cast them to the canonical dtypes."""

    def fail(problem: str) -> TrackerInputError:
        return TrackerInputError(f"{path}: {problem}; see the poses.npz table in the file formats documentation")

    def names(key: str) -> np.ndarray:
        value = arrays[key]
        if value.ndim != 1 or value.dtype.kind not in "US":
            raise fail(f"'{key}' must be a 1-D array of strings, got {value.dtype} {value.shape}")
        value = value.astype(str)
        if len(set(value)) != len(value):
            raise fail(f"'{key}' repeats a name")
        return value

    def numbers(key: str, shape: tuple[int, ...], dtype: type, integer: bool = False) -> np.ndarray:
        value = arrays[key]
        kinds = "iu" if integer else "iuf"
        if value.dtype.kind not in kinds or value.shape != shape:
            kind = "integer" if integer else "numeric"
            raise fail(f"'{key}' must be {kind} of shape {shape}, got {value.dtype} {value.shape}")
        return value.astype(dtype)

    missing = [key for key in ("joint_names", "joints") if key not in arrays]
    if missing:
        raise fail(f"missing array {', '.join(map(repr, missing))}")
    out = dict(arrays)
    out["joint_names"] = names("joint_names")
    if arrays["joints"].ndim != 3:
        raise fail(f"'joints' must have shape (frames, joints, 3), got {arrays['joints'].shape}")
    frames = arrays["joints"].shape[0]
    out["joints"] = numbers("joints", (frames, len(out["joint_names"]), 3), np.float64)
    for key, dtype, integer in (
        ("frame", np.int64, True),
        ("status", np.int8, True),
        ("time", np.float64, False),
        ("residual", np.float64, False),
        ("elapsed", np.float64, False),
    ):
        if key in arrays:
            out[key] = numbers(key, (frames,), dtype, integer)
    out.setdefault("frame", np.arange(frames, dtype=np.int64))
    if len(np.unique(out["frame"])) != frames:
        raise fail("'frame' repeats a frame index")
    if "status" in out and not np.isin(out["status"], (TRACKED, UNCERTAIN, LOST, RESEEDED)).all():
        raise fail("'status' holds values other than 0, 1, 2, 3")
    if "component_names" in arrays:
        out["component_names"] = names("component_names")
    if "poses" in arrays:
        if "component_names" not in out:
            raise fail("'poses' needs 'component_names'")
        out["poses"] = numbers("poses", (frames, len(out["component_names"]), 4, 4), np.float64)
    if "held" in arrays:
        if "component_names" not in out:
            raise fail("'held' needs 'component_names'")
        out["held"] = numbers("held", (frames, len(out["component_names"])), np.int8, integer=True)
        if not np.isin(out["held"], (HELD, LOOSE, UNSEEN)).all():
            raise fail("'held' holds values other than 0, 1, 2")
    return out
