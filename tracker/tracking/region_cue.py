"""The region cue: where along each sample's line the colours change from the part's own to the room's
(docs/region.md).

The edge search takes the nearest grey-level edge, which in a furnished room or on patterned clothes is often
not the body's outline.  The region cue reads the same lines in colour instead, in the half-size colour image the
readers decode beside the grey one (:class:`tracker.io.readers.WithChroma`), and asks which offset ``d`` of the
outline along the line best splits it into the part's colours inside and the background's outside.

Colour statistics: each colour (16 bins per channel, 4096 bins) has a frequency ``h_f`` among the pixels of
component ``i`` in camera ``k`` and ``h_b`` among the background pixels just outside that part's outline in camera
``k``, learnt online from the tracked poses (:func:`learn_kernel`, ``h <- (1 - a) h + a h_new``).  A pixel of
colour ``y`` is the part's with probability ``p_f = h_f / (h_f + g)`` (0.5 for a colour seen in neither), where
``g`` is the mean of the part's own background ``h_b`` and the camera's, the mean of all its parts' ``h_b``: the
legs are seen against the floor, the arms and the head against the walls, and a part's own background alone, learnt
from its few lines, is too sparse to be fair to a printed costume (:func:`part_table`).  Between pixel centres,
``p_f`` is interpolated bilinearly, so that the line's points lie where the line is.

Along the line ``x_t = p + t n`` (``t`` in half-size pixels, ``n`` the outward normal), with a smoothed step
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
take are read from a table over ``p_f`` (:func:`log_table`), so a line costs a few table reads per pixel.

A line whose outside is another part (an arm across the trunk, perhaps in the same shirt) is left out: the colours
there do not tell the part from the background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

BINS = 16  # per colour channel
COLOURS = BINS**3
FACTOR = 2  # the colour image is half the full size (4:2:0 chroma)
MAX_LINE = 64  # half-size pixels a line may reach either side, at most
LOG_STEPS = 4096  # intervals of the likelihood terms' table over p_f in [0, 1] (log_table)


@dataclass
class Histograms:
    """Colour frequencies per camera and component, of the part (``foreground`` (C, N, COLOURS)) and of the
    background just outside its outline (``background`` (C, N, COLOURS)), each summing to 1 where ``seen`` (C, N) /
    ``seen_background`` (C, N) say it was learnt."""

    foreground: np.ndarray
    background: np.ndarray
    seen: np.ndarray
    seen_background: np.ndarray

    @classmethod
    def empty(cls, cameras: int, components: int) -> Histograms:
        return cls(
            np.zeros((cameras, components, COLOURS)),
            np.zeros((cameras, components, COLOURS)),
            np.zeros((cameras, components), np.bool_),
            np.zeros((cameras, components), np.bool_),
        )

    @property
    def ready(self) -> bool:
        """Whether any camera has both a background and a part learnt."""
        return bool((self.seen.any(axis=1) & self.seen_background.any(axis=1)).any())

    def learn(self, counts: np.ndarray, counts_background: np.ndarray, *, rate: float) -> None:
        """Mix a frame's counts (C, N, COLOURS) each in (:func:`blend_kernel`), which leaves them zero."""
        blend_kernel(self.foreground, self.background, self.seen, self.seen_background, counts, counts_background, rate)


