"""SE(3): exp/log against scipy's expm, the group axioms and the adjoint identity
(docs/method-tracking.md, section 8)."""

import numpy as np
import pytest
from scipy.linalg import expm

from tracker.geometry import se3


def _twists(seed, count=200, scale=1.0):
    return np.random.default_rng(seed).normal(scale=scale, size=(count, 6))


def test_generators_order_and_hat():
    g = se3.generators()
    assert np.allclose(g[0][0:3, 3], [1, 0, 0]) and np.allclose(g[2][0:3, 3], [0, 0, 1])
    # G4 is a right-handed rotation about x: it maps y to z
    assert np.allclose(g[3][0:3, 0:3] @ [0, 1, 0], [0, 0, 1])
    for alpha in _twists(0, 20):
        assert np.allclose(np.tensordot(alpha, g, axes=1), se3.hat(alpha), atol=0)


@pytest.mark.parametrize("scale", [1e-9, 1e-5, 1e-3, 1.0, 3.0])
def test_exp_matches_expm(scale):
    for alpha in _twists(1, 100, scale):
        assert np.abs(se3.exp(alpha) - expm(se3.hat(alpha))).max() < 1e-12


@pytest.mark.parametrize("angle", [1e-9, 1e-6, 1e-4, 1e-2, 1.0, 3.0, np.pi - 1e-6])
def test_log_inverts_exp(angle):
    rng = np.random.default_rng(2)
    for _ in range(50):
        axis = rng.normal(size=3)
        alpha = np.concatenate([rng.normal(size=3), angle * axis / np.linalg.norm(axis)])
        back = se3.log(se3.exp(alpha))
        assert np.abs(back - alpha).max() < 1e-9 * max(1.0, np.abs(alpha).max())


def test_exp_of_log_for_random_poses():
    rng = np.random.default_rng(3)
    for _ in range(100):
        pose = se3.from_rotvec(rng.normal(size=3) * 2.0, rng.normal(size=3))
        assert np.abs(se3.exp(se3.log(pose)) - pose).max() < 1e-12


def test_group_axioms():
    rng = np.random.default_rng(4)
    a, b, c = (se3.exp(x) for x in rng.normal(size=(3, 6)))
    assert np.allclose((a @ b) @ c, a @ (b @ c), atol=1e-12)
    assert np.allclose(a @ se3.inverse(a), np.eye(4), atol=1e-12)
    assert np.allclose(se3.exp(np.zeros(6)), np.eye(4))
    assert np.allclose(se3.inverse(a), np.linalg.inv(a), atol=1e-12)
    assert np.allclose(se3.between(a, b), np.linalg.inv(a) @ b, atol=1e-12)


def test_adjoint_identity():
    rng = np.random.default_rng(5)
    for _ in range(50):
        e = se3.exp(rng.normal(size=6))
        alpha = rng.normal(size=6)
        lhs = e @ se3.exp(alpha) @ se3.inverse(e)
        assert np.abs(lhs - se3.exp(se3.adjoint(e) @ alpha)).max() < 1e-12
        assert np.allclose(se3.adjoint(se3.inverse(e)), np.linalg.inv(se3.adjoint(e)), atol=1e-12)


def test_point_velocity_matches_finite_differences():
    rng = np.random.default_rng(6)
    x, alpha = rng.normal(size=3), rng.normal(size=6)
    eps = 1e-6
    moved = [(se3.exp(s * eps * alpha) @ np.append(x, 1.0))[0:3] for s in (1.0, -1.0)]
    assert np.allclose((moved[0] - moved[1]) / (2 * eps), se3.point_velocity(x) @ alpha, atol=1e-8)


