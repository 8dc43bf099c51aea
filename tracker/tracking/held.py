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
outline) the part can move in that direction for the cost of one well-fitting sample.  Depth seen from one camera
alone moves the outline little, and counts by the little it moves it.  A part is :data:`HELD` (:mod:`tracker.status`)
when that is at most ``held_within`` pixels, :data:`UNSEEN` when no cue reads anything of it (hidden from every view,
no edge found, no landmark on it), and :data:`LOOSE` between: the images see it, or the detector places a landmark
on it (which it also does where nothing shows the part), but the prior and the joints carry it in some direction.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.status import HELD, LOOSE, UNSEEN

SEEN = 1e-9
"""The share of a part's largest outline motion below which a direction is one no view shows (the range of G_i)."""


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


def firmness(evidence: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """lambda_i (N,): the least information ``evidence`` (N, 6, 6) gives per pixel^2 of mean squared outline motion
    ``motion`` (N, 6, 6), over the range of each G_i (module docstring); 0 where either is nothing."""
    out = np.zeros(len(evidence))
    for i, (e, g) in enumerate(zip(evidence, motion)):
        if not e.any() or not g.any():
            continue
        values, vectors = np.linalg.eigh(g)
        kept = values > SEEN * values[-1]
        basis = vectors[:, kept] / np.sqrt(values[kept])  # G_i is the identity on it
        out[i] = max(float(np.linalg.eigvalsh(basis.T @ e @ basis)[0]), 0.0)
    return out


def held_codes(evidence: np.ndarray, motion: np.ndarray, *, within: float, seen: np.ndarray) -> np.ndarray:
    """Each component's code (N,) int8: :data:`HELD` where ``evidence`` (N, 6, 6) places its outline within
    ``within`` pixels in its least-seen direction of ``motion`` (N, 6, 6) (lambda_i >= 1 / within^2),
    :data:`UNSEEN` where it is nothing and the part is not ``seen`` (N,) bool by any other cue, :data:`LOOSE`
    otherwise (module docstring)."""
    codes = np.where(firmness(evidence, motion) * within * within >= 1.0, HELD, LOOSE).astype(np.int8)
    codes[~seen & ~evidence.any(axis=(1, 2))] = UNSEEN
    return codes
