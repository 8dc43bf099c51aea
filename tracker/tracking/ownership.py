"""Which predicted edge may claim an image edge: search limits along each sample's line.

D&C's 1-D search (docs/method-tracking.md, section 3) takes the nearest image edge within
``[-r, r]`` of each sample, whatever produced it.  With thin limbs, limbs in
front of the torso, legs crossing and a forearm lying along its upper arm, the
nearest edge is often the outline of *another* component, and taking it drags
the component into a wrong local minimum (a forearm folding back onto its upper
arm, a foot onto its shin) that it then explains perfectly well.

The current poses predict every visible edge along the search line: walking
along ``p + t n`` (integer ``t``), the front-most component hit by the pixel's
ray (a label; -1 for background) changes exactly at predicted outline
crossings.  The sample's own edge is the change at ``t = 0`` between its
component ``i`` and the label just outside, ``o`` (the label at ``t = +1``).
Any other change (between a pair other than ``{i, o}``) is another predicted
edge, so an image edge beyond the midpoint to it is nearer to that prediction
and is not searched: a change between ``t`` and ``t + 1`` (``t >= 1``) sets
``hi = floor((t + 1/2) / 2)``, one between ``-t`` and ``-t - 1`` sets
``lo = -floor((t + 1/2) / 2)``.  Changes between ``i`` and ``o`` again (the
far side of the same limb against the same background) do not cut the line.

The label of a pixel: the ray ``x = (u, v, 1)`` of its undistorted position
meets quadric ``[[A, b], [b^T, c]]`` (camera frame, section 2) at depths
``s`` with ``s^2 x^T A x + 2 s b^T x + c = 0``; the nearest ``s > 0`` whose
point lies inside the quadric's clipping quadric wins.

Speed (two numba calls per IRLS iteration, no allocation per sample):

* the camera-frame quadrics, clips, bounding spheres and their cones of rays
  are the ones :func:`tracker.tracking.outline.place` made for the outlines (the
  :class:`~tracker.tracking.samples.Placed` buffers the :class:`~tracker.tracking.frame_loop.Tracker`
  owns); per call :func:`prepare` only lists, per camera and quadric, the
  quadrics whose cone of rays comes near it (the only ones its samples can meet);
* per sample only the two ends of the search segment ``p +- (r + 1) n`` are
  undistorted (bilinearly in a per-camera grid of exact undistortions made
  once, :func:`undistort_grid`; Newton outside it); the rays in between are
  taken on the straight segment between the two, ``x(t) = x_m + t d`` (the
  lens is smooth over a few tens of pixels: the labels differ from per-pixel
  exact rays only on rare points within a pixel of a boundary; measured in
  docs/method-tracking.md, section 3);
* a quadric takes part only if its bounding sphere meets the fan of rays over
  the segment (exact test: a quadratic in ``t``);
* with ``x`` linear in ``t``, ``x^T A x`` is a quadratic and ``b^T x`` a line
  in ``t`` for each quadric and each clip, and so is the discriminant
  ``(2 b^T x)^2 - 4 c x^T A x``: a label costs a few multiply-adds per
  candidate, and a square root only where the ray meets the quadric;
* from the roots of the discriminants and sphere tests, the points where a
  label that could cut may occur are marked (:func:`_coverage`); only pairs of
  neighbours touching them are labelled, walking outwards from the sample,
  and each side stops at its first cut.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.geometry.lens import undistort
from tracker.tracking.outline import cone_gap

_SPHERE_MARGIN = 1e-6  # relative, on the bounding spheres (they only cull)
GRID_STEP = 8.0  # pixels between the nodes of the undistortion grid
GRID_MARGIN = 48.0  # pixels the grid reaches beyond the image
_UNKNOWN = -2  # label not computed
_WIDEN = 1e-4  # the analytic discriminant intervals are widened by this (in t) so that they cover every point
NCOEF = 18  # per candidate: discriminant (3), x^T A x (3), 2 b^T x (2), c, clip x^T A x (3), clip 2 b^T x (2), clip c,
# sphere test g (3)


@njit(cache=True, nogil=True)
def prepare(cone, cam_scale, r, o_near, o_near_count):
    """Per camera and quadric ``j``, the quadrics whose bounding sphere's cone of rays comes within the angle
    of a search line (``r + 1`` pixels at most ``cam_scale[k]`` radians each, see :func:`pixel_scale`) of
    quadric ``j``'s: a coarse cull for the samples of ``j``, ``o_near[k, j, :o_near_count[k, j]]``.
    ``cone`` (C, Q, 6) holds the cones of rays of :func:`tracker.tracking.outline.place` (axis, cos, sin, angle)."""
    n_cams, n_quadrics = cone.shape[0], cone.shape[1]
    for k in range(n_cams):
        # quadric l is near quadric j when the angle between the cone axes is at most a_j + a_l + a margin
        # m covering the r + 1 pixels of a search line (and 10% for the straight segments):
        # cos(axes) >= cos(a_j) cos(a_l + m) - sin(a_j) sin(a_l + m)
        margin = 1.1 * (r + 2.0) * cam_scale[k]
        c = cone[k]
        for j in range(n_quadrics):
            count = 0
            for l in range(n_quadrics):
                wide = c[l, 5] + margin
                near = l == j or c[j, 5] + wide >= np.pi
                if not near:
                    near = cone_gap(c[j], c[l], np.cos(wide), np.sin(wide)) >= 0.0
                if near:
                    o_near[k, j, count] = l
                    count += 1
            o_near_count[k, j] = count


def undistort_grid(rig, *, step=GRID_STEP, margin=GRID_MARGIN):
    """Ideal normalised coordinates of the recorded pixels on a grid (C, ny, nx, 2) for the cameras of ``rig``
    (a :class:`tracker.tracking.rig.Rig`): node (iy, ix) is the pixel (ix step - margin, iy step - margin); it
    covers every camera's image and ``margin`` pixels around it."""
    width = int(np.max(rig.size[:, 0]))
    height = int(np.max(rig.size[:, 1]))
    nx = int(np.ceil((width - 1 + 2 * margin) / step)) + 1
    ny = int(np.ceil((height - 1 + 2 * margin) / step)) + 1
    grid = np.empty((len(rig.names), ny, nx, 2))
    _fill_grid(rig.matrix, rig.lens, rig.distortion, float(step), float(margin), grid)
    return grid


