"""When a view was captured, read off the tracker's own edge residuals (docs/sync.md, "Refined by the edges").

A body tracked in the other cameras gives its poses at the recording's frame times.  Camera k's frame m, captured
at ``m / fps + o`` for a trial offset ``o``, shows the body at the fractional frame ``m + o fps`` of that track: the
poses there, interpolated along the geodesic between the two tracked frames about it, are projected into frame m
and their outlines' edges searched as the tracker's last iteration searches them.  Where ``o`` is the camera's true
offset the outlines lie on the body's edges; at any other the body has moved since, and they lie off by as much.
So the summed edge distance over the frames, as a function of ``o``, is least at the offset.  Each sample's distance
counts up to the search range, and a sample that finds no edge counts the whole range, so that clutter or a limb
the other views placed wrongly weighs no more than a miss.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numba import njit

from tracker.geometry.se3 import between, exp, log


@njit(cache=True)
def poses_at(poses: np.ndarray, time: float) -> np.ndarray:
    """The poses (N, 4, 4) at the fractional frame ``time`` of a track ``poses`` (F, N, 4, 4): each component moved
    from the frame before along the geodesic to the frame after, E = E_i exp(f log(E_i^-1 E_i+1)), f = time - i;
    ``time`` within 0..F-1."""
    first = min(int(np.floor(time)), poses.shape[0] - 2)
    share = time - first
    out = np.empty(poses.shape[1:])
    for i in range(poses.shape[1]):
        out[i] = poses[first, i] @ exp(share * log(between(poses[first, i], poses[first + 1, i])))
    return out


def edge_costs(tracker, frames: Iterable[tuple[int, list]], poses: np.ndarray, *, shifts: np.ndarray) -> np.ndarray:
    """Per trial shift and per frame of one camera, its edges' summed distance to the track and their count: a table
    (S, 2, M) over ``shifts`` (S,) (frames: the camera's frame m shows the track's frame m + shift) and the camera's
    frames 0..M-1 (module docstring); zeros where the shifted time lies outside the track.

    ``tracker``: a :class:`tracker.tracking.track.Tracker` of the one camera; ``frames``: its frames (index, [image]),
    already smoothed by the tracker; ``poses`` (F, N, 4, 4): the body tracked in the other cameras at frames 0..F-1,
    contiguous."""
    search = tracker.search_range(tracker.settings.iterations - 1)
    table: dict[int, np.ndarray] = {}
    for index, images in frames:
        column = np.zeros((len(shifts), 2))
        for row, shift in enumerate(shifts):
            time = index + shift
            if not 0.0 <= time <= len(poses) - 1:
                continue
            seen = tracker.inspect(images, smoothed=True, poses=poses_at(poses, time), search_range=search)
            distance = np.abs(seen.offset)
            column[row] = np.where(np.isfinite(distance), np.minimum(distance, search), search).sum(), len(distance)
        table[index] = column
    out = np.zeros((len(shifts), 2, max(table, default=-1) + 1))
    for index, column in table.items():
        out[:, :, index] = column
    return out
