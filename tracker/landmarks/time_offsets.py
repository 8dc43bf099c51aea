"""Each camera's capture-time offset, found from the detector's landmarks (docs/sync.md).

A rig that is not frame-locked shows frame n of camera k at ``n / fps + o_k`` (``o_0 = 0``).  The same landmark seen
at the same instant by two cameras i and j satisfies the epipolar constraint of their calibration, ``x_j' E x_i = 0``
with ``E = [t]x R`` their relative pose, in ideal normalised coordinates.  Camera i's frame m and camera j at the same
instant, frame ``m - (o_j - o_i) fps`` (between two frames, its landmarks interpolated linearly), satisfy it only at
the true shift ``d = o_j - o_i``; a moving body's landmarks leave it at every other shift.  So for each pair of cameras
the shift is the minimum of the mean epipolar distance (pixels, each landmark's counted up to :data:`CAP` of the
image's short side, so that a swap or a mistaken detection weighs no more than that) over the confident landmarks of
every frame: first on a grid of tenths of a frame, then on hundredths about the grid's best and a parabola through the
three nearest points.  Its uncertainty is the spread of that minimum over the frames resampled in blocks of a
quarter of a second (a block bootstrap: the landmarks' errors are correlated from frame to frame).  A body that
stands still leaves the distance flat, the resampled minima spread, and the pair undecided.  The pairs that decide
give the offsets by weighted least squares, each pair weighed by the inverse of its variance.  A pair decides only
where its distance rises steeply either side of the least (:data:`RISE`): a slow body leaves it nearly flat, its least
wherever the detector's own errors (several pixels, correlated from frame to frame) put it, and the resampling cannot
tell, since every block of frames shares those errors.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tracker.camera import Camera
from tracker.geometry.se3 import skew
from tracker.landmarks.guided import undistorted

CONFIDENT = 0.5
"""A landmark counts where the detector's confidence is at least this in both frames it is interpolated between."""

CAP = 0.05
"""Share of the image's short side to which a landmark's epipolar distance is counted."""

LEAST = 40
"""Landmark sightings a shift needs in both cameras of a pair for the pair to be judged."""

UNDECIDED = 0.25
"""Frames: a pair whose resampled minima spread more than this (standard deviation) does not decide its shift."""

RISE = 1.15
"""A pair decides its shift only where the mean distance :data:`RISE_SECONDS` (at least a frame) either side of the
least is this many times the least: a body that moves slowly leaves the distance nearly flat, its least wherever the
detector's own errors put it."""

RISE_SECONDS = 0.05

RESAMPLES = 200
"""Block-bootstrap resamples of the frames for a pair's uncertainty."""


@dataclass(frozen=True)
class Offsets:
    """Each camera's capture-time offset from the first camera's, ``seconds`` (C,), with its standard deviation
    ``sigma`` (C,) (0 for the first camera, NaN for a camera no deciding pair reaches), and each pair of cameras'
    shift ``pairs``: (i, j) -> (seconds of j after i, sigma, decided)."""

    seconds: np.ndarray
    sigma: np.ndarray
    pairs: dict[tuple[int, int], tuple[float, float, bool]]

    @property
    def decided(self) -> np.ndarray:
        """(C,) bool: the cameras whose offset the motion decides."""
        return np.isfinite(self.sigma)


def essential(first: Camera, second: Camera) -> np.ndarray:
    """The essential matrix E (3, 3) with ``x2' E x1 = 0`` for the ideal normalised image points x1, x2 of one world
    point in ``first`` and ``second``."""
    relative = second.camera_from_world @ np.linalg.inv(first.camera_from_world)
    return skew(np.ascontiguousarray(relative[:3, 3])) @ relative[:3, :3]


def epipolar_pixels(
    first: np.ndarray, second: np.ndarray, *, matrix: np.ndarray, focal: tuple[float, float]
) -> np.ndarray:
    """The symmetric epipolar distance (...) in pixels of ideal normalised points ``first`` and ``second`` (..., 2)
    under the essential matrix ``matrix``: the mean of each point's distance to the other's epipolar line, each in
    its own camera's pixels (``focal``: the two cameras' focal lengths)."""
    a = np.concatenate([first, np.ones_like(first[..., :1])], axis=-1)
    b = np.concatenate([second, np.ones_like(second[..., :1])], axis=-1)
    line_b = a @ matrix.T  # epipolar lines in the second image
    line_a = b @ matrix  # ... and in the first
    residual = np.abs(np.sum(b * line_b, axis=-1))
    in_b = residual / np.hypot(line_b[..., 0], line_b[..., 1])
    in_a = residual / np.hypot(line_a[..., 0], line_a[..., 1])
    return 0.5 * (focal[1] * in_b + focal[0] * in_a)


