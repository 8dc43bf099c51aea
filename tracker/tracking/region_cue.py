"""The region cue: where along each sample's line the colours change from the part's own to the room's
(docs/region.md).

The edge search takes the nearest grey-level edge, which in a furnished room or on patterned clothes is often
not the body's outline.  The region cue reads the same lines in colour instead, in the half-size colour image the
readers decode beside the grey one (:class:`tracker.io.readers.WithChroma`), reduced further by the factor the edge
search reduces the view's grey image by (:func:`colour_reduction`), and asks which offset ``d`` of the outline along
the line best splits it into the part's colours inside and the background's outside.  Each camera's colour image is
``grid[k, 2]`` full-size pixels to one of its own, the *colour pixels*, and ``grid[k, :2]`` of them wide and high.

Colour statistics: each colour (16 bins per channel, 4096 bins) has a frequency ``h_f`` among the pixels of
component ``i`` in camera ``k`` and ``h_b`` among the background pixels just outside that part's outline in camera
``k``, learnt online from the tracked poses (:func:`learn_kernel`, ``h <- (1 - a) h + a h_new``).  A pixel of
colour ``y`` is the part's with probability ``p_f = h_f / (h_f + g)`` (0.5 for a colour seen in neither), where
``g`` is the mean of the part's own background ``h_b`` and the camera's, the mean of all its parts' ``h_b``: the
legs are seen against the floor, the arms and the head against the walls, and a part's own background alone, learnt
from its few lines, is too sparse to be fair to a printed costume (:func:`part_table`).  Between pixel centres,
``p_f`` is interpolated bilinearly, so that the line's points lie where the line is.

Along the line ``x_t = p + t n`` (``t`` in colour pixels, ``n`` the outward normal), with a smoothed step
``H(x) = 1/2 - a tanh(x / (2 s))`` (taken flat, ``1/2 -+ a``, beyond one pixel) for the chance that a pixel
``x`` from the outline is the part's, the likelihood of the outline at ``d`` is

    L(d) = prod_t [ H(t - d) p_f(x_t) + (1 - H(t - d)) (1 - p_f(x_t)) ],

the posterior over the candidate offsets ``d`` (integers within the search interval) is ``L`` normalised, and its
mean ``mu`` and variance ``sigma^2`` (in full-size pixels) enter the component's information like an edge
measurement with offset ``mu`` and weight ``lambda / max(sigma^2, sigma_min^2)``:

    C_i += w L^T L,   eta_i += w L^T mu.

``a`` < 1/2 keeps a share of every pixel for misclassification (the step never reaches 0 or 1), so one odd pixel
cannot veto an offset.  The pixels further than one from ``d`` lie on the step's flat parts; their terms are the
same for every ``d`` on their side and are summed once per line (prefix sums), and the four terms a pixel can
take are read from a table over ``p_f`` (:func:`log_table`), so a line costs a few table reads per pixel.  Each
line is scored once per sampling of the outlines (:func:`line_profiles`) and read in the iterations between, while
its part moves little along it (:func:`region_kernel`).

A line whose outside is another part (an arm across the trunk, perhaps in the same shirt) is left out: the colours
there do not tell the part from the background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from tracker.tracking.measure import bilinear, reduction

BINS = 16  # per colour channel
COLOURS = BINS**3
FACTOR = 2  # the readers' colour image is half the full size (4:2:0 chroma)
MAX_LINE = 64  # colour pixels a line may reach either side, at most
RESCALE = 1e-150  # a histogram's scale below which its values take it in (blend_kernel)
LOG_STEPS = 512  # intervals of the likelihood terms' table over p_f in [0, 1] (log_table): 16 kB, read per pixel


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


@njit(cache=True, inline="always")
def part_probability(bins, table, width, height, x, y):
    """p_f at (x, y) of one camera's bin image (colour pixels, within ``[0, width - 1] x [0, height - 1]``),
    from one part's ``table`` (COLOURS,), bilinear between the four pixels around it (pixel centres at
    integers)."""
    u = min(int(x), width - 2)
    v = min(int(y), height - 2)
    fx = x - u
    fy = y - v
    top = table[bins[v, u]] * (1.0 - fx) + table[bins[v, u + 1]] * fx
    bottom = table[bins[v + 1, u]] * (1.0 - fx) + table[bins[v + 1, u + 1]] * fx
    return top * (1.0 - fy) + bottom * fy


@njit(cache=True, inline="always")
def with_person(p, person, width, height, x, y, trust):
    """A pixel's ``p`` (p_f) joined by the person's mask at the colour pixel (x, y) (``person`` (H', W') uint8,
    the probability x 255, :func:`tracker.tracking.person.person_grid`, read bilinearly within ``width`` x
    ``height``), as independent evidence whose odds multiply ``p``'s, ``m`` taken as ``1/2 + trust (m - 1/2)``: the
    mask is coarse (a 1080p body's is 7 pixels a cell), and the network sometimes paints a hidden leg on the table
    before it (docs/region.md)."""
    m = 0.5 + trust * (bilinear(person, width, height, x, y) / 255.0 - 0.5)
    a = p * m
    return a / (a + (1.0 - p) * (1.0 - m))


@njit(cache=True, inline="always")
def _colour(bins, width, height, x, y):
    """The colour bin of the colour pixel nearest to (x, y) (colour pixels); -1 outside the image."""
    u = int(math.floor(x + 0.5))
    v = int(math.floor(y + 0.5))
    if u < 0 or v < 0 or u >= width or v >= height:
        return -1
    return bins[v, u]


@njit(cache=True)
def log_table(amplitude, slope):
    """The four terms of a line's likelihood as functions of p_f, tabulated at p_f = 0, 1/LOG_STEPS, ..., 1 (linear
    between): ``log(H p + (1 - H) (1 - p))`` for H far inside the outline, far outside, one pixel inside and one
    pixel outside (module docstring).  Within 1e-4 of the logarithm (at its worst near p_f 0 or 1), and small
    enough to stay in the processor's nearest cache: read for every pixel of every line, a table eight times as
    fine (within 1e-6) made the lines a fifth dearer."""
    step = amplitude * math.tanh(1.0 / (2.0 * slope))
    steps = (0.5 + amplitude, 0.5 - amplitude, 0.5 + step, 0.5 - step)
    out = np.empty((4, LOG_STEPS + 1))
    for row in range(4):
        h = steps[row]
        for c in range(LOG_STEPS + 1):
            p = c / LOG_STEPS
            out[row, c] = math.log(h * p + (1.0 - h) * (1.0 - p))
    return out


@njit(cache=True, inline="always")
def _on_grid(px, py, nx, ny, moved, inverse):
    """A full-size sample moved by ``moved`` pixels along its normal, in colour pixels of ``1 / inverse`` full-size
    ones (a product, not a quotient: it is taken for every line in every iteration, and for the factors 2 and 4 the
    same to the last bit)."""
    return ((px + moved * nx) + 0.5) * inverse - 0.5, ((py + moved * ny) + 0.5) * inverse - 0.5


@njit(cache=True, inline="always")
def _limits(s_lo, s_hi, s_depth, factor):
    """A line's candidate offsets (colour pixels of ``factor`` full-size ones, :func:`region_kernel`): from the
    search interval ``s_lo``, ``s_hi`` (full-size pixels) and short of the part's far side (half its width along the
    line, ``s_depth``)."""
    return -min(-s_lo // factor, s_depth // (2 * factor), MAX_LINE), min(s_hi // factor, MAX_LINE)


@njit(cache=True, inline="always")
def _line(s, every, table_ki, outside, s_lo, s_hi, s_depth, factor):
    """Whether sample ``s``'s line takes part (every ``every``-th, of a part whose colours the camera knows, with the
    background outside, and at least three candidates long) and its candidate offsets (:func:`_limits`, 0 for a
    line not used).  The tests that need no division come first: most samples fail them."""
    if s % every != 0 or outside != -1 or np.isnan(table_ki[0]):
        return False, 0, 0
    d_lo, d_hi = _limits(s_lo, s_hi, s_depth, factor)
    return d_hi - d_lo >= 2, d_lo, d_hi


@njit(cache=True, inline="always")
def _moments(likelihood, at, n):
    """The mean and variance (in steps from ``at``) of the posterior ``likelihood[at:at + n]`` normalised."""
    total = 0.0
    mean = 0.0
    for c in range(n):
        total += likelihood[at + c]
        mean += likelihood[at + c] * c
    mean /= total
    variance = 0.0
    for c in range(n):
        variance += likelihood[at + c] * (c - mean) ** 2
    return mean, variance / total


@njit(cache=True, inline="always")
def _likelihood(bins, table, person, trust, width, height, x0, y0, nx, ny, d_lo, d_hi, logs, terms, out, at):
    """The likelihood of the outline at each offset ``d_lo..d_hi`` along the line ``(x0, y0) + t n`` (colour
    pixels; module docstring), divided by the largest, into ``out[at:]``; False where the line leaves the image.
    ``terms`` (5, n + 3) is scratch.  With ``trust`` > 0 each pixel's p_f is joined by the person's mask ``person``
    (:func:`with_person`).

    Two of a line's log-likelihoods differ in at most 2 * (MAX_LINE + margin) + 3 pixels' terms, each
    within log((1/2 + a) / (1/2 - a)) (2.6 for a = 0.43) of the other's: the smallest ratio (about e^-350) is far
    from underflow (e^-708), so any run of candidates keeps its posterior's shape to the last bits."""
    for t in (d_lo - 1, d_hi + 1):  # the line's ends: a straight line is in the image where both are
        x = x0 + t * nx
        y = y0 + t * ny
        if x < 0.0 or y < 0.0 or x > width - 1.0 or y > height - 1.0:
            return False
    n_pix = d_hi - d_lo + 3  # pixels t in [d_lo - 1, d_hi + 1]; index j = t - d_lo + 1
    prefix_in, l_out, l_m1, l_p1, suffix_out = terms[0], terms[1], terms[2], terms[3], terms[4]
    far_in, far_out, near_in, near_out = logs[0], logs[1], logs[2], logs[3]
    prefix_in[0] = 0.0
    for j in range(n_pix):
        t = d_lo - 1 + j
        x = x0 + t * nx
        y = y0 + t * ny
        p = part_probability(bins, table, width, height, x, y)
        if trust > 0.0:
            p = with_person(p, person, width, height, x, y, trust)
        x = p * LOG_STEPS
        c = min(int(x), LOG_STEPS - 1)
        f = x - c
        prefix_in[j + 1] = prefix_in[j] + far_in[c] + f * (far_in[c + 1] - far_in[c])
        l_out[j] = far_out[c] + f * (far_out[c + 1] - far_out[c])
        l_m1[j] = near_in[c] + f * (near_in[c + 1] - near_in[c])
        l_p1[j] = near_out[c] + f * (near_out[c + 1] - near_out[c])
    suffix_out[n_pix] = 0.0
    for j in range(n_pix - 1, -1, -1):
        suffix_out[j] = suffix_out[j + 1] + l_out[j]
    log_half = math.log(0.5)
    for c in range(d_hi - d_lo + 1):
        j = c + 1  # the pixel at t = d
        out[at + c] = prefix_in[j - 1] + l_m1[j - 1] + log_half + l_p1[j + 1] + suffix_out[j + 2]
    n = d_hi - d_lo + 1
    best = out[at : at + n].max()
    for c in range(n):
        out[at + c] = math.exp(out[at + c] - best)
    return True


