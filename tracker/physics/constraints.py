"""Point-to-point constraints between parts (docs/method-physics.md, section 4).

Constraint j joins a point of part A_j to a point of part B_j:

    C_j = x_A - x_B,   Cdot_j = L_A qdot_A - L_B qdot_B

Stacking k of them gives C (3k,) and G (3k x n_total) with +L_A in the columns of A_j and
-L_B in those of B_j, so Cdot = G qdot, and the constraint forces f_c (3k,) act on the parts as
G^T f_c.  The parts' coordinates are concatenated in the order of their blocks; mass and damping
matrices are block diagonal, one block per part, and are given as the list of blocks.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla


def stack_jacobian(
    jacobians_a: list[np.ndarray],
    jacobians_b: list[np.ndarray],
    *,
    parts_a: list[int],
    parts_b: list[int],
    sizes: list[int],
) -> np.ndarray:
    """G (3k x sum(sizes)): row block j is +L_A (3 x sizes[parts_a[j]]) in part A_j's columns
    and -L_B in part B_j's (section 4, 'k constraints')."""
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    g = np.zeros((3 * len(parts_a), offsets[-1]))
    for j, (l_a, l_b, a, b) in enumerate(zip(jacobians_a, jacobians_b, parts_a, parts_b)):
        g[3 * j : 3 * j + 3, offsets[a] : offsets[a + 1]] += l_a
        g[3 * j : 3 * j + 3, offsets[b] : offsets[b + 1]] -= l_b
    return g


def stack_differences(values_a: np.ndarray, values_b: np.ndarray) -> np.ndarray:
    """(a_j - b_j) stacked into (3k,): C from the joined points' positions (k, 3), and Gdot qdot
    from their velocity products Ldot qdot (section 4)."""
    return (np.asarray(values_a) - np.asarray(values_b)).ravel()


def block_solve(blocks: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """blockdiag(blocks)^-1 x by one Cholesky factorisation per symmetric positive definite block."""
    out = np.empty_like(x, dtype=np.float64)
    start = 0
    for block in blocks:
        stop = start + block.shape[0]
        out[start:stop] = sla.cho_solve(sla.cho_factor(block), x[start:stop])
        start = stop
    return out


def second_order_system(
    g: np.ndarray,
    mass_blocks: list[np.ndarray],
    forces: np.ndarray,
    *,
    qdot: np.ndarray,
    gdot_qdot: np.ndarray,
    violation: np.ndarray,
    a: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(N, r) of N f_c + r = 0 for M qddot = F + G^T f_c with Cddot + 2a Cdot + a^2 C = 0:

        N = G M^-1 G^T,   r = Gdot qdot + 2a Cdot + a^2 C + G M^-1 F,   Cdot = G qdot

    (section 4, second order); F = g_q + f_q - K q - D qdot.  The resulting violation decays as
    C(t) = (C0 + (Cdot0 + a C0) t) e^{-at}.
    """
    n = g @ block_solve(mass_blocks, g.T)
    r = gdot_qdot + 2.0 * a * (g @ qdot) + a * a * violation + g @ block_solve(mass_blocks, forces)
    return n, r


def first_order_system(
    g: np.ndarray,
    damping_blocks: list[np.ndarray] | None,
    qdot_free: np.ndarray,
    *,
    violation: np.ndarray,
    a: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(N, r) of N f_c + r = 0 for D qdot = F + G^T f_c with Cdot + a C = 0:

        N = G D^-1 G^T,   r = a C + G qdot_free,   qdot_free = D^-1 F

    (section 4, first order); then qdot = qdot_free + D^-1 G^T f_c and C(t) = C0 e^{-at}.
    ``damping_blocks`` None stands for D = I (the paper's fitting), N = G G^T, without a solve.
    """
    d_inv_gt = g.T if damping_blocks is None else block_solve(damping_blocks, g.T)
    return g @ d_inv_gt, a * violation + g @ qdot_free


def solve_forces(n: np.ndarray, r: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """f_c with N f_c + r = 0 (section 4).

    Cholesky when N is well conditioned; otherwise (redundant constraints, e.g. closed loops,
    make the positive semi-definite N singular) the minimum-norm least-squares solution, with
    singular values below rcond times the largest treated as zero.  The Cholesky branch is taken
    when it succeeds and its pivots imply a condition number below 1 / rcond.
    """
    try:
        factor = sla.cho_factor(n)
    except np.linalg.LinAlgError:
        factor = None
    if factor is not None:
        pivots = np.abs(np.diag(factor[0])) ** 2
        if pivots.min() > rcond * pivots.max():
            return -sla.cho_solve(factor, r)
    return -sla.lstsq(n, r, cond=rcond)[0]
