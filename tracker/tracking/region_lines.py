"""The region cue's lines in numba kernels (:mod:`tracker.tracking.region_cue` gives the method): each line's
likelihood of the outline at every candidate offset, scored once per sampling (:func:`line_profiles`), its posterior
mean and variance added to C_i and eta_i (:func:`region_kernel`), and the colours along it counted into the part's
and the background's histograms (:func:`learn_kernel`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tracker.tracking.measure import bilinear

MAX_LINE = 64  # colour pixels a line may reach either side, at most
LOG_STEPS = 512  # intervals of the likelihood terms' table over p_f in [0, 1] (log_table): 16 kB, read per pixel


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