def pixel_scale(grid, step=GRID_STEP):
    """Per camera, the largest angle (radians) between the rays of two neighbouring pixels of the grid's
    area: the distance in normalised coordinates per pixel, bounded over the grid's cells (with 1% to spare)."""
    dx = np.linalg.norm(np.diff(grid, axis=2), axis=3).max(axis=(1, 2))
    dy = np.linalg.norm(np.diff(grid, axis=1), axis=3).max(axis=(1, 2))
    diagonal = np.linalg.norm(grid[:, 1:, 1:] - grid[:, :-1, :-1], axis=3).max(axis=(1, 2)) / np.sqrt(2.0)
    return 1.01 * np.maximum(np.maximum(dx, dy), diagonal) / step


@njit(cache=True)
def _fill_grid(cam_matrix, cam_lens, cam_dist, step, margin, grid):
    for k in range(grid.shape[0]):
        for iy in range(grid.shape[1]):
            for ix in range(grid.shape[2]):
                x, y = undistort(cam_matrix[k], cam_lens[k], cam_dist[k], ix * step - margin, iy * step - margin)
                grid[k, iy, ix, 0] = x
                grid[k, iy, ix, 1] = y


@njit(cache=True, inline="always")
def _undistort_fast(grid, cam_matrix, cam_lens, cam_dist, k, px, py):
    """:func:`tracker.geometry.lens.undistort` for camera k by bilinear interpolation in its grid (the map is
    smooth, so the error is a small fraction of a pixel for ordinary lenses: docs/method-tracking.md, section 3),
    or exactly outside the grid."""
    gx = (px + GRID_MARGIN) * (1.0 / GRID_STEP)
    gy = (py + GRID_MARGIN) * (1.0 / GRID_STEP)
    if gx >= 0.0 and gy >= 0.0:
        ix = int(gx)
        iy = int(gy)
        if ix < grid.shape[2] - 1 and iy < grid.shape[1] - 1:
            fx = gx - ix
            fy = gy - iy
            x0 = grid[k, iy, ix, 0] + fx * (grid[k, iy, ix + 1, 0] - grid[k, iy, ix, 0])
            x1 = grid[k, iy + 1, ix, 0] + fx * (grid[k, iy + 1, ix + 1, 0] - grid[k, iy + 1, ix, 0])
            y0 = grid[k, iy, ix, 1] + fx * (grid[k, iy, ix + 1, 1] - grid[k, iy, ix, 1])
            y1 = grid[k, iy + 1, ix, 1] + fx * (grid[k, iy + 1, ix + 1, 1] - grid[k, iy + 1, ix, 1])
            return x0 + fy * (x1 - x0), y0 + fy * (y1 - y0)
    return undistort(cam_matrix[k], cam_lens[k], cam_dist[k], px, py)


