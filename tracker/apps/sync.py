"""The library form of ``tracker sync --refine``: the landmarks' offsets refined by the tracker's own edge residuals
(docs/sync.md, "Refined by the edges").

Each camera but the first is timed against the body tracked in the others (:func:`tracker.apps.track.track`, each
at its offset from the landmarks; a camera they leave undecided takes no part): its edges' summed distance to that
track at trial offsets a quarter of a frame apart, :data:`REACH` frames either side of where the landmarks put it
(:func:`tracker.tracking.view_time.edge_costs`).  The least, refined by a parabola, is its offset; the spread of
that least over the frames resampled in blocks of a quarter of a second is its uncertainty.  It decides only where
the distance rises by :data:`RISE` either side of the least within 0.05 s (at least a frame): a camera that sees
the body's motion mostly along its line of sight sees its outline barely move, and its least lies wherever the
track's own errors put it.  Leaving the camera out of its track keeps the track from bending to the camera's
frames at the offset they were tracked at.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from tracker.apps.track import Bar, Tracking, track
from tracker.io.pairing import by_offsets
from tracker.io.recording import Recording, frames, open_recording
from tracker.landmarks.time_offsets import RISE_SECONDS, UNDECIDED, Offsets, resampled_least, rises

REACH = 4.0
"""Frames either side of the landmarks' offset (0 where they leave it undecided) searched."""

STEP = 0.25
"""Frames between trial offsets."""

RISE = 1.10
"""A camera's offset is decided where its edges' mean distance 0.05 s (at least a frame) either side of the least is
this many times the least: on the balancing trial the two cameras that see the sway across their view rise 14-18 %,
the two that see it along their line of sight 1-2 % (docs/sync.md)."""


@dataclasses.dataclass(frozen=True)
class Refined:
    """Each camera's offset from the edges, ``seconds`` (C,), with its standard deviation ``sigma`` (C,) and
    whether the edges decide it, ``decided`` (C,) (the first camera: 0, 0, True; a camera no track could time:
    NaN, inf, False)."""

    seconds: np.ndarray
    sigma: np.ndarray
    decided: np.ndarray


def refine_offsets(rec: Recording, found: Offsets, tracking: Tracking, *, out: Path, bar: Bar) -> Refined:
    """Refine the landmarks' offsets ``found`` of ``rec`` (read as recorded, unpaired) by the edges (module
    docstring), each camera's track written to OUT/without-<camera>/ (``out``) as ``tracking`` says; the body
    model, when neither ``tracking`` nor the recording gives one, fitted once, in the first track (``rec`` of two
    cameras or more: ``tracker sync`` refuses fewer)."""
    names = [camera.name for camera in rec.cameras]
    count = len(names)
    seconds, sigma = np.full(count, np.nan), np.full(count, np.inf)
    seconds[0], sigma[0] = 0.0, 0.0
    decided = np.zeros(count, bool)
    decided[0] = True
    start = np.where(found.decided, found.seconds, 0.0)
    for camera in range(1, count):
        others = [k for k in range(count) if k != camera and found.decided[k]]
        folder = out / f"without-{names[camera]}"
        print(f"refining {names[camera]}: tracking the body in {', '.join(names[k] for k in others)}", file=sys.stderr)
        outcome = track(_picked(rec, others, start), tracking, out=folder, bar=bar)
        if outcome.interrupted:
            raise KeyboardInterrupt
        if tracking.model is None:  # the model given, the recording's, or the one the first track fitted
            tracking = dataclasses.replace(tracking, model=str(rec.model_path or folder / "model.toml"))
        held = _track(outcome.poses, rec.frame_count)
        if held is None:
            continue
        seconds[camera], sigma[camera], decided[camera] = _timed(rec, camera, held, start[camera], tracking, bar)
    return Refined(seconds, sigma, decided)


def _picked(rec: Recording, cameras: list[int], offsets: np.ndarray) -> Recording:
    """``rec`` with only ``cameras``, their frames paired by ``offsets`` (C,) seconds."""
    picked = open_recording(rec.path, [rec.cameras[k].name for k in cameras], rec.calibration_path, paired=False)
    pairing = by_offsets(offsets[cameras], count=rec.frame_count, fps=rec.fps)
    return dataclasses.replace(picked, pairing=None if pairing.frame_locked else pairing)


def _track(path: Path, count: int) -> tuple[int, np.ndarray] | None:
    """The longest run of frames tracked without a loss into the poses.npz at ``path``: its first frame and its
    poses (F, N, 4, 4); None when it is shorter than two frames."""
    from tracker.io.poses import load_poses
    from tracker.status import LOST

    tracked = load_poses(path)
    poses = np.full((count, *tracked["poses"].shape[1:]), np.nan)
    kept = tracked["status"] != LOST
    poses[tracked["frame"][kept]] = tracked["poses"][kept]
    held = np.concatenate([[False], np.isfinite(poses).all(axis=(1, 2, 3)), [False]])
    edges = np.flatnonzero(np.diff(held.astype(int)))  # starts and stops of the runs of frames held, in turn
    starts, stops = edges[::2], edges[1::2]
    if not len(starts) or (stops - starts).max() < 2:
        return None
    longest = int(np.argmax(stops - starts))
    return int(starts[longest]), np.ascontiguousarray(poses[starts[longest] : stops[longest]])


def _timed(
    rec: Recording, camera: int, held: tuple[int, np.ndarray], start: float, tracking: Tracking, bar: Bar
) -> tuple[float, float, bool]:
    """Camera ``camera``'s offset (seconds), its standard deviation and whether it is decided, from its edges
    against the poses tracked without it (``held``: the first frame of the run and its poses, :func:`_track`;
    module docstring), trial offsets about ``start`` seconds."""
    from tracker.model import load_model
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.view_time import edge_costs

    assert tracking.model is not None  # set by refine_offsets after the first track
    model = load_model(tracking.model)
    alone = open_recording(rec.path, [rec.cameras[camera].name], rec.calibration_path, paired=False)
    begin, poses = held
    tracker = Tracker(model, alone.cameras, poses[0], tracking.settings)
    shifts = start * rec.fps + np.arange(-REACH, REACH + 1e-9, STEP)
    along = shifts - begin  # the camera's frame m shows the run's frame m + shift - begin
    first = max(0, int(np.ceil(-along[0])))  # the camera's frames that every trial offset places within the run
    stop = min(alone.frame_count, int(np.floor(len(poses) - 1 - along[-1])) + 1)
    if stop - first < 2:
        return float("nan"), float("inf"), False
    read = frames(alone, first, stop, prepare=tracker.smooth)
    table = edge_costs(
        tracker, bar(f"timing {alone.cameras[0].name}", "frame")(read, total=stop - first), poses, shifts=along
    )
    table = table[:, :, first:]
    counts = table[:, 1].sum(axis=1)
    if counts.min() == 0:  # the body outside the camera's view at some trial offset all along: nothing to compare
        return float("nan"), float("inf"), False
    cost = table[:, 0].sum(axis=1) / counts
    rise = max(1.0, RISE_SECONDS * rec.fps)
    least, sigma = resampled_least(shifts, table, block=max(2, round(rec.fps / 4)))
    decided = rises(cost, steps=round(rise / STEP), ratio=RISE) and sigma <= UNDECIDED
    return least / rec.fps, sigma / rec.fps, decided
