"""Part kinematics: x = c + R (s + d), L against central differences, Ldot qdot against a
difference of L qdot along a trajectory, the lumped mass (docs/method-physics.md,
sections 2, 3 and 7)."""

import numpy as np

from tracker.geometry.se3 import exp_so3
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

# a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3
LOW = np.array([0.5, 0.1, 0.1, 0.1, 0.3, 0.3, -0.8, -0.8, -1.0, -1.0, 0.05])
HIGH = np.array([3.0, 1.0, 1.0, 1.0, 1.7, 1.7, 0.8, 0.8, 1.0, 1.0, 1.0])


def random_part(rng, n_nodes=5):
    """A part at random nodes away from the singular meridians and poles."""
    return kin.Part(
        c=rng.normal(size=3),
        rotation=exp_so3(rng.normal(size=3)),
        q_s=rng.uniform(LOW, HIGH),
        d=0.1 * rng.normal(size=(n_nodes, 3)),
        u=rng.uniform(-1.3, 1.3, n_nodes),
        v=rng.uniform(-np.pi, np.pi, n_nodes),
    )


def test_positions_are_c_plus_r_times_s_plus_d():
    rng = np.random.default_rng(1)
    part = random_part(rng)
    expected = part.c + (part.rotation @ (sq.shape(part.q_s, part.u, part.v) + part.d).T).T
    np.testing.assert_allclose(kin.positions(part), expected, atol=1e-14)
    assert part.n_coordinates == 6 + 11 + 15


def test_jacobian_matches_central_differences():
    """Every column of L, with phi perturbed as R <- Exp([dphi]x) R, over 50 random parts."""
    rng = np.random.default_rng(2)
    h = 1e-6
    worst = 0.0
    for _ in range(50):
        part = random_part(rng)
        n = part.n_coordinates
        numeric = np.stack(
            [
                (kin.positions(kin.retract(part, h * e)) - kin.positions(kin.retract(part, -h * e))) / (2 * h)
                for e in np.eye(n)
            ],
            axis=-1,
        )
        worst = max(worst, np.abs(kin.jacobians(part) - numeric).max())
    assert worst < 1e-7, worst


def test_jacobian_blocks():
    rng = np.random.default_rng(3)
    part = random_part(rng, n_nodes=4)
    big_l = kin.jacobians(part)
    np.testing.assert_array_equal(big_l[:, :, 0:3], np.broadcast_to(np.eye(3), (4, 3, 3)))
    np.testing.assert_allclose(big_l[:, :, kin.SHAPE], part.rotation @ sq.jacobian(part.q_s, part.u, part.v))
    for i in range(4):
        d_columns = big_l[i, :, kin.SHAPE.stop :].reshape(3, 4, 3)
        np.testing.assert_array_equal(d_columns[:, i], part.rotation)
        assert not np.delete(d_columns, i, axis=1).any()


def test_retract_keeps_the_rotation_orthonormal():
    rng = np.random.default_rng(4)
    part = random_part(rng)
    for _ in range(20):
        part = kin.retract(part, rng.normal(size=part.n_coordinates))
    np.testing.assert_allclose(part.rotation @ part.rotation.T, np.eye(3), atol=1e-13)


def _trajectory_l_qdot(part, qdot, t):
    """L(q(t)) qdot along q(t) = q (+) t qdot (constant rates, constant world angular velocity)."""
    return kin.jacobians(kin.retract(part, t * qdot)) @ qdot


def _eq_43(part, qdot):
    """w x (w x R p) + 2 w x R pdot: the velocity product without R Jdot qdot_s."""
    w = qdot[3:6]
    rp = kin.positions(part) - part.c
    pdot = sq.jacobian(part.q_s, part.u, part.v) @ qdot[kin.SHAPE] + qdot[kin.SHAPE.stop :].reshape(-1, 3)
    return np.cross(w, np.cross(w, rp)) + 2 * np.cross(w, pdot @ part.rotation.T)


def test_velocity_product_matches_a_difference_of_l_qdot():
    """Ldot qdot = d/dt (L qdot) along the trajectory, with |qdot_s| = 0.3 as in the note."""
    rng = np.random.default_rng(5)
    h = 1e-5
    worst, worst_eq_43 = 0.0, 0.0
    for _ in range(50):
        part = random_part(rng)
        qdot = rng.normal(size=part.n_coordinates)
        qdot[kin.SHAPE] *= 0.3 / np.linalg.norm(qdot[kin.SHAPE])
        numeric = (_trajectory_l_qdot(part, qdot, h) - _trajectory_l_qdot(part, qdot, -h)) / (2 * h)
        worst = max(worst, np.abs(kin.velocity_products(part, qdot) - numeric).max())
        worst_eq_43 = max(worst_eq_43, np.abs(_eq_43(part, qdot) - numeric).max())
    assert worst < 1e-6, worst
    assert worst_eq_43 > 1e-2, worst_eq_43  # R Jdot qdot_s matters


def test_velocity_product_of_a_rigid_motion_is_centripetal():
    rng = np.random.default_rng(6)
    part = random_part(rng)
    qdot = np.zeros(part.n_coordinates)
    qdot[0:6] = rng.normal(size=6)
    rp = kin.positions(part) - part.c
    w = qdot[3:6]
    np.testing.assert_allclose(kin.velocity_products(part, qdot), np.cross(w, np.cross(w, rp)), atol=1e-13)


def test_lumped_mass():
    rng = np.random.default_rng(7)
    part = random_part(rng, n_nodes=4)
    big_l = kin.jacobians(part)
    masses = rng.uniform(0.5, 2.0, 4)
    qdot = rng.normal(size=part.n_coordinates)
    m = kin.lumped_mass(big_l, masses)
    kinetic = 0.5 * np.sum(masses * np.sum((big_l @ qdot) ** 2, axis=1))
    np.testing.assert_allclose(0.5 * qdot @ m @ qdot, kinetic, rtol=1e-12)
    assert np.linalg.matrix_rank(m) <= 3 * 4  # a deformable part alone is singular
    rigid = kin.lumped_mass(big_l[:, :, :6], masses)
    assert np.linalg.eigvalsh(rigid).min() > 0.0
    regularized = kin.lumped_mass(big_l, masses, regularizer=1e-3)
    np.testing.assert_allclose(regularized - m, 1e-3 * np.eye(part.n_coordinates), atol=1e-15)