@njit(cache=True, inline="always")
def _coefficients(q, k, l, x0, x1, d0, d1, coef, c, at):
    """Along x = (x0, x1, 1) + t (d0, d1, 0), for the matrix q[k, l]: x^T A x = coef[c, at] + coef[c, at+1] t +
    coef[c, at+2] t^2, 2 b^T x = coef[c, at+3] + coef[c, at+4] t, and coef[c, at+5] = c."""
    ax0 = q[k, l, 0, 0] * x0 + q[k, l, 0, 1] * x1 + q[k, l, 0, 2]
    ax1 = q[k, l, 1, 0] * x0 + q[k, l, 1, 1] * x1 + q[k, l, 1, 2]
    ax2 = q[k, l, 2, 0] * x0 + q[k, l, 2, 1] * x1 + q[k, l, 2, 2]
    ad0 = q[k, l, 0, 0] * d0 + q[k, l, 0, 1] * d1
    ad1 = q[k, l, 1, 0] * d0 + q[k, l, 1, 1] * d1
    coef[c, at] = x0 * ax0 + x1 * ax1 + ax2
    coef[c, at + 1] = 2.0 * (d0 * ax0 + d1 * ax1)
    coef[c, at + 2] = d0 * ad0 + d1 * ad1
    coef[c, at + 3] = 2.0 * (q[k, l, 0, 3] * x0 + q[k, l, 1, 3] * x1 + q[k, l, 2, 3])
    coef[c, at + 4] = 2.0 * (q[k, l, 0, 3] * d0 + q[k, l, 1, 3] * d1)
    coef[c, at + 5] = q[k, l, 3, 3]


@njit(cache=True, inline="always")
def _label_at(t, n_cand, cand_comp, coef):
    """Front-most component hit by the ray x(t) among the candidates (coefficients in ``coef``); -1 if none."""
    nearest = np.inf
    label = -1
    for c in range(n_cand):
        disc = coef[c, 0] + t * (coef[c, 1] + t * coef[c, 2])
        if disc < 0.0:
            continue
        qa = coef[c, 3] + t * (coef[c, 4] + t * coef[c, 5])
        if qa == 0.0:
            continue
        qb = coef[c, 6] + t * coef[c, 7]
        root = np.sqrt(disc)
        big = -0.5 * (qb + root) if qb >= 0.0 else -0.5 * (qb - root)
        if big == 0.0:
            continue
        ca = coef[c, 9] + t * (coef[c, 10] + t * coef[c, 11])
        cb = coef[c, 12] + t * coef[c, 13]
        cc = coef[c, 14]
        z = big / qa
        if 0.0 < z < nearest and (z * ca + cb) * z + cc <= 0.0:
            nearest = z
            label = cand_comp[c]
        z = coef[c, 8] / big
        if 0.0 < z < nearest and (z * ca + cb) * z + cc <= 0.0:
            nearest = z
            label = cand_comp[c]
    return label


@njit(cache=True, inline="always")
def _cuts(a, b, own, outside):
    """A label change a -> b that is not the sample's own boundary pair {own, outside}."""
    return a != b and not ((a == own and b == outside) or (a == outside and b == own))


