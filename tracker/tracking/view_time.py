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

from tracker.tracking.edge_cue import EdgeCue
from tracker.tracking.motion_model import motion_since, views_at


@njit(cache=True)
def poses_at(poses: np.ndarray, time: float) -> np.ndarray:
    """The poses (N, 4, 4) at the fractional frame ``time`` of a track ``poses`` (F, N, 4, 4): each component moved
    from the frame before along the geodesic to the frame after, E = E_i exp(f log(E_i^-1 E_i+1)), f = time - i
    (:func:`~tracker.tracking.frame_loop.views_at` of the motion between them); ``time`` within 0..F-1."""
    first = min(int(np.floor(time)), poses.shape[0] - 2)
    velocity = motion_since(poses[first], poses[first + 1])
    return views_at(np.ascontiguousarray(poses[first]), velocity, np.array([time - first]))[0]


def edge_costs(tracker, frames: Iterable[tuple[int, list]], poses: np.ndarray, *, shifts: np.ndarray) -> np.ndarray:
    """Per trial shift and per frame of one camera, its edges' summed distance to the track and their count: a table
    (S, 2, M) over ``shifts`` (S,) (frames: the camera's frame m shows the track's frame m + shift) and the camera's
    frames 0..M-1 (module docstring); zeros where the shifted time lies outside the track.

    ``tracker``: a :class:`tracker.tracking.frame_loop.Tracker` of the one camera, used up: each frame is loaded into
    its buffers once and searched there at every shift; ``frames``: its frames (index, [image]), already smoothed by the
    tracker; ``poses`` (F, N, 4, 4): the body tracked in the other cameras at frames 0..F-1, contiguous."""
    search = tracker.search_range(tracker.settings.solve.iterations - 1)
    work = tracker.work
    columns = {}
    for index, images in frames:
        tracker.load_images(images, smoothed=True)
        column = np.zeros((len(shifts), 2))
        for row, shift in enumerate(shifts):
            time = index + shift
            if not 0.0 <= time <= len(poses) - 1:
                continue
            tracker.sample(work, poses_at(poses, time), search)
            EdgeCue.measure(tracker, work, search_range=search, twist=tracker.still)
            distance = np.abs(work.offset[: work.samples.count])
            column[row] = np.where(np.isfinite(distance), np.minimum(distance, search), search).sum(), len(distance)
        columns[index] = column
    out = np.zeros((len(shifts), 2, max(columns, default=-1) + 1))
    for index, column in columns.items():
        out[:, :, index] = column
    return out