@njit(cache=True, nogil=True)
def line_profiles(
    bins,
    grid,
    count,
    s_cam,
    s_comp,
    s_pixel,
    s_normal,
    s_outside,
    s_depth,
    s_lo,
    s_hi,
    every,
    table,
    person,
    trust,
    logs,
    margin,
):
    """Each line's likelihood of the outline at every candidate offset from its sampled place (module docstring,
    :func:`_likelihood`), reaching ``margin[k]`` colour pixels beyond its candidates either way (or none beyond,
    where the wider line would leave the image), which :func:`region_kernel` reads for this and the next
    iterations until the next sampling.  Returns the line profiles ``(likelihood, start, first, length)``: sample
    ``s``'s lie at ``likelihood[start[s]:start[s] + length[s]]``, for the offsets ``first[s], first[s] + 1, ...``
    (colour pixels along the line; length 0 for a line not used, or one that leaves the image).  ``grid`` (C, 4):
    each camera's colour image's width, height and full-size pixels to one of its own (module docstring), and the
    row of ``logs`` (T, 4, LOG_STEPS + 1) that holds its :func:`log_table`; ``person`` (C, H', W') and ``trust``
    (C,): each camera's person mask and how far it is trusted (0: no mask; :func:`with_person`)."""
    start = np.zeros(count, np.int64)
    first = np.zeros(count, np.int64)
    length = np.zeros(count, np.int64)
    total = 0
    for s in range(count):
        k = s_cam[s]
        taken, d_lo, d_hi = _line(s, every, table[k, s_comp[s]], s_outside[s], s_lo[s], s_hi[s], s_depth[s], grid[k, 2])
        if taken:
            start[s] = total
            total += d_hi - d_lo + 1 + 2 * margin[k]
    likelihood = np.empty(total)
    terms = np.empty((5, 2 * (MAX_LINE + margin.max()) + 4))
    inverse = 1.0 / grid[:, 2]
    for s in range(count):
        k = s_cam[s]
        i = s_comp[s]
        taken, d_lo, d_hi = _line(s, every, table[k, i], s_outside[s], s_lo[s], s_hi[s], s_depth[s], grid[k, 2])
        if not taken:
            continue
        nx = s_normal[s, 0]
        ny = s_normal[s, 1]
        x0, y0 = _on_grid(s_pixel[s, 0], s_pixel[s, 1], nx, ny, 0.0, inverse[k])
        for wide in (margin[k], 0):
            lo = d_lo - wide
            hi = d_hi + wide
            if _likelihood(
                bins[k],
                table[k, i],
                person[k],
                trust[k],
                grid[k, 0],
                grid[k, 1],
                x0,
                y0,
                nx,
                ny,
                lo,
                hi,
                logs[grid[k, 3]],
                terms,
                likelihood,
                start[s],
            ):
                first[s] = lo
                length[s] = hi - lo + 1
                break
    return likelihood, start, first, length


