"""One solve of the whole body (docs/method-tracking.md, sections 3-5): the prior about the predicted pose, the trunk
held near rest, the tree solve, the step and the coercion of the joints, in numba kernels."""

from __future__ import annotations

import numpy as np
from numba import njit

from tracker.chain import coerce_kernel, solve_kernel
from tracker.geometry.se3 import between, exp, exp_so3, log, log_so3


@njit(cache=True)
def add_prior(information, eta, prior, poses, anchor):
    """Gaussian prior on each component's pose about the frame's predicted pose ``anchor``.

    With delta_i = log(E_i^-1 E_anchor_i), the twist that would return E_i to
    the prediction, the cost (alpha_i - delta_i)^T P_i (alpha_i - delta_i) adds
    P_i to C_i and P_i delta_i to eta_i (section 3: it also keeps C_i invertible).
    ``prior`` (N,6,6) holds one P_i per component.
    """
    for i in range(poses.shape[0]):
        delta = log(between(poses[i], anchor[i]))
        information[i] += prior[i]
        eta[i] += prior[i] @ delta


@njit(cache=True, nogil=True)
def hold_kernel(information, eta, poses, trunk, parent, rest, turn, weight):
    """For each joint j of ``trunk`` turned from its ``rest`` by more than ``turn`` radians (the rotation vector
    ``bend`` of rest_j^T R_parent^T R_j), add ``weight`` I to its parent i's rotation block of C_i and ``weight``
    times the rotation vector from R_i to the rotation that would leave j turned ``turn`` the same way,
    R_j exp(bend turn / |bend|)^T rest_j^T, to eta_i (body frame, as :func:`add_prior`)."""
    for j in trunk:
        i = parent[j]
        parent_rotation = np.ascontiguousarray(poses[i, :3, :3])
        rotation = np.ascontiguousarray(poses[j, :3, :3])
        rest_j = np.ascontiguousarray(rest[j, :3, :3])
        bend = log_so3(np.ascontiguousarray(rest_j.T) @ np.ascontiguousarray(parent_rotation.T) @ rotation)
        angle = np.sqrt(bend[0] ** 2 + bend[1] ** 2 + bend[2] ** 2)
        if angle <= turn:
            continue
        back = np.ascontiguousarray(exp_so3(bend * (turn / angle)).T)
        within = rotation @ back @ np.ascontiguousarray(rest_j.T)
        pull = log_so3(np.ascontiguousarray(parent_rotation.T) @ within)
        for a in range(3):
            information[i, 3 + a, 3 + a] += weight
            eta[i, 3 + a] += weight * pull[a]


@njit(cache=True, nogil=True)
def update_kernel(
    information,
    eta,
    prior,
    poses,
    anchor,
    parent,
    D,
    projector,
    rows,
    rest,
    joint_type,
    axis,
    lower,
    upper,
    twist_limit,
    max_turn,
):
    """Prior, tree solve, E_i <- E_i exp(s alpha_i) and coercion in one call (sections 3-5).

    ``s = min(1, max_turn / max_i |w_i|)`` scales the whole body's step (all twists alike, so the
    linearised joint constraints still hold) when a component would turn by more than ``max_turn``
    radians (before the coercion, which may turn it a little more): the linearisation only holds
    for small motions."""
    add_prior(information, eta, prior, poses, anchor)
    alpha = solve_kernel(information, eta, parent, D, rows, poses)
    largest = 0.0
    for i in range(poses.shape[0]):
        largest = max(largest, np.sqrt(alpha[i, 3] ** 2 + alpha[i, 4] ** 2 + alpha[i, 5] ** 2))
    if largest > max_turn:
        alpha *= max_turn / largest
    moved = np.empty_like(poses)
    for i in range(poses.shape[0]):
        moved[i] = poses[i] @ exp(alpha[i])
    return coerce_kernel(moved, parent, rest, projector, rows, joint_type, axis, lower, upper, twist_limit)


def narrowing(first: int, last: int, *, step: int, steps: int) -> int:
    """Search range of step ``step`` of ``steps`` narrowing geometrically from ``first`` to ``last``:
    r_i = r_0 (r_last / r_0)^(i / (n - 1)), rounded, at least 1; ``last`` when there is a single step."""
    if steps < 2:
        return last
    return max(1, round(first * (last / first) ** (step / (steps - 1))))
