"""Which frame of each camera shows each frame of a recording whose cameras are not frame-locked (docs/sync.md).

A recording's frame n is the instant ``t_n``: ``n / fps``, or the first camera's capture time of its frame n in
``timestamps.csv``.  Camera k is read at its frame ``m = frames[n, k]``, the one captured nearest ``t_n``, and that
view is ``late[n, k]`` seconds late (negative: early).  From constant offsets (``sync.toml``: camera k's frame m was
captured at ``m / fps + offset_k``) ``m = n - round(offset_k fps)``; from capture times, the frame whose time lies
nearest.  A camera that has no frame so near (the first frames of a camera that started late, the last of one that
stopped early) shows its nearest frame, later or earlier than that.  The frames of each camera never go back as n
goes on, so each video is still decoded once, in order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Pairing:
    """Camera k's frame ``frames[n, k]`` (F, C) int is read for the recording's frame n; it was captured
    ``late[n, k]`` (F, C) seconds after frame n's time."""

    frames: np.ndarray
    late: np.ndarray

    @property
    def identity(self) -> bool:
        """Every camera's frame n read for frame n."""
        return bool((self.frames == np.arange(len(self.frames))[:, None]).all())

    @property
    def frame_locked(self) -> bool:
        """Every camera's frame n read for frame n and captured at its time: no pairing needed."""
        return self.identity and not np.any(self.late)


def by_offsets(offsets: np.ndarray, *, count: int, fps: float) -> Pairing:
    """The pairing of ``count`` frames at ``fps`` whose cameras' frame m was captured at ``m / fps + offsets[k]``
    (C,) seconds (module docstring)."""
    reference = np.arange(count)
    shifts = np.round(np.asarray(offsets, float) * fps).astype(int)
    frames = np.clip(reference[:, None] - shifts[None, :], 0, count - 1)
    late = (frames - reference[:, None]) / fps + np.asarray(offsets, float)[None, :]
    return Pairing(frames, late)


def by_times(times: np.ndarray, reference: np.ndarray) -> Pairing:
    """The pairing by capture times: camera k's frame m captured at ``times[m, k]`` (F, C) seconds (NaN: no time,
    never picked), the recording's frame n at ``reference[n]`` (F,); each frame n reads the frame of each camera
    captured nearest it (the earlier of two as near); a camera without any time is read frame by frame, on time."""
    count, cameras = times.shape
    frames = np.tile(np.arange(count)[:, None], (1, cameras))
    for camera in range(cameras):
        known = np.flatnonzero(np.isfinite(times[:, camera]))
        if not len(known):
            continue
        at = times[known, camera]
        after = np.clip(np.searchsorted(at, reference), 1, len(at) - 1) if len(at) > 1 else np.zeros(count, int)
        before = np.maximum(after - 1, 0)
        nearer = np.where(np.abs(at[after] - reference) < np.abs(at[before] - reference), after, before)
        frames[:, camera] = known[nearer]
    frames = np.maximum.accumulate(frames, axis=0)  # equal times can pick back; a camera's frames go on
    late = times[frames, np.arange(cameras)] - reference[:, None]
    return Pairing(frames, np.where(np.isfinite(late), late, 0.0))