@njit(cache=True, inline="always")
def _candidates(
    q_cam, clip_cam, sphere, near, near_count, quadric_component, k, j, m0, m1, d0, d1, steps, cand_comp, coef
):
    """Of the quadrics ``near[k, j, :near_count[k, j]]`` of camera k, those whose bounding sphere meets a ray
    x(t) = (m0, m1, 1) + t (d0, d1, 0), |t| <= steps: their components into ``cand_comp`` and their
    coefficients along the line into ``coef``; returns their count.

    Sphere (c, rho): some ray with x.c > 0 has g(t) = (|c|^2 - rho^2) |x|^2 - (x.c)^2 <= 0 (a quadratic in t).
    """
    n_cand = 0
    mm = m0 * m0 + m1 * m1 + 1.0
    md = m0 * d0 + m1 * d1
    dd = d0 * d0 + d1 * d1
    for i in range(near_count[k, j]):
        l = near[k, j, i]
        s0 = sphere[k, l, 0]
        s1 = sphere[k, l, 1]
        s2 = sphere[k, l, 2]
        rho = sphere[k, l, 3] * (1.0 + _SPHERE_MARGIN)
        kk = s0 * s0 + s1 * s1 + s2 * s2 - rho * rho
        g0 = -1.0
        g1 = 0.0
        g2 = 0.0
        if kk > 0.0:
            mc = m0 * s0 + m1 * s1 + s2
            dc = d0 * s0 + d1 * s1
            if mc - steps * dc <= 0.0 and mc + steps * dc <= 0.0:
                continue
            g0 = kk * mm - mc * mc
            g1 = 2.0 * (kk * md - mc * dc)
            g2 = kk * dd - dc * dc
            lo_g = min(g0 - steps * g1 + steps * steps * g2, g0 + steps * g1 + steps * steps * g2)
            if g2 > 0.0:
                vertex = -0.5 * g1 / g2
                if -steps < vertex < steps:
                    lo_g = min(lo_g, g0 + vertex * (g1 + vertex * g2))
            if lo_g > 0.0:
                continue
        c = n_cand
        cand_comp[c] = quadric_component[l]
        _coefficients(q_cam, k, l, m0, m1, d0, d1, coef, c, 3)
        _coefficients(clip_cam, k, l, m0, m1, d0, d1, coef, c, 9)
        # discriminant qb^2 - 4 qa qc with qb = coef[6] + coef[7] t, qa = coef[3] + coef[4] t + coef[5] t^2
        coef[c, 0] = coef[c, 6] * coef[c, 6] - 4.0 * coef[c, 8] * coef[c, 3]
        coef[c, 1] = 2.0 * coef[c, 6] * coef[c, 7] - 4.0 * coef[c, 8] * coef[c, 4]
        coef[c, 2] = coef[c, 7] * coef[c, 7] - 4.0 * coef[c, 8] * coef[c, 5]
        coef[c, 15] = g0
        coef[c, 16] = g1
        coef[c, 17] = g2
        n_cand += 1
    return n_cand


@njit(cache=True, inline="always")
def _segment(grid, cam_matrix, cam_lens, cam_dist, k, px, py, nx, ny, steps):
    """The rays of p -+ steps n (undistorted, z = 1) as the line x(t) = m + t d: (m0, m1, d0, d1)."""
    ax, ay = _undistort_fast(grid, cam_matrix, cam_lens, cam_dist, k, px - steps * nx, py - steps * ny)
    bx, by = _undistort_fast(grid, cam_matrix, cam_lens, cam_dist, k, px + steps * nx, py + steps * ny)
    return 0.5 * (ax + bx), 0.5 * (ay + by), (bx - ax) / (2.0 * steps), (by - ay) / (2.0 * steps)


@njit(cache=True, inline="always")
def _mark(t_lo, t_hi, r, covered):
    """covered[t + r + 1] = True for the integers t in [t_lo, t_hi] (widened by _WIDEN) within [-r - 1, r + 1]."""
    first = max(-r - 1, int(np.ceil(max(t_lo - _WIDEN, -r - 2.0))))
    last = min(r + 1, int(np.floor(min(t_hi + _WIDEN, r + 2.0))))
    for t in range(first, last + 1):
        covered[t + r + 1] = True


@njit(cache=True, inline="always")
def _roots(c0, c1, c2):
    """Real roots t1 <= t2 of c0 + c1 t + c2 t^2 (c2 != 0) and whether there are any."""
    delta = c1 * c1 - 4.0 * c2 * c0
    if delta < 0.0:
        return 0.0, 0.0, False
    root = np.sqrt(delta)
    q = -0.5 * (c1 + root) if c1 >= 0.0 else -0.5 * (c1 - root)
    t1 = q / c2
    t2 = c0 / q if q != 0.0 else t1
    if t1 > t2:
        return t2, t1, True
    return t1, t2, True


