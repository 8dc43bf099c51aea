"""Which parts the images hold in a frame, and which only the prior and the joints carry (docs/method-tracking.md,
section 6, "Which parts the images hold").

The cues that place a part where the images show it, the edges and the colour lines along its outline, give each
component ``i`` an information ``E_i`` (6 x 6) about its body twist ``alpha`` in the frame's last iteration
(:meth:`tracker.tracking.cue.Cue.evidence`): ``sum w L^T L`` over its samples that found something.  A twist moves
each of its outline samples along its normal by ``L alpha`` pixels, so

    G_i = mean over part i's searched samples of L^T L       (every view)

gives the mean squared motion of its outline in the images, ``alpha^T G_i alpha`` (pixels^2), and its null space
holds the motions no view shows (a cone turned about its axis).  The images hold the part in its least-seen
direction by

    lambda_i = min over alpha in range(G_i) of  alpha^T E_i alpha / alpha^T G_i alpha,

their information per pixel^2 of that motion: ``1 / sqrt(lambda_i)`` is how far (pixels, root mean square over its
outline) the part can move in that direction for the cost of one well-fitting sample.  Whether lambda_i reaches a
bound ``l`` is whether ``E_i - l G_i`` is positive semi-definite (the two share the null space, being sums over the
same rows), which one Cholesky factorisation of a 6 x 6 says (:func:`holds`).  Depth seen from one camera
alone moves the outline little, and counts by the little it moves it.  A part is :data:`HELD` (:mod:`tracker.status`)
when that is at most ``held_within`` pixels, :data:`UNSEEN` when no cue reads anything of it (hidden from every view,
no edge found, no landmark on it), and :data:`LOOSE` between: the images see it, or the detector places a landmark
on it (which it also does where nothing shows the part), but the prior and the joints carry it in some direction.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.status import HELD, LOOSE, UNSEEN

ROUNDING = 1e-12
"""The share of the largest diagonal element of E_i + least G_i added to E_i - least G_i before it is factorised
(:func:`holds`): above the rounding of a direction that neither moves (a cone turned about its axis), far below the
outline motion of any direction a view shows (one camera's depth: a thousandth of the others)."""


@njit(cache=True, nogil=True)
def outline_motion(jacobian, component, lo, hi, count, n_components):
    """G_i (n_components, 6, 6): the mean over each component's first ``count`` samples whose search is not empty
    (``lo <= hi``) of L^T L, ``jacobian`` (S, 6) their rows L; zero for a component with none."""
    out = np.zeros((n_components, 6, 6))
    samples = np.zeros(n_components)
    for s in range(count):
        if lo[s] > hi[s]:
            continue
        i = component[s]
        samples[i] += 1.0
        for a in range(6):
            for b in range(a, 6):
                out[i, a, b] += jacobian[s, a] * jacobian[s, b]
    for i in range(n_components):
        if samples[i] > 0.0:
            for a in range(6):
                for b in range(a, 6):
                    out[i, a, b] /= samples[i]
                    out[i, b, a] = out[i, a, b]
    return out


@njit(cache=True, nogil=True)
def holds(evidence, motion, least):
    """Whether each component's lambda_i (module docstring) is at least ``least`` (N,) bool: whether E_i - least
    G_i is positive semi-definite, ``evidence`` E (N, 6, 6) and ``motion`` G (N, 6, 6), by a Cholesky factorisation
    of it with :data:`ROUNDING` of its diagonal's largest added (a direction neither moves, a cone turned about its
    axis, is then as good as held, and the others decide); False where E_i is nothing."""
    n = evidence.shape[0]
    out = np.zeros(n, np.bool_)
    m = np.empty((6, 6))
    for i in range(n):
        if not evidence[i].any():
            continue
        scale = 0.0
        for a in range(6):
            scale = max(scale, evidence[i, a, a] + least * motion[i, a, a])
        for a in range(6):
            for b in range(6):
                m[a, b] = evidence[i, a, b] - least * motion[i, a, b]
            m[a, a] += ROUNDING * scale
        ok = True
        for j in range(6):  # Cholesky, in place in the lower triangle
            d = m[j, j]
            for k in range(j):
                d -= m[j, k] * m[j, k]
            if d <= 0.0:
                ok = False
                break
            m[j, j] = np.sqrt(d)
            for r in range(j + 1, 6):
                v = m[r, j]
                for k in range(j):
                    v -= m[r, k] * m[j, k]
                m[r, j] = v / m[j, j]
        out[i] = ok
    return out


def held_codes(evidence: np.ndarray, motion: np.ndarray, *, within: float, seen: np.ndarray) -> np.ndarray:
    """Each component's code (N,) int8: :data:`HELD` where ``evidence`` (N, 6, 6) places its outline within
    ``within`` pixels in its least-seen direction of ``motion`` (N, 6, 6) (lambda_i >= 1 / within^2, :func:`holds`),
    :data:`UNSEEN` where it is nothing and the part is not ``seen`` (N,) bool by any other cue, :data:`LOOSE`
    otherwise (module docstring)."""
    codes = np.where(holds(evidence, motion, 1.0 / (within * within)), HELD, LOOSE).astype(np.int8)
    codes[~seen & ~evidence.any(axis=(1, 2))] = UNSEEN
    return codes