@njit(cache=True, nogil=True)
def region_kernel(
    bins,
    grid,
    count,
    s_cam,
    s_comp,
    s_pixel,
    s_normal,
    s_jac,
    s_outside,
    s_depth,
    twist,
    s_lo,
    s_hi,
    every,
    table,
    person,
    trust,
    distinct,
    logs,
    weight,
    min_variance,
    p_likelihood,
    p_start,
    p_first,
    p_length,
    afresh,
    o_mean,
    o_variance,
    information,
    eta,
):
    """The outline's offset posterior along the lines of every ``every``-th sample, added to C_i and eta_i (module
    docstring); returns the number of lines used.

    ``s_lo``, ``s_hi`` (full-size pixels, per sample) bound the candidate offsets, which step by one colour pixel
    from the sample's predicted place ``p + (L . twist_i) n``, and so does half the part's width along the line,
    ``s_depth`` (:func:`tracker.tracking.ownership.search_limits`): beyond it the line would see the part's far
    side.  Where the line's profile (``p_*``, :func:`line_profiles`) holds them all, the candidates are read from
    it, on the whole colour pixels from the sampled place; else, and for every line with ``afresh`` (the frame's
    last iteration), the line is scored afresh on those from the moved place: read from the profile, the candidates
    lie a sub-pixel phase off it, and the outline's final place with them (the demo 4.8 mm against 4.4 with the last
    iteration afresh).  ``grid``, ``logs``, ``person``, ``trust``: as in :func:`line_profiles`.  Writes each sample's
    posterior mean and variance (full-size pixels; NaN for a line not used).  ``min_variance`` floors the variance in
    the weight, ``weight`` is lambda."""
    used = 0
    terms = np.empty((5, 2 * MAX_LINE + 4))
    fresh = np.empty(2 * MAX_LINE + 1)
    inverse = 1.0 / grid[:, 2]
    for s in range(count):
        o_mean[s] = np.nan
        o_variance[s] = np.nan
        k = s_cam[s]
        i = s_comp[s]
        factor = grid[k, 2]
        taken, d_lo, d_hi = _line(s, every, table[k, i], s_outside[s], s_lo[s], s_hi[s], s_depth[s], factor)
        if not taken:
            continue
        moved = 0.0
        for a in range(6):
            moved += s_jac[s, a] * twist[i, a]
        shift = moved * inverse[k]  # colour pixels
        u_lo = int(math.ceil(d_lo + shift - 1e-9))
        u_hi = int(math.floor(d_hi + shift + 1e-9))
        if not afresh and u_lo >= p_first[s] and u_hi < p_first[s] + p_length[s] and u_hi - u_lo >= 2:
            step, variance = _moments(p_likelihood, p_start[s] + u_lo - p_first[s], u_hi - u_lo + 1)
            mean = u_lo + step - shift
        else:
            nx = s_normal[s, 0]
            ny = s_normal[s, 1]
            x0, y0 = _on_grid(s_pixel[s, 0], s_pixel[s, 1], nx, ny, moved, inverse[k])
            if not _likelihood(
                bins[k],
                table[k, i],
                person[k],
                trust[k],
                grid[k, 0],
                grid[k, 1],
                x0,
                y0,
                nx,
                ny,
                d_lo,
                d_hi,
                logs[grid[k, 3]],
                terms,
                fresh,
                0,
            ):
                continue
            step, variance = _moments(fresh, 0, d_hi - d_lo + 1)
            mean = d_lo + step
        mean *= factor
        variance *= factor * factor
        o_mean[s] = mean
        o_variance[s] = variance
        w = weight * distinct[k, i] / max(variance, min_variance)
        used += 1
        for a in range(6):
            la = w * s_jac[s, a]
            eta[i, a] += la * mean
            for b in range(6):
                information[i, a, b] += la * s_jac[s, b]
    return used