@njit(cache=True, inline="always")
def _coverage(n_cand, cand_comp, coef, own, outside, r, covered):
    """Mark the points t (``covered[t + r + 1]``) where a candidate that matters may be hit: its discriminant
    is >= 0 there and the ray meets its bounding sphere (analytic roots of both quadratics, slightly widened).
    When the label just outside is the background, only candidates of components other than {own, outside}
    matter: elsewhere every label is own or outside, and no change cuts.  Otherwise every candidate matters:
    elsewhere the label is -1 for sure."""
    for i in range(2 * r + 3):
        covered[i] = False
    span = r + 2.0
    for c in range(n_cand):
        comp = cand_comp[c]
        if outside == -1 and (comp == own or comp == outside):
            continue
        # the sphere: g(t) <= 0 on [s_lo, s_hi] (or everywhere when g is not convex: conservative)
        s_lo = -span
        s_hi = span
        if coef[c, 17] > 0.0:
            u1, u2, real = _roots(coef[c, 15], coef[c, 16], coef[c, 17])
            if not real:
                continue
            s_lo = max(s_lo, u1)
            s_hi = min(s_hi, u2)
        d0 = coef[c, 0]
        d1 = coef[c, 1]
        d2 = coef[c, 2]
        if d2 == 0.0:
            if d1 == 0.0:
                if d0 >= 0.0:
                    _mark(s_lo, s_hi, r, covered)
            elif d1 > 0.0:
                _mark(max(s_lo, -d0 / d1), s_hi, r, covered)
            else:
                _mark(s_lo, min(s_hi, -d0 / d1), r, covered)
            continue
        t1, t2, real = _roots(d0, d1, d2)
        if not real:
            if d2 > 0.0:
                _mark(s_lo, s_hi, r, covered)
        elif d2 > 0.0:
            _mark(s_lo, min(s_hi, t1), r, covered)
            _mark(max(s_lo, t2), s_hi, r, covered)
        else:
            _mark(max(s_lo, t1), min(s_hi, t2), r, covered)


