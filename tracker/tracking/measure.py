"""Edge measurement and per-component information (docs/method-tracking.md, section 3).

Each visible sample searches the (smoothed) grey image along its normal,
``p + s n`` for ``s`` in ``[-r, r]`` (or a per-sample sub-interval ``[lo, hi]``
of it, see :mod:`tracker.tracking.ownership`), for the nearest edge: a local maximum of
the directional derivative ``|dI/ds|`` above ``threshold`` (sub-pixel by a
parabola through the three values around it).  Its signed offset ``m`` (pixels,
positive along ``+n``) and the sample's Jacobian row ``L`` give, per
component ``i`` and summed over all its quadrics and all cameras,

    C_i = sum w L^T L,   eta_i = sum w L^T m,   w = 1 / (c + |m|)

the IRLS normal equations with weight ``w`` (rows scaled by sqrt(w)), which
minimise sum rho(m), rho(m) = |m| - c ln(1 + |m|/c): Gaussian for small
offsets and Laplacian for large ones (the paper's eq. 10).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class Statistics:
    """The counts of one measurement pass over all samples (C_i and eta_i stay in the caller's buffers)."""

    visible: int  # samples searched
    found: int  # samples that found an edge
    residual: float  # robust mean |m| = sum w|m| / sum w, pixels


def reduction(short_side: int, work_side: int) -> int:
    """The factor by which the edge search reduces images ``short_side`` pixels on their short side: the largest
    integer that keeps it at least ``work_side`` long (1: full size; always 1 for ``work_side`` 0)."""
    return max(1, short_side // work_side) if work_side > 0 else 1


@njit(cache=True, inline="always")
def bilinear(image, width, height, x, y):
    """The value of ``image`` (H, W) at (x, y) (pixel centres at integers, bilinear); -1 outside ``width`` x
    ``height``."""
    if x < 0.0 or y < 0.0 or x > width - 1.0 or y > height - 1.0:
        return -1.0
    x0 = min(int(x), width - 2)
    y0 = min(int(y), height - 2)
    fx = x - x0
    fy = y - y0
    top = image[y0, x0] * (1.0 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1.0 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1.0 - fy) + bottom * fy


@njit(cache=True)
def edge_offset(image, width, height, px, py, nx, ny, search_range, threshold, profile, lo=-(1 << 30), hi=1 << 30):
    """Signed distance along (nx, ny) from (px, py) to the nearest edge, or NaN if none within range.

    Only integer offsets ``t`` with ``lo <= t <= hi`` (clipped to ``[-r, r]``) are searched, and only the
    grey values they need are read.  ``profile`` is scratch space of at least 2 * search_range + 5 floats
    (the derivative at t = +-r needs the grey values at t +- 2).
    """
    r = search_range
    lo = max(lo, -r)
    hi = min(hi, r)
    for t in range(lo - 2, hi + 3):
        profile[t + r + 2] = bilinear(image, width, height, px + t * nx, py + t * ny)
    for d in range(r + 1):
        for sign in (1, -1):
            if d == 0 and sign == -1:
                continue
            t = sign * d
            if t < lo or t > hi:
                continue
            c = t + r + 2
            a0 = profile[c - 2]
            a1 = profile[c - 1]
            a2 = profile[c]
            a3 = profile[c + 1]
            a4 = profile[c + 2]
            if a0 < 0.0 or a1 < 0.0 or a2 < 0.0 or a3 < 0.0 or a4 < 0.0:
                continue
            g_prev = abs(a2 - a0) * 0.5
            g = abs(a3 - a1) * 0.5
            g_next = abs(a4 - a2) * 0.5
            if g < threshold or g < g_prev or g <= g_next:
                continue
            curvature = g_prev - 2.0 * g + g_next
            shift = 0.0
            if curvature < 0.0:
                shift = 0.5 * (g_prev - g_next) / curvature
            return t + shift
    return np.nan


@njit(cache=True, nogil=True)
def measure_kernel(
    images,
    cam_size,
    cam_factor,
    count,
    s_cam,
    s_comp,
    s_pixel,
    s_normal,
    s_jac,
    twist,
    search_range,
    threshold,
    robust_c,
    n_components,
    o_offset,
    o_weight,
    information,
    eta,
    s_lo=None,
    s_hi=None,
):
    """Search every sample's edge and accumulate C_i, eta_i; returns (visible, found, sum w|m|, sum w).

    ``twist`` (n_components, 6) is each component's motion since the samples were taken: every search
    starts from the sample's first-order predicted position ``p + (L . twist_i) n`` (section 3; zero
    for fresh samples), and ``m`` is measured from there.  ``s_lo``, ``s_hi`` (optional, integer per
    sample) restrict each search to ``[lo, hi]`` about that start.  Camera k's image may be reduced by the
    integer ``cam_factor[k]`` = f (f x f blocks averaged, ``cam_size[k]`` its reduced size): its searches then
    step one reduced pixel at a time, over ``search_range // f`` of them (``lo``, ``hi`` likewise, inwards), from
    the sample's place in it, ``(p + 0.5) / f - 0.5``, and their offsets are given in full-size pixels (times f);
    ``threshold`` stays a derivative per full-size pixel.  Steps of a full-size pixel in the reduced image would
    read its bilinear interpolation, whose slope is flat between its pixels: the sub-pixel peak would be off by up
    to a third of a full-size pixel.
    """
    information[:] = 0.0
    eta[:] = 0.0
    profile = np.empty(2 * search_range + 5)
    found = 0
    sum_wm = 0.0
    sum_w = 0.0
    for s in range(count):
        k = s_cam[s]
        f = cam_factor[k]
        lo = -search_range
        hi = search_range
        if s_lo is not None:
            lo = s_lo[s]
        if s_hi is not None:
            hi = s_hi[s]
        i = s_comp[s]
        moved = 0.0
        for a in range(6):
            moved += s_jac[s, a] * twist[i, a]
        nx = s_normal[s, 0]
        ny = s_normal[s, 1]
        shift = (1.0 - f) / (2.0 * f)  # (p + 0.5) / f - 0.5 written so that f = 1 leaves p's bits as they are
        m = f * edge_offset(
            images[k],
            cam_size[k, 0],
            cam_size[k, 1],
            (s_pixel[s, 0] + moved * nx) / f + shift,
            (s_pixel[s, 1] + moved * ny) / f + shift,
            nx,
            ny,
            max(search_range // f, 1),
            threshold * f,
            profile,
            -(-lo // f),
            hi // f,
        )
        o_offset[s] = m
        if np.isnan(m):
            o_weight[s] = 0.0
            continue
        w = 1.0 / (robust_c + abs(m))
        o_weight[s] = w
        found += 1
        sum_wm += w * abs(m)
        sum_w += w
        for a in range(6):
            la = w * s_jac[s, a]
            eta[i, a] += la * m
            for b in range(a, 6):
                information[i, a, b] += la * s_jac[s, b]
    for i in range(n_components):
        for a in range(6):
            for b in range(a + 1, 6):
                information[i, b, a] = information[i, a, b]
    return count, found, sum_wm, sum_w


@njit(cache=True)
def component_misfits(offset, component, count, n_components):
    """Each component's median |m| (pixels, (n_components,)) over its first ``count`` samples that found an
    edge (``offset`` not NaN), as the last measurement left them: how closely its outline fits the image's
    edges; inf for a component with no such sample (hidden, or nothing found), whose pose the edges do not
    hold."""
    out = np.full(n_components, np.inf)
    found = np.zeros(n_components, np.int64)
    for s in range(count):
        if not np.isnan(offset[s]):
            found[component[s]] += 1
    start = np.zeros(n_components + 1, np.int64)
    for i in range(n_components):
        start[i + 1] = start[i] + found[i]
    values = np.empty(start[n_components])
    filled = start[:n_components].copy()
    for s in range(count):
        if not np.isnan(offset[s]):
            i = component[s]
            values[filled[i]] = abs(offset[s])
            filled[i] += 1
    for i in range(n_components):
        if found[i] > 0:
            out[i] = np.median(values[start[i] : start[i + 1]])
    return out


def support(offset: np.ndarray, component: np.ndarray, *, count: int, chosen: np.ndarray, robust_c: float) -> float:
    """How closely the outlines of the components ``chosen`` (N,) bool found their edges in the last measurement:
    the mean over their first ``count`` samples of c / (c + |m|), the IRLS weight scaled to 1 at m = 0, where the
    sample found an edge (``offset`` not NaN) and 0 where it found none; 0 for no sample.  An outline lying on its
    edges scores near 1, one among clutter's edges at random offsets well below."""
    mine = chosen[component[:count]]
    if not mine.any():
        return 0.0
    m = np.abs(offset[:count][mine])
    return float(np.where(np.isnan(m), 0.0, robust_c / (robust_c + np.nan_to_num(m))).mean())