@njit(cache=True, nogil=True)
def learn_kernel(
    bins,
    grid,
    count,
    s_cam,
    s_comp,
    s_pixel,
    s_normal,
    s_jac,
    s_outside,
    s_depth,
    twist,
    s_lo,
    s_hi,
    s_mean,
    seen,
    agree,
    inside,
    outside,
    person,
    trust,
    o_colours,
    o_touched,
    o_touched_count,
):
    """Count the colours along every sample's line at the poses ``twist`` moved them to (into :class:`Counts`'
    arrays ``o_*``): the colour pixels ``1..inside[k]`` in from the outline are its component's, those
    ``2..outside[k]`` out are its background's where the line's outside is the background and within the search
    interval (and inside, short of the part's far side, ``s_depth``); ``grid`` as in :func:`line_profiles`.

    Once camera k knows part i's colours (``seen[k, i]``), only the lines whose last offset posterior agrees with
    the outline (``|s_mean| <= agree``, full-size pixels) count: a part that strays would otherwise learn the room's
    colours where it lies and hold itself there.  Where camera k has the person's mask (``trust[k] > 0``), a pixel
    counts for the part only where the mask says the person (``person`` >= 128), and for the background only where
    it does not: a leg hidden behind a table would otherwise learn the table's colours as its own."""
    inverse = 1.0 / grid[:, 2]
    for s in range(count):
        k = s_cam[s]
        i = s_comp[s]
        if seen[k, i] and not abs(s_mean[s]) <= agree:
            continue
        moved = 0.0
        for a in range(6):
            moved += s_jac[s, a] * twist[i, a]
        nx = s_normal[s, 0]
        ny = s_normal[s, 1]
        factor = grid[k, 2]
        x0, y0 = _on_grid(s_pixel[s, 0], s_pixel[s, 1], nx, ny, moved, inverse[k])
        width = grid[k, 0]
        height = grid[k, 1]
        deepest = min(inside[k], -s_lo[s] // factor, (s_depth[s] - 1) // factor)
        farthest = min(outside[k], s_hi[s] // factor) if s_outside[s] == -1 else 1
        for side in range(2):  # 0: the part's pixels, inwards; 1: the background's, outwards
            sign = -1.0 if side == 0 else 1.0
            for t in range(1 + side, (deepest if side == 0 else farthest) + 1):
                x = x0 + sign * t * nx
                y = y0 + sign * t * ny
                b = _colour(bins[k], width, height, x, y)
                if b < 0:
                    continue
                if trust[k] > 0.0 and (person[k, int(y + 0.5), int(x + 0.5)] >= 128) != (side == 0):
                    continue
                if o_colours[side, k, i, b] == 0.0:  # a colour new to this frame's counts
                    o_touched[side, k, i, o_touched_count[side, k, i]] = b
                    o_touched_count[side, k, i] += 1
                o_colours[side, k, i, b] += 1.0


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
