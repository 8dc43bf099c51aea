"""The colours the region cue learns (docs/region.md): per camera and component, the frequency of each colour among
the part's pixels and among the background's just outside it, blended in frame after frame, and the chance ``p_f``
that a pixel of a colour is the part's (:func:`part_table`); and each camera's colour image as the region cue reads
it (:func:`colour_grids`, :func:`colour_bins`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from tracker.tracking.measure import reduction

BINS = 16  # per colour channel
COLOURS = BINS**3
FACTOR = 2  # the readers' colour image is half the full size (4:2:0 chroma)
RESCALE = 1e-150  # a histogram's scale below which its values take it in (blend_kernel)


@dataclass
class Histograms:
    """Colour frequencies per camera and component, of the part (``scale[0, k, i] * foreground[k, i]``,
    ``foreground`` (C, N, COLOURS)) and of the background just outside its outline (``scale[1, k, i] *
    background[k, i]``), each summing to 1 where ``seen`` (C, N) / ``seen_background`` (C, N) say it was learnt.
    The scales (2, C, N) carry each frame's decay, so that learning touches only the colours the frame showed
    (:func:`blend_kernel`).

    What :func:`part_table` needs to visit only the colours that matter, kept as they learn (:func:`index_colours`):
    each part's *own* colours, those its foreground ever counted, the first ``own_size[k, i]`` of ``own[k, i]``
    (ascending; ``is_own`` (C, N, COLOURS) says which); the colours some background of camera ``k`` ever counted,
    ``backed`` (C, COLOURS); and those that joined them since the table last read them, the first
    ``newly_backed_size[k]`` of ``newly_backed[k]``."""

    foreground: np.ndarray
    background: np.ndarray
    scale: np.ndarray
    seen: np.ndarray
    seen_background: np.ndarray
    own: np.ndarray = field(init=False)
    own_size: np.ndarray = field(init=False)
    is_own: np.ndarray = field(init=False)
    backed: np.ndarray = field(init=False)
    newly_backed: np.ndarray = field(init=False)
    newly_backed_size: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.gather_colours()

    @classmethod
    def empty(cls, cameras: int, components: int) -> Histograms:
        return cls(
            np.zeros((cameras, components, COLOURS)),
            np.zeros((cameras, components, COLOURS)),
            np.ones((2, cameras, components)),
            np.zeros((cameras, components), np.bool_),
            np.zeros((cameras, components), np.bool_),
        )

    def gather_colours(self) -> None:
        """The parts' own colours and the backed ones from the histograms as they are now (after they were written
        directly); the table must then be made afresh (every row NaN), as nothing is newly backed."""
        self.is_own = self.foreground != 0
        self.own_size = self.is_own.sum(axis=2).astype(np.int64)
        self.own = np.zeros(self.foreground.shape, np.int16)
        for k, i in np.ndindex(*self.own_size.shape):
            self.own[k, i, : self.own_size[k, i]] = np.flatnonzero(self.is_own[k, i])
        self.backed = (self.background != 0).any(axis=1)
        self.newly_backed = np.zeros(self.backed.shape, np.int16)
        self.newly_backed_size = np.zeros(len(self.backed), np.int64)

    @property
    def ready(self) -> bool:
        """Whether any camera has both a background and a part learnt."""
        return bool((self.seen.any(axis=1) & self.seen_background.any(axis=1)).any())

    def frequencies(self) -> tuple[np.ndarray, np.ndarray]:
        """The parts' and the backgrounds' colour frequencies (C, N, COLOURS), scaled."""
        return self.scale[0][..., None] * self.foreground, self.scale[1][..., None] * self.background

    def learn(self, counts: Counts, *, rate: float) -> None:
        """Mix a frame's ``counts`` in (:func:`blend_kernel`), which leaves them empty."""
        index_colours(
            self.own,
            self.own_size,
            self.is_own,
            self.backed,
            self.newly_backed,
            self.newly_backed_size,
            counts.touched,
            counts.touched_count,
        )
        blend_kernel(
            self.foreground, self.background, self.scale, self.seen, self.seen_background, *counts.arrays(), rate
        )