def test_batched_rotation_exp_and_log_match_the_se3_ones():
    rng = np.random.default_rng(9)
    w = np.concatenate(
        [
            rng.normal(size=(20, 3)),
            rng.normal(size=(5, 3)) * 1e-6,
            np.zeros((1, 3)),
            [[np.pi - 1e-3, 0.0, 0.0], [0.0, 2.9, 0.1]],
        ]
    )
    rotations = se3.exp_so3_many(w)
    for i in range(len(w)):
        np.testing.assert_allclose(rotations[i], se3.exp_so3(w[i]), atol=1e-14)
    logs = se3.log_so3_many(rotations)
    for i in range(len(w)):
        np.testing.assert_allclose(logs[i], se3.log_so3(rotations[i]), atol=1e-10)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-6, 1e-2, 1.0, 3.0, np.pi - 1e-6, np.pi])
def test_rotation_angle_is_the_norm_of_log(angle):
    """rotation_angle(R) = |log_so3(R)| to round-off, also where arccos of the trace loses digits
    (near 0), one rotation (a float) or a stack (an array)."""
    rng = np.random.default_rng(5)
    axes = rng.normal(size=(20, 3))
    rotations = se3.exp_so3_many(angle * axes / np.linalg.norm(axes, axis=1, keepdims=True))
    angles = se3.rotation_angle(rotations)
    assert angles.shape == (20,)
    assert np.abs(angles - angle).max() < 1e-15 + 1e-14 * angle
    assert np.abs(angles - np.linalg.norm(se3.log_so3_many(rotations), axis=1)).max() < 1e-14
    assert isinstance(se3.rotation_angle(rotations[0]), float)
    # between two rotations: the angle of Ra^T Rb
    assert abs(se3.rotation_angle(rotations[0].T @ rotations[0]) - 0.0) < 1e-15


def test_from_rotation_builds_transforms():
    r = se3.exp_so3(np.array([0.3, -0.2, 0.1]))
    t = np.array([1.0, 2.0, 3.0])
    e = se3.from_rotation(r, t)
    assert np.array_equal(e[:3, :3], r) and np.array_equal(e[:3, 3], t) and np.array_equal(e[3], [0, 0, 0, 1])
    stack = se3.from_rotation(np.stack([r, r.T]), np.stack([t, -t]))
    assert (
        stack.shape == (2, 4, 4) and np.array_equal(stack[1, :3, :3], r.T) and np.array_equal(stack[1, 3], [0, 0, 0, 1])
    )
    assert np.array_equal(se3.from_rotation(r), se3.from_rotation(r, np.zeros(3)))


@pytest.mark.parametrize("angle", [0.0, 1e-6, 0.4, 2.5])
def test_right_jacobian_matches_finite_differences(angle):
    rng = np.random.default_rng(7)
    axis = rng.normal(size=3)
    w = angle * axis / np.linalg.norm(axis)
    jacobian = se3.right_jacobian_so3(w)
    h = 1e-6
    for k in range(3):
        step = np.eye(3)[k] * h
        # exp(w)^T exp(w + d) = exp(J_r d): its rotation vector over h is J_r's column
        column = (
            se3.log_so3(se3.exp_so3(w).T @ se3.exp_so3(w + step))
            - se3.log_so3(se3.exp_so3(w).T @ se3.exp_so3(w - step))
        ) / (2 * h)
        np.testing.assert_allclose(column, jacobian[:, k], atol=1e-8)
        left = (
            se3.log_so3(se3.exp_so3(w + step) @ se3.exp_so3(w).T)
            - se3.log_so3(se3.exp_so3(w - step) @ se3.exp_so3(w).T)
        ) / (2 * h)
        np.testing.assert_allclose(left, jacobian.T[:, k], atol=1e-8)


def test_cross_is_numpys_to_the_last_bit_when_broadcast():
    """The Jacobians' cross product gives np.cross's very numbers (so that swapping one for the other changes no
    fit), for one vector against many and for many against many broadcast."""
    rng = np.random.default_rng(3)
    one, many, grid = rng.normal(size=3), rng.normal(size=(5, 3)), rng.normal(size=(4, 1, 3))
    for a, b in ((one, many), (many, one), (grid, many), (many * 1e-9, grid * 1e9)):
        assert np.array_equal(se3.cross(a, b), np.cross(a, b))
    assert np.array_equal(se3.cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), [0.0, 0.0, 1.0])