@njit(cache=True, inline="always")
def _side(sign, r, n_cand, cand_comp, coef, own, outside, first, covered):
    """Walk t = sign, 2 sign, ... (r + 1) sign; at the first cutting change between |t| and |t| + 1 return
    floor((|t| + 1/2) / 2), or r when there is none.  ``first`` is the exact label at t = sign, or _UNKNOWN.
    A pair is only labelled exactly when one of its points is ``covered`` (see :func:`_coverage`)."""
    a = first
    for t in range(1, r + 1):  # a change between t and t + 1 (times sign)
        ta = sign * t
        tb = sign * (t + 1)
        b = _UNKNOWN
        if covered[ta + r + 1] or covered[tb + r + 1]:
            if a == _UNKNOWN:
                a = _label_at(float(ta), n_cand, cand_comp, coef)
            b = _label_at(float(tb), n_cand, cand_comp, coef)
            if _cuts(a, b, own, outside):
                return min(r, (2 * t + 1) // 4)
        a = b
    return r


@njit(cache=True, nogil=True)
def search_limits(
    q_cam,
    clip_cam,
    sphere,
    near,
    near_count,
    quadric_component,
    cam_matrix,
    cam_lens,
    cam_dist,
    grid,
    count,
    s_cam,
    s_comp,
    s_quadric,
    s_pixel,
    s_normal,
    r,
    cand_comp,
    coef,
    covered,
    o_lo,
    o_hi,
    o_outside,
    o_depth,
    depths,
):
    """Per sample, the search interval ``[lo, hi]`` (within ``[-r, r]``) that ends half way to the next
    predicted edge along its line that is not the sample's own boundary pair, and the label just outside it
    (``o_outside``: the component seen at ``t = +1``, -1 for the background).  With ``depths``, also how far in
    the sample's own component reaches along the line (``o_depth``: the first ``t >= 1`` at which ``-t`` is not
    its label, ``r + 1`` if none within ``r``): the width of a limb across its outline.

    ``q_cam``, ``clip_cam``, ``sphere``, ``near``, ``near_count`` come from :func:`prepare` (with the same
    ``r``), ``grid`` from :func:`undistort_grid`; ``cand_comp`` (Q,) int, ``coef`` (Q, NCOEF) and ``covered``
    (at least 2 r + 3 booleans) are scratch.  The labels are walked outwards from the sample on each side up
    to the first cut, and a pair of neighbours is only labelled exactly when it may cut (see
    :func:`_coverage`).
    """
    steps = float(r + 1)
    for smp in range(count):
        k = s_cam[smp]
        own = s_comp[smp]
        m0, m1, d0, d1 = _segment(
            grid,
            cam_matrix,
            cam_lens,
            cam_dist,
            k,
            s_pixel[smp, 0],
            s_pixel[smp, 1],
            s_normal[smp, 0],
            s_normal[smp, 1],
            steps,
        )
        n_cand = _candidates(
            q_cam,
            clip_cam,
            sphere,
            near,
            near_count,
            quadric_component,
            k,
            s_quadric[smp],
            m0,
            m1,
            d0,
            d1,
            steps,
            cand_comp,
            coef,
        )
        outside = _label_at(1.0, n_cand, cand_comp, coef)
        o_outside[smp] = outside
        if depths:
            depth = r + 1
            for t in range(1, r + 1):
                if _label_at(-float(t), n_cand, cand_comp, coef) != own:
                    depth = t
                    break
            o_depth[smp] = depth
        _coverage(n_cand, cand_comp, coef, own, outside, r, covered)
        o_hi[smp] = _side(1, r, n_cand, cand_comp, coef, own, outside, outside, covered)
        o_lo[smp] = -_side(-1, r, n_cand, cand_comp, coef, own, outside, _UNKNOWN, covered)


@njit(cache=True)
def line_labels(
    q_cam,
    clip_cam,
    sphere,
    quadric_component,
    cam_matrix,
    cam_lens,
    cam_dist,
    grid,
    k,
    px,
    py,
    nx,
    ny,
    r,
    cand_comp,
    coef,
    out,
):
    """The labels :func:`search_limits` walks, for one sample in camera k (every quadric a candidate when its
    sphere meets the segment): ``out[t + r + 1]`` for the pixels ``p + t n``, ``t`` in ``[-r - 1, r + 1]``."""
    n_quadrics = q_cam.shape[1]
    near = np.empty((k + 1, 1, n_quadrics), np.int64)
    near_count = np.full((k + 1, 1), n_quadrics, np.int64)
    for l in range(n_quadrics):
        near[k, 0, l] = l
    steps = float(r + 1)
    m0, m1, d0, d1 = _segment(grid, cam_matrix, cam_lens, cam_dist, k, px, py, nx, ny, steps)
    n_cand = _candidates(
        q_cam, clip_cam, sphere, near, near_count, quadric_component, k, 0, m0, m1, d0, d1, steps, cand_comp, coef
    )
    for t in range(-r - 1, r + 2):
        out[t + r + 1] = _label_at(float(t), n_cand, cand_comp, coef)


class Ownership:
    """The search limits of a tracker's samples, with every buffer allocated once for a model and a rig.

    ``limits(placed, samples, r)`` fills ``lo``/``hi`` for the first ``samples.count`` samples, from the
    camera-frame quadrics that the outline stage left in ``placed`` (:class:`tracker.tracking.samples.Placed`).
    """

    def __init__(self, model, rig, capacity: int, max_range: int, grid: np.ndarray | None = None):
        """Buffers for ``capacity`` samples searched at most ``max_range`` pixels either side, over the rig's
        :func:`undistort_grid` (``grid``, when it is already made for ``rig``)."""
        n_cams, n_quadrics = len(rig.names), model.quadric.shape[0]
        self.model, self.rig, self.max_range = model, rig, max_range
        self.grid = undistort_grid(rig) if grid is None else grid
        self.scale = pixel_scale(self.grid)
        self.near = np.zeros((n_cams, n_quadrics, n_quadrics), np.int64)
        self.near_count = np.zeros((n_cams, n_quadrics), np.int64)
        self.candidates = np.zeros(n_quadrics, np.int64)
        self.coefficients = np.zeros((n_quadrics, NCOEF))
        self.covered = np.zeros(2 * max_range + 3, np.bool_)
        self.lo = np.zeros(capacity, np.int64)
        self.hi = np.zeros(capacity, np.int64)
        self.outside = np.zeros(capacity, np.int64)
        self.depth = np.zeros(capacity, np.int64)

    def spare(self) -> Ownership:
        """Buffers of its own for a search beside this one's, over the same model, rig and grid (the grid only
        depends on the rig, and costs the most to make)."""
        return Ownership(self.model, self.rig, len(self.lo), self.max_range, self.grid)

    def limits(self, placed, samples, r: int, *, depths: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Fill ``lo``/``hi`` and ``outside`` (and, with ``depths``, ``depth``) of the first ``samples.count``
        samples (:func:`search_limits`); returns ``lo`` and ``hi``."""
        m, rig = self.model, self.rig
        prepare(placed.cone, self.scale, r, self.near, self.near_count)
        search_limits(
            placed.quadric,
            placed.clip,
            placed.sphere,
            self.near,
            self.near_count,
            m.quadric_component,
            rig.matrix,
            rig.lens,
            rig.distortion,
            self.grid,
            samples.count,
            samples.camera,
            samples.component,
            samples.quadric,
            samples.pixel,
            samples.normal,
            r,
            self.candidates,
            self.coefficients,
            self.covered,
            self.lo,
            self.hi,
            self.outside,
            self.depth,
            depths,
        )
        return self.lo[: samples.count], self.hi[: samples.count]