@dataclass
class Counts:
    """A frame's colour counts before they are learnt (:func:`learn_kernel`): of the parts (``colours[0]``) and of
    their backgrounds (``colours[1]``), (2, C, N, COLOURS), and the bins each count holds, the first
    ``touched_count`` (2, C, N) of ``touched`` (2, C, N, COLOURS)."""

    colours: np.ndarray
    touched: np.ndarray
    touched_count: np.ndarray

    @classmethod
    def empty(cls, cameras: int, components: int) -> Counts:
        return cls(
            np.zeros((2, cameras, components, COLOURS)),
            np.zeros((2, cameras, components, COLOURS), np.int16),
            np.zeros((2, cameras, components), np.int64),
        )

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.colours, self.touched, self.touched_count


def colour_reduction(short_side: int, work_side: int) -> int:
    """The factor by which the region cue reduces a half-size colour image ``short_side`` pixels on its short side
    further: the largest integer that keeps it at least ``work_side / 2`` long (1: as it is; always 1 for
    ``work_side`` 0), the edge search's factor for the view (:func:`tracker.tracking.measure.reduction`) where
    ``work_side`` is even.  A 1080-pixel view's lines then hold as many colour pixels as a 480-pixel one's, as its
    edge search's do grey ones (docs/region.md)."""
    return reduction(short_side, work_side // FACTOR)


def colour_grids(size: np.ndarray, work_side: int) -> np.ndarray:
    """Each camera's colour image as the region cue reads it, (C, 3) int64: width, height and the full-size pixels
    to one of its pixels, for full-size images ``size`` (C, 2: width, height): the readers' half-size colour image
    (:data:`FACTOR`) reduced by :func:`colour_reduction`, each pixel the mean of a block, the rows and columns past
    the last whole block dropped (:func:`tracker.io.readers.reduced`)."""
    half = np.asarray(size, np.int64) // FACTOR
    factor = np.array([colour_reduction(int(min(h)), work_side) for h in half], np.int64)
    return np.column_stack([half // factor[:, None], FACTOR * factor])


@njit(cache=True, nogil=True)
def colour_bins(chroma, out):
    """Each pixel's colour bin (of 16 x 16 x 16) of a colour image (H', W', 3) into ``out`` (H', W')."""
    step = 256 // BINS
    for v in range(chroma.shape[0]):
        for u in range(chroma.shape[1]):
            out[v, u] = (
                (chroma[v, u, 0] // step) * (BINS * BINS) + (chroma[v, u, 1] // step) * BINS + chroma[v, u, 2] // step
            )


@njit(cache=True, nogil=True)
def part_table(
    foreground,
    background,
    scale,
    seen,
    seen_background,
    own,
    own_size,
    backed,
    newly_backed,
    newly_backed_size,
    out,
    o_distinct,
):
    """p_f = h_f / (h_f + g) of every colour bin for every camera and component (C, N, COLOURS; the histograms,
    their ``scale`` and the colours they counted, :class:`Histograms`) into ``out``, kept from frame to frame (NaN
    where the camera has not learnt the part, or no background), ``g`` the mean of the part's background and the
    camera's (the mean of its parts' backgrounds learnt; the camera's alone for a part whose lines all had another
    part outside), and how distinct the part's colours are from that background, ``o_distinct`` (C, N): 1 minus the
    Bhattacharyya coefficient sum_y sqrt(h_f(y) g(y)) of the two histograms (0 for the same colours, 1 for none
    shared).

    A colour the part never counted has p_f 0 where a background of the camera did, 0.5 where none did (a colour
    seen in neither).  Only the part's own colours change from frame to frame, so a learnt row is written whole
    once, when it is first learnt (a row is all NaN or all numbers: its first bin tells which), and then at its own
    colours and at the colours newly backed, which it reads and empties."""
    around = np.zeros(foreground.shape[2])
    done = np.zeros(foreground.shape[2], np.int64)  # the camera (plus one) whose ``around`` a colour holds
    for k in range(foreground.shape[0]):
        parts = 0
        for i in range(foreground.shape[1]):
            parts += seen_background[k, i]
        for i in range(foreground.shape[1]):
            o_distinct[k, i] = 0.0
            if not (seen[k, i] and parts):
                if not np.isnan(out[k, i, 0]):
                    out[k, i, :] = np.nan
                continue
            if np.isnan(out[k, i, 0]):
                for b in range(foreground.shape[2]):
                    out[k, i, b] = 0.0 if backed[k, b] else 0.5
            else:
                for c in range(newly_backed_size[k]):
                    out[k, i, newly_backed[k, c]] = 0.0
            own_share = 0.5 * scale[1, k, i] if seen_background[k, i] else 0.0
            camera = 0.5 if seen_background[k, i] else 1.0
            part = scale[0, k, i]
            shared = 0.0
            for c in range(own_size[k, i]):
                b = own[k, i, c]
                if done[b] != k + 1:
                    total = 0.0
                    for j in range(foreground.shape[1]):
                        if seen_background[k, j]:
                            total += scale[1, k, j] * background[k, j, b]
                    around[b] = total / parts
                    done[b] = k + 1
                f = part * foreground[k, i, b]
                g = own_share * background[k, i, b] + camera * around[b]
                if f <= 0.0:  # only after the histogram's values underflowed
                    out[k, i, b] = 0.0 if backed[k, b] else 0.5
                    continue
                out[k, i, b] = f / (f + g)
                shared += math.sqrt(f * g)
            o_distinct[k, i] = max(0.0, 1.0 - shared)
        newly_backed_size[k] = 0


@njit(cache=True, nogil=True)
def index_colours(own, own_size, is_own, backed, newly_backed, newly_backed_size, touched, touched_count):
    """Add the colours a frame counted (:class:`Counts`' ``touched``, (2, C, N, COLOURS), the first
    ``touched_count`` of each) to their parts' own colours (kept ascending) and to their cameras' backed ones
    (:class:`Histograms`)."""
    for k in range(touched.shape[1]):
        for i in range(touched.shape[2]):
            for c in range(touched_count[0, k, i]):
                b = touched[0, k, i, c]
                if is_own[k, i, b]:
                    continue
                is_own[k, i, b] = True
                at = own_size[k, i]
                while at > 0 and own[k, i, at - 1] > b:
                    own[k, i, at] = own[k, i, at - 1]
                    at -= 1
                own[k, i, at] = b
                own_size[k, i] += 1
            for c in range(touched_count[1, k, i]):
                b = touched[1, k, i, c]
                if not backed[k, b]:
                    backed[k, b] = True
                    newly_backed[k, newly_backed_size[k]] = b
                    newly_backed_size[k] += 1


@njit(cache=True, nogil=True)
def blend_kernel(foreground, background, scale, seen, seen_background, colours, touched, touched_count, rate):
    """Mix a frame's colour counts (:class:`Counts`' arrays, :func:`learn_kernel`) into the histograms in place,
    each normalised, ``h <- (1 - rate) h + rate h_new``, or taken whole where the histogram was never learnt or the
    ``rate`` is 1; the counts are left empty.  The decay goes into the histogram's scale, so only the bins counted
    are written (and every bin once in a few hundred frames, when the scale nears underflow)."""
    for k in range(foreground.shape[0]):
        for i in range(foreground.shape[1]):
            seen[k, i] = _blend(
                foreground[k, i],
                scale[0, k, i : i + 1],
                colours[0, k, i],
                touched[0, k, i],
                touched_count[0, k, i],
                rate,
                seen[k, i],
            )
            seen_background[k, i] = _blend(
                background[k, i],
                scale[1, k, i : i + 1],
                colours[1, k, i],
                touched[1, k, i],
                touched_count[1, k, i],
                rate,
                seen_background[k, i],
            )
            touched_count[0, k, i] = 0
            touched_count[1, k, i] = 0


@njit(cache=True, inline="always")
def _blend(histogram, scale, counts, touched, n, rate, learnt):
    """Mix ``counts`` normalised into ``scale[0] * histogram`` (taken whole if it was never ``learnt``), reading and
    zeroing only the first ``n`` bins ``touched`` (:func:`blend_kernel`); returns whether the histogram is learnt
    now."""
    total = 0.0
    for c in range(n):
        total += counts[touched[c]]
    if total <= 0.0:
        return learnt
    if learnt and rate < 1.0:
        scale[0] *= 1.0 - rate
        share = rate / (total * scale[0])
    else:  # a histogram never learnt is all zero; at a rate of 1 the counts replace it
        if learnt:
            histogram[:] = 0.0
        scale[0] = 1.0
        share = 1.0 / total
    for c in range(n):
        b = touched[c]
        histogram[b] += share * counts[b]
        counts[b] = 0.0
    if scale[0] < RESCALE:
        histogram *= scale[0]
        scale[0] = 1.0
    return True