@njit(cache=True, nogil=True)
def colour_bins(chroma, out):
    """Each pixel's colour bin (of 16 x 16 x 16) of a half-size colour image (H', W', 3) into ``out`` (H', W')."""
    step = 256 // BINS
    for v in range(chroma.shape[0]):
        for u in range(chroma.shape[1]):
            out[v, u] = (
                (chroma[v, u, 0] // step) * (BINS * BINS) + (chroma[v, u, 1] // step) * BINS + chroma[v, u, 2] // step
            )


@njit(cache=True, nogil=True)
def part_table(foreground, background, seen, seen_background, out, o_distinct):
    """p_f = h_f / (h_f + g) of every colour bin for every camera and component (C, N, COLOURS) into ``out`` (0.5
    for a colour seen in neither; NaN where the camera has not learnt the part, or no background), ``g`` the mean of
    the part's background and the camera's (the mean of its parts' backgrounds learnt; the camera's alone for a part
    whose lines all had another part outside), and how distinct the part's colours are from that background,
    ``o_distinct`` (C, N): 1 minus the Bhattacharyya coefficient sum_y sqrt(h_f(y) g(y)) of the two histograms (0
    for the same colours, 1 for none shared)."""
    around = np.zeros(foreground.shape[2])
    for k in range(foreground.shape[0]):
        around[:] = 0.0
        parts = 0
        for i in range(foreground.shape[1]):
            if seen_background[k, i]:
                around += background[k, i]
                parts += 1
        if parts:
            around /= parts
        for i in range(foreground.shape[1]):
            o_distinct[k, i] = 0.0
            if not (seen[k, i] and parts):
                out[k, i, :] = np.nan
                continue
            own = 0.5 if seen_background[k, i] else 0.0
            shared = 0.0
            for b in range(foreground.shape[2]):
                f = foreground[k, i, b]
                g = own * background[k, i, b] + (1.0 - own) * around[b]
                if f <= 0.0:  # most colours: no share, no root to take
                    out[k, i, b] = 0.5 if g <= 0.0 else 0.0
                    continue
                out[k, i, b] = f / (f + g)
                shared += math.sqrt(f * g)
            o_distinct[k, i] = max(0.0, 1.0 - shared)


@njit(cache=True, inline="always")
def part_probability(bins, table, width, height, x, y):
    """p_f at (x, y) of one camera's bin image (half-size coordinates), from one part's ``table`` (COLOURS,),
    bilinear between the four pixels around it (pixel centres at integers); -1 where one of them is outside."""
    if x < 0.0 or y < 0.0 or x > width - 1.0 or y > height - 1.0:
        return -1.0
    u = min(int(x), width - 2)
    v = min(int(y), height - 2)
    fx = x - u
    fy = y - v
    top = table[bins[v, u]] * (1.0 - fx) + table[bins[v, u + 1]] * fx
    bottom = table[bins[v + 1, u]] * (1.0 - fx) + table[bins[v + 1, u + 1]] * fx
    return top * (1.0 - fy) + bottom * fy


@njit(cache=True, inline="always")
def _colour(bins, width, height, x, y):
    """The colour bin of the half-size pixel nearest to (x, y) (half-size coordinates); -1 outside the image."""
    u = int(math.floor(x + 0.5))
    v = int(math.floor(y + 0.5))
    if u < 0 or v < 0 or u >= width or v >= height:
        return -1
    return bins[v, u]


@njit(cache=True)
def log_table(amplitude, slope):
    """The four terms of a line's likelihood as functions of p_f, tabulated at p_f = 0, 1/LOG_STEPS, ..., 1 (linear
    between: within 1e-6 of the logarithm): ``log(H p + (1 - H) (1 - p))`` for H far inside the outline, far
    outside, one pixel inside and one pixel outside (module docstring)."""
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
def _half(px, py, nx, ny, moved):
    """A full-size sample moved by ``moved`` pixels along its normal, in half-size coordinates."""
    return ((px + moved * nx) + 0.5) / FACTOR - 0.5, ((py + moved * ny) + 0.5) / FACTOR - 0.5


@njit(cache=True, inline="always")
def _limits(s_lo, s_hi, s_depth):
    """A line's candidate offsets (half-size pixels, :func:`region_kernel`): from the search interval ``s_lo``,
    ``s_hi`` (full-size pixels) and short of the part's far side (half its width along the line, ``s_depth``)."""
    return -min(-s_lo // FACTOR, s_depth // (2 * FACTOR), MAX_LINE), min(s_hi // FACTOR, MAX_LINE)


@njit(cache=True, inline="always")
def _used(s, every, table_ki, outside, d_lo, d_hi):
    """Whether a line takes part: every ``every``-th, of a part whose colours the camera knows, with the
    background outside, and at least three candidates long."""
    return s % every == 0 and not np.isnan(table_ki[0]) and outside == -1 and d_hi - d_lo >= 2


@njit(cache=True, nogil=True)
def _scores(bins, table, width, height, x0, y0, nx, ny, d_lo, d_hi, logs, pf, terms, out, at):
    """The log-likelihood of the outline at each offset ``d_lo..d_hi`` along the line ``(x0, y0) + t n`` (half-size
    pixels) into ``out[at:]`` (module docstring); False where a pixel of the line lies outside the image.  ``pf``
    (n + 2,) and ``terms`` (6, n + 3) are scratch."""
    log_half = math.log(0.5)
    n_pix = d_hi - d_lo + 3  # pixels t in [d_lo - 1, d_hi + 1]; index j = t - d_lo + 1
    for j in range(n_pix):
        t = d_lo - 1 + j
        p = part_probability(bins, table, width, height, x0 + t * nx, y0 + t * ny)
        if p < 0.0:
            return False
        pf[j] = p
    prefix_in = terms[4]
    suffix_out = terms[5]
    for j in range(n_pix):
        x = pf[j] * LOG_STEPS
        c = min(int(x), LOG_STEPS - 1)
        f = x - c
        for row in range(4):
            terms[row, j] = logs[row, c] + f * (logs[row, c + 1] - logs[row, c])
    prefix_in[0] = 0.0
    for j in range(n_pix):
        prefix_in[j + 1] = prefix_in[j] + terms[0, j]
    suffix_out[n_pix] = 0.0
    for j in range(n_pix - 1, -1, -1):
        suffix_out[j] = suffix_out[j + 1] + terms[1, j]
    for c in range(d_hi - d_lo + 1):
        j = c + 1  # the pixel at t = d
        out[at + c] = prefix_in[j - 1] + terms[2, j - 1] + log_half + terms[3, j + 1] + suffix_out[j + 2]
    return True


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


@njit(cache=True, nogil=True)
def line_profiles(
    bins, chroma_size, count, s_cam, s_comp, s_pixel, s_normal, s_outside, s_depth, s_lo, s_hi, every, table, logs
):
    """Each line's likelihood of the outline at every candidate offset from its sampled place (module docstring),
    divided by its largest, which :func:`region_kernel` reads for this and the next iterations until the next
    sampling.  Returns the line profiles ``(likelihood, start, first, length)``: sample ``s``'s lie at
    ``likelihood[start[s]:start[s] + length[s]]``, for the offsets ``first[s], first[s] + 1, ...`` (half-size
    pixels along the line; length 0 for a line not used, or one that leaves the image).

    A line's log-likelihoods differ by at most 2 * (MAX_LINE + 1) pixels' terms, each within
    log((1/2 + a) / (1/2 - a)) (2.6 for a = 0.43) of another's: the smallest ratio (e^-340 then) is far from
    underflow, so any run of candidates keeps its posterior's shape to the last bits."""
    start = np.zeros(count, np.int64)
    first = np.zeros(count, np.int64)
    length = np.zeros(count, np.int64)
    total = 0
    for s in range(count):
        d_lo, d_hi = _limits(s_lo[s], s_hi[s], s_depth[s])
        if _used(s, every, table[s_cam[s], s_comp[s]], s_outside[s], d_lo, d_hi):
            start[s] = total
            total += d_hi - d_lo + 1
    likelihood = np.empty(total)
    n_max = 2 * MAX_LINE + 3
    pf = np.empty(n_max)
    terms = np.empty((6, n_max + 1))
    for s in range(count):
        k = s_cam[s]
        i = s_comp[s]
        d_lo, d_hi = _limits(s_lo[s], s_hi[s], s_depth[s])
        if not _used(s, every, table[k, i], s_outside[s], d_lo, d_hi):
            continue
        nx = s_normal[s, 0]
        ny = s_normal[s, 1]
        x0, y0 = _half(s_pixel[s, 0], s_pixel[s, 1], nx, ny, 0.0)
        if _scores(
            bins[k],
            table[k, i],
            chroma_size[k, 0],
            chroma_size[k, 1],
            x0,
            y0,
            nx,
            ny,
            d_lo,
            d_hi,
            logs,
            pf,
            terms,
            likelihood,
            start[s],
        ):
            at, n = start[s], d_hi - d_lo + 1
            best = likelihood[at : at + n].max()
            for c in range(n):
                likelihood[at + c] = math.exp(likelihood[at + c] - best)
            first[s] = d_lo
            length[s] = n
    return likelihood, start, first, length


@njit(cache=True, nogil=True)
def region_kernel(
    count,
    s_cam,
    s_comp,
    s_jac,
    s_lo,
    s_hi,
    s_depth,
    twist,
    distinct,
    weight,
    min_variance,
    p_likelihood,
    p_start,
    p_first,
    p_length,
    o_mean,
    o_variance,
    information,
    eta,
):
    """The outline's offset posterior along each line profiled at the sampling (``p_*``, :func:`line_profiles`),
    added to C_i and eta_i (module docstring); returns the number of lines used.

    The candidate offsets step by one half-size pixel.  Since the sampling, the part moved by ``L . twist_i``
    along the line, and with it the line's search interval (``s_lo``, ``s_hi``, full-size pixels, short of the
    part's far side ``s_depth``): the candidates are those of the profile that lie within the interval moved
    (at least three, else the line is left out this iteration).  Writes each sample's posterior mean and variance
    (full-size pixels, from the moved place; NaN for a line not used).  ``min_variance`` floors the variance in
    the weight, ``weight`` is lambda."""
    used = 0
    for s in range(count):
        o_mean[s] = np.nan
        o_variance[s] = np.nan
        if p_length[s] == 0:
            continue
        k = s_cam[s]
        i = s_comp[s]
        moved = 0.0
        for a in range(6):
            moved += s_jac[s, a] * twist[i, a]
        shift = moved / FACTOR  # half-size pixels
        d_lo, d_hi = _limits(s_lo[s], s_hi[s], s_depth[s])
        u_lo = max(int(math.ceil(d_lo + shift - 1e-9)), p_first[s])
        u_hi = min(int(math.floor(d_hi + shift + 1e-9)), p_first[s] + p_length[s] - 1)
        if u_hi - u_lo < 2:
            continue
        step, variance = _moments(p_likelihood, p_start[s] + u_lo - p_first[s], u_hi - u_lo + 1)
        mean = (u_lo + step - shift) * FACTOR
        variance *= FACTOR * FACTOR
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
    chroma_size,
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
    o_foreground,
    o_background,
):
    """Count the colours along every sample's line at the poses ``twist`` moved them to: the half-size pixels
    ``1..inside`` in from the outline are its component's (in ``o_foreground`` (C, N, COLOURS)), those
    ``2..outside`` out are its background's (``o_background`` (C, N, COLOURS)) where the line's outside is the
    background and within the search interval (and inside, short of the part's far side, ``s_depth``).

    Once camera k knows part i's colours (``seen[k, i]``), only the lines whose last offset posterior agrees with
    the outline (``|s_mean| <= agree``, full-size pixels) count: a part that strays would otherwise learn the room's
    colours where it lies and hold itself there."""
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
        x0, y0 = _half(s_pixel[s, 0], s_pixel[s, 1], nx, ny, moved)
        width = chroma_size[k, 0]
        height = chroma_size[k, 1]
        deepest = min(inside, -s_lo[s] // FACTOR, (s_depth[s] - 1) // FACTOR)
        for t in range(1, deepest + 1):
            b = _colour(bins[k], width, height, x0 - t * nx, y0 - t * ny)
            if b >= 0:
                o_foreground[k, i, b] += 1.0
        if s_outside[s] != -1:
            continue
        farthest = min(outside, s_hi[s] // FACTOR)
        for t in range(2, farthest + 1):
            b = _colour(bins[k], width, height, x0 + t * nx, y0 + t * ny)
            if b >= 0:
                o_background[k, i, b] += 1.0


@njit(cache=True, nogil=True)
def blend_kernel(foreground, background, seen, seen_background, counts, counts_background, rate):
    """Mix a frame's colour counts (:func:`learn_kernel`) into the histograms in place, each normalised,
    ``h <- (1 - rate) h + rate h_new``, or taken whole where the histogram was never learnt; the counts are left
    zero."""
    for k in range(foreground.shape[0]):
        for i in range(foreground.shape[1]):
            seen[k, i] = _blend(foreground[k, i], counts[k, i], rate, seen[k, i])
            seen_background[k, i] = _blend(background[k, i], counts_background[k, i], rate, seen_background[k, i])


@njit(cache=True, inline="always")
def _blend(histogram, counts, rate, learnt):
    """Mix ``counts`` normalised into ``histogram`` (taken whole if it was never ``learnt``) and zero them
    (:func:`blend_kernel`); returns whether the histogram is learnt now."""
    total = counts.sum()
    if total <= 0.0:
        return learnt
    keep = 1.0 - rate if learnt else 0.0
    for b in range(histogram.shape[0]):
        histogram[b] = keep * histogram[b] + (1.0 - keep) * counts[b] / total
        counts[b] = 0.0
    return True