def _at(points: np.ndarray, seen: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``points`` (F, K, 2) of one camera at fractional frames ``times`` (F,), interpolated by the Catmull-Rom
    cubic through the four frames about each time (a landmark's path bends within a frame at 30 frames a second),
    and where all four frames saw the landmark (F, K) (False where they are not all in the recording)."""
    frames = len(points)
    if frames < 4:
        return np.full(points.shape, np.nan), np.zeros(seen.shape, bool)
    below = np.floor(times).astype(int)
    inside = (below >= 1) & (below < frames - 2)
    low = np.clip(below, 1, frames - 3)
    s = (times - low)[:, None, None]
    p0, p1, p2, p3 = (points[low + k] for k in (-1, 0, 1, 2))
    moved = p1 + 0.5 * s * (p2 - p0 + s * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + s * (3.0 * (p1 - p2) + p3 - p0)))
    both = seen[low - 1] & seen[low] & seen[low + 1] & seen[low + 2] & inside[:, None]
    return moved, both


def _per_frame(
    first: tuple[np.ndarray, np.ndarray], second: tuple[np.ndarray, np.ndarray], shift: float, *, matrix, focal, cap
) -> tuple[np.ndarray, np.ndarray]:
    """Per frame m of the first camera (F,): the summed capped epipolar distance of its landmarks to the second
    camera's ``shift`` frames earlier (frame m - shift), and how many landmarks it sums."""
    points, seen = first
    other, other_seen = _at(*second, np.arange(len(points)) - shift)
    both = seen & other_seen
    distance = np.minimum(epipolar_pixels(points, other, matrix=matrix, focal=focal), cap)
    return np.where(both, distance, 0.0).sum(axis=1), both.sum(axis=1)


def _blocks(frames: int, size: int, rng: np.random.Generator) -> np.ndarray:
    """Weights (F,) of one block-bootstrap resample: blocks of ``size`` frames drawn with replacement."""
    starts = rng.integers(0, max(frames - size, 0) + 1, size=int(np.ceil(frames / size)))
    weights = np.zeros(frames)
    for start in starts:
        weights[start : start + size] += 1.0
    return weights


def pair_shift(
    first: tuple[np.ndarray, np.ndarray],
    second: tuple[np.ndarray, np.ndarray],
    *,
    matrix: np.ndarray,
    focal: tuple[float, float],
    cap: float,
    reach: float,
    block: int,
    rise: float,
    seed: int = 0,
) -> tuple[float, float, bool]:
    """The shift (frames) by which the second camera lags the first, its standard deviation, and whether the pair
    decides it (module docstring): the resampled minima spread less than :data:`UNDECIDED` and the mean distance
    ``rise`` frames either side of the least is :data:`RISE` times the least or more.  NaN, inf and False where too
    few landmarks are seen by both.  ``first`` and ``second``: normalised points (F, K, 2) and where they are seen
    (F, K); shifts searched within +-``reach`` frames."""
    coarse = np.arange(-reach, reach + 1e-9, 0.1)
    sums = np.array([_per_frame(first, second, shift, matrix=matrix, focal=focal, cap=cap) for shift in coarse])
    counts = sums[:, 1].sum(axis=1)
    usable = counts >= LEAST
    if not usable.any():
        return float("nan"), float("inf"), False
    cost = np.where(usable, sums[:, 0].sum(axis=1) / np.maximum(counts, 1), np.inf)
    best = coarse[int(np.argmin(cost))]
    steep = rises(cost, steps=round(rise / 0.1), ratio=RISE)
    fine = best + np.arange(-0.2, 0.2 + 1e-9, 0.01)
    table = np.array([_per_frame(first, second, shift, matrix=matrix, focal=focal, cap=cap) for shift in fine])
    shift, sigma = resampled_least(fine, table, block=block, seed=seed)
    return shift, sigma, steep and sigma <= UNDECIDED


def rises(cost: np.ndarray, *, steps: int, ratio: float) -> bool:
    """Whether the ``cost`` (S,) over evenly spaced shifts is at least ``ratio`` times its least ``steps`` shifts
    either side of it, both sides within the shifts searched."""
    least = int(np.argmin(cost))
    if not steps <= least < len(cost) - steps:
        return False
    return bool((cost[[least - steps, least + steps]] >= ratio * cost[least]).all())


def resampled_least(shifts: np.ndarray, table: np.ndarray, *, block: int, seed: int = 0) -> tuple[float, float]:
    """The shift of least mean cost over ``table`` (S, 2, F) (per shift and frame: summed costs, counts), refined by
    a parabola, and its spread over :data:`RESAMPLES` resamples of the frames in blocks of ``block`` (a block
    bootstrap: the errors are correlated from frame to frame)."""
    rng = np.random.default_rng(seed)
    minima = [_minimum(shifts, table, _blocks(table.shape[2], block, rng)) for _ in range(RESAMPLES)]
    return _minimum(shifts, table, np.ones(table.shape[2])), float(np.std(minima))


def _minimum(shifts: np.ndarray, table: np.ndarray, weights: np.ndarray) -> float:
    """The shift of least weighted mean distance over ``table`` (S, 2, F) (per shift: summed distances, counts), refined
    by the parabola through it and its neighbours."""
    counts = table[:, 1] @ weights
    cost = np.where(counts > 0, (table[:, 0] @ weights) / np.maximum(counts, 1e-12), np.inf)
    k = int(np.argmin(cost))
    if 0 < k < len(shifts) - 1 and np.isfinite(cost[k - 1 : k + 2]).all():
        left, middle, right = cost[k - 1 : k + 2]
        bend = left - 2.0 * middle + right
        if bend > 0:
            return float(shifts[k] + 0.5 * (left - right) / bend * (shifts[1] - shifts[0]))
    return float(shifts[k])


def camera_offsets(
    pixels: np.ndarray, confidence: np.ndarray, cameras: list[Camera], *, fps: float, reach: float
) -> Offsets:
    """Each camera's capture-time offset from the first camera's (module docstring), from landmarks detected in
    every frame: ``pixels`` (F, C, K, 2) recorded pixels, ``confidence`` (F, C, K); offsets searched within
    +-``reach`` seconds."""
    normalised = undistorted(pixels, cameras)
    seen = (confidence >= CONFIDENT) & np.isfinite(normalised).all(axis=3)
    block = max(2, round(fps / 4))
    frames = reach * fps
    pairs = {}
    for i, j in itertools.combinations(range(len(cameras)), 2):
        first, second = cameras[i], cameras[j]
        cap = CAP * min(*first.size, *second.size)
        shift, sigma, decided = pair_shift(
            (normalised[:, i], seen[:, i]),
            (normalised[:, j], seen[:, j]),
            matrix=essential(first, second),
            focal=(float(first.matrix[0, 0]), float(second.matrix[0, 0])),
            cap=cap,
            reach=frames,
            block=block,
            rise=max(1.0, RISE_SECONDS * fps),
        )
        pairs[(i, j)] = (shift / fps, sigma / fps, decided)
    return _solved(len(cameras), pairs)


def _solved(count: int, pairs: dict[tuple[int, int], tuple[float, float, bool]]) -> Offsets:
    """The offsets (o_0 = 0) that the deciding pairs' shifts ``o_j - o_i`` give by weighted least squares, with their
    standard deviations; NaN for the cameras no chain of deciding pairs joins to the first."""
    used = [(i, j, shift, max(sigma, 1e-6)) for (i, j), (shift, sigma, decided) in pairs.items() if decided]
    joined = {0}
    while True:
        more = {j for i, j, *_ in used if i in joined} | {i for i, j, *_ in used if j in joined}
        if more <= joined:
            break
        joined |= more
    unknowns = sorted(joined - {0})
    seconds, sigma = np.full(count, np.nan), np.full(count, np.nan)
    seconds[0], sigma[0] = 0.0, 0.0
    if unknowns:
        column = {camera: index for index, camera in enumerate(unknowns)}
        rows = [(i, j, shift, s) for i, j, shift, s in used if i in joined and j in joined]
        design = np.zeros((len(rows), len(unknowns)))
        for row, (i, j, _, s) in enumerate(rows):
            if j in column:
                design[row, column[j]] = 1.0 / s
            if i in column:
                design[row, column[i]] = -1.0 / s
        target = np.array([shift / s for _, _, shift, s in rows])
        solution = np.linalg.lstsq(design, target, rcond=None)[0]
        covariance = np.linalg.inv(design.T @ design)
        seconds[unknowns] = solution
        sigma[unknowns] = np.sqrt(np.diag(covariance))
    return Offsets(seconds, sigma, pairs)
