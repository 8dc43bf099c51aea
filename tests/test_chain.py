"""Joint constraints, tree solve and coercion (tracker.chain) against docs/method-tracking.md, sections 4-5."""

import numpy as np
import pytest

from tracker import chain
from tracker.geometry import se3

JOINTS = (chain.BALL, chain.HINGE, chain.SLIDE, chain.FIXED, chain.FREE)


def unit(rng, n=3):
    x = rng.normal(size=n)
    return x / np.linalg.norm(x)


def random_tree(rng, n, max_children=7):
    """parent[i] < i, each node with at most max_children children; often bushy at the root."""
    parent = np.full(n, -1, dtype=np.int64)
    children = np.zeros(n, dtype=int)
    for i in range(1, n):
        open_ = np.flatnonzero(children[:i] < max_children)
        p = 0 if (children[0] < max_children and rng.random() < 0.4) else rng.choice(open_)
        parent[i] = p
        children[p] += 1
    return parent


def allowed_motion(rng, joint, point, axis, scale=0.5):
    """A relative twist the joint allows, built from its geometry (not from constraint_rows)."""
    if joint == chain.BALL:
        w = scale * rng.normal(size=3)
        return np.concatenate([np.cross(point, w), w])
    if joint == chain.HINGE:
        return scale * rng.normal() * np.concatenate([np.cross(point, axis), axis])
    if joint == chain.SLIDE:
        return np.concatenate([scale * rng.normal() * axis, np.zeros(3)])
    if joint == chain.FIXED:
        return np.zeros(6)
    return np.concatenate([rng.normal(size=3), scale * rng.normal(size=3)])


def random_model(rng, n, joints=JOINTS, joint_at_origin=False):
    """Random tree, joint types, child-frame joint points/axes, rest transforms T0 and (D, rows)."""
    parent = random_tree(rng, n)
    joint = np.array([chain.FREE] + [joints[rng.integers(len(joints))] for _ in range(n - 1)])
    point = np.zeros((n, 3)) if joint_at_origin else rng.normal(size=(n, 3))
    axis = np.array([unit(rng) for _ in range(n)])
    rest = np.array([se3.from_rotvec(rng.normal(size=3), rng.normal(size=3)) for _ in range(n)])
    D, rows = chain.pack_constraints([chain.constraint_rows(j, p, d) for j, p, d in zip(joint, point, axis)])
    return dict(parent=parent, joint=joint, point=point, axis=axis, rest=rest, D=D, rows=rows)


def valid_poses(rng, model):
    """E_root random, E_i = E_parent T0_i exp(a') with a' a motion the joint allows."""
    n = len(model["parent"])
    poses = np.empty((n, 4, 4))
    poses[0] = se3.from_rotvec(rng.normal(size=3), rng.normal(size=3))
    for i in range(1, n):
        a = allowed_motion(rng, model["joint"][i], model["point"][i], model["axis"][i])
        poses[i] = poses[model["parent"][i]] @ model["rest"][i] @ se3.exp(a)
    return poses


def joint_gap(joint, child, parent, rest, point, axis):
    """Geometric violation of a joint, via the child's pose relative to rest, Delta = T0^-1 E_p^-1 E_c.

    ball: |Delta p - p|; hinge: also |R_Delta d - d|; slide: |R_Delta - I| and the
    translation off the axis; fixed: |Delta - I|; free: 0.
    """
    delta = se3.inverse(rest) @ se3.inverse(parent) @ child
    r, t = delta[0:3, 0:3], delta[0:3, 3]
    if joint == chain.BALL:
        return np.linalg.norm(r @ point + t - point)
    if joint == chain.HINGE:
        return np.linalg.norm(r @ point + t - point) + np.linalg.norm(r @ axis - axis)
    if joint == chain.SLIDE:
        return np.linalg.norm(r - np.eye(3)) + np.linalg.norm(t - (t @ axis) * axis)
    if joint == chain.FIXED:
        return np.linalg.norm(delta - np.eye(4))
    return 0.0


def max_gap(model, poses):
    return max(
        joint_gap(
            model["joint"][i],
            poses[i],
            poses[model["parent"][i]],
            model["rest"][i],
            model["point"][i],
            model["axis"][i],
        )
        for i in range(1, len(poses))
    )


def linear_constraints(parent, D, rows, poses):
    """Dense A with one block row per constrained child: D_i at column i, D_pi at column parent(i)."""
    n = len(parent)
    blocks = []
    for i in range(1, n):
        k, p = rows[i], parent[i]
        if k == 0:
            continue
        block = np.zeros((k, 6 * n))
        block[:, 6 * i : 6 * i + 6] = D[i, :k]
        block[:, 6 * p : 6 * p + 6] = -D[i, :k] @ se3.adjoint(se3.inverse(poses[i]) @ poses[p])
        blocks.append(block)
    return np.vstack(blocks) if blocks else np.zeros((0, 6 * n))


def kkt_solution(information, eta, A):
    """[[2C, A^T], [A, 0]] [alpha; lambda] = [2 C mu; 0] with C block-diagonal and C mu = eta."""
    n = information.shape[0]
    big_c = np.zeros((6 * n, 6 * n))
    for i in range(n):
        big_c[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = information[i]
    m = A.shape[0]
    kkt = np.block([[2 * big_c, A.T], [A, np.zeros((m, m))]])
    rhs = np.concatenate([2 * eta.ravel(), np.zeros(m)])
    return np.linalg.solve(kkt, rhs)[: 6 * n].reshape(n, 6)


def random_information(rng, n):
    """SPD 6x6 per component with spread-out scales and moderate conditioning."""
    a = rng.normal(size=(n, 6, 6)) * 10.0 ** rng.uniform(-1, 1, size=(n, 1, 1))
    return a @ a.transpose(0, 2, 1) + 0.1 * np.eye(6)


def test_constraint_rows_shapes_and_allowed_motion():
    rng = np.random.default_rng(0)
    point, axis = rng.normal(size=3), unit(rng)
    for joint, k in [(chain.FREE, 0), (chain.BALL, 3), (chain.HINGE, 5), (chain.SLIDE, 5), (chain.FIXED, 6)]:
        rows = chain.constraint_rows(joint, point, axis)
        assert rows.shape == (k, 6)
        assert np.linalg.matrix_rank(rows) == k
        if joint != chain.FREE:
            assert np.abs(rows @ allowed_motion(rng, joint, point, axis)).max() < 1e-14
    assert np.allclose(chain.constraint_rows(chain.BALL, point, axis)[:, 3:], -se3.skew(point))
    with pytest.raises(ValueError):
        chain.constraint_rows(chain.HINGE, point, np.zeros(3))


def test_pack_constraints_pads_with_zeros():
    blocks = [np.zeros((0, 6)), np.ones((3, 6)), np.eye(6)]
    D, rows = chain.pack_constraints(blocks)
    assert D.shape == (3, 6, 6) and rows.dtype == np.int64
    assert rows.tolist() == [0, 3, 6]
    assert np.all(D[0] == 0) and np.all(D[1, :3] == 1) and np.all(D[1, 3:] == 0)


@pytest.mark.parametrize("joint", [chain.BALL, chain.HINGE, chain.SLIDE, chain.FIXED])
def test_null_space_of_constraint_pair_keeps_joint_to_second_order(joint):
    """Along null([D12 D21]) the joint gap grows like eps^2 (log-log slope 2); along other
    directions like eps (slope 1).  For a fixed joint the null space is rigid co-motion, so
    the gap there stays at round-off."""
    rng = np.random.default_rng(10 + joint)
    eps = np.geomspace(1e-2, 1e-4, 5)
    for _ in range(5):
        point, axis = rng.normal(size=3), unit(rng)
        rest = se3.from_rotvec(rng.normal(size=3), rng.normal(size=3))
        e_parent = se3.from_rotvec(rng.normal(size=3), rng.normal(size=3))
        e_child = e_parent @ rest @ se3.exp(allowed_motion(rng, joint, point, axis))
        d12 = chain.constraint_rows(joint, point, axis)
        d21 = -d12 @ se3.adjoint(se3.inverse(e_child) @ e_parent)
        pair = np.hstack([d12, d21])
        _, _, vt = np.linalg.svd(pair)
        null = vt[pair.shape[0] :].T
        inside = null @ rng.normal(size=null.shape[1])
        outside = rng.normal(size=12)
        outside -= null @ (null.T @ outside)
        for direction, slope in [(inside, 2.0), (outside, 1.0)]:
            gaps = [
                joint_gap(
                    joint,
                    e_child @ se3.exp(e * direction[:6]),
                    e_parent @ se3.exp(e * direction[6:]),
                    rest,
                    point,
                    axis,
                )
                for e in eps
            ]
            if joint == chain.FIXED and slope == 2.0:
                assert max(gaps) < 1e-12
                continue
            fitted = np.polyfit(np.log(eps), np.log(gaps), 1)[0]
            assert abs(fitted - slope) < 0.05, (joint, slope, fitted)


def test_tree_solve_matches_dense_kkt():
    """300 random trees: max |alpha_tree - alpha_kkt| / max |alpha_kkt| < 1e-9 (relative);
    every linearised constraint |D_i alpha_i + D_pi alpha_p| < 1e-9 (absolute, |alpha| ~ 1)."""
    rng = np.random.default_rng(2024)
    worst_error, worst_residual = 0.0, 0.0
    for trial in range(300):
        n = int(rng.integers(5, 16))
        model = random_model(rng, n)
        if trial % 2:
            poses = valid_poses(rng, model)
        else:
            poses = np.array([se3.from_rotvec(rng.normal(size=3), rng.normal(size=3)) for _ in range(n)])
        information = random_information(rng, n)
        mu = rng.normal(size=(n, 6))
        eta = np.einsum("nij,nj->ni", information, mu)
        alpha = chain.solve(information, eta, parent=model["parent"], D=model["D"], rows=model["rows"], poses=poses)
        A = linear_constraints(model["parent"], model["D"], model["rows"], poses)
        expected = kkt_solution(information, eta, A)
        worst_error = max(worst_error, np.abs(alpha - expected).max() / np.abs(expected).max())
        if A.shape[0]:
            worst_residual = max(worst_residual, np.abs(A @ alpha.ravel()).max())
    assert worst_error < 1e-9
    assert worst_residual < 1e-9


def test_marginal_information_is_the_inverse_of_the_constrained_covariance():
    """50 random trees: the inverse of the information of each alpha_i through the joints equals the i-th diagonal
    block of the constrained solution's covariance, from the dense KKT matrix's inverse, to 1e-6 (relative: that
    matrix's condition number reaches 1e10 with a component of next to no data); that component gets its
    neighbours' information through its joint."""
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(50):
        n = int(rng.integers(3, 12))
        model = random_model(rng, n, joints=(chain.BALL, chain.HINGE, chain.SLIDE, chain.FREE))
        poses = valid_poses(rng, model)
        information = random_information(rng, n)
        information[-1] *= 1e-6  # a component its cues barely see
        A = linear_constraints(model["parent"], model["D"], model["rows"], poses)
        big_c = np.zeros((6 * n, 6 * n))
        for i in range(n):
            big_c[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = information[i]
        m = A.shape[0]
        covariance = np.linalg.inv(np.block([[big_c, A.T], [A, np.zeros((m, m))]]))[: 6 * n, : 6 * n]
        expected = np.array([covariance[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] for i in range(n)])
        basis = chain.motion_basis(chain.row_projectors(model["D"], model["rows"]), model["rows"])
        found = chain.marginal_information(information, parent=model["parent"], poses=poses, basis=basis)
        worst = max(worst, max(np.abs(np.linalg.inv(f) - e).max() / np.abs(e).max() for f, e in zip(found, expected)))
        constrained = model["rows"][-1] > 0 and model["joint"][-1] != chain.FREE
        if constrained:  # its joint's rows are known from its parent's data
            assert np.linalg.eigvalsh(found[-1]).max() > 100 * np.linalg.eigvalsh(information[-1]).max()
    assert worst < 1e-6


def test_tree_solve_star_with_seven_children_and_free_child_independent():
    rng = np.random.default_rng(7)
    n = 9
    parent = np.array([-1, 0, 0, 0, 0, 0, 0, 0, 1])
    joints = [
        chain.FREE,
        chain.BALL,
        chain.HINGE,
        chain.SLIDE,
        chain.FIXED,
        chain.FREE,
        chain.BALL,
        chain.HINGE,
        chain.FREE,
    ]
    D, rows = chain.pack_constraints([chain.constraint_rows(j, rng.normal(size=3), unit(rng)) for j in joints])
    poses = np.array([se3.from_rotvec(rng.normal(size=3), rng.normal(size=3)) for _ in range(n)])
    information = random_information(rng, n)
    eta = rng.normal(size=(n, 6))
    alpha = chain.solve(information, eta, parent=parent, D=D, rows=rows, poses=poses)
    expected = kkt_solution(information, eta, linear_constraints(parent, D, rows, poses))
    assert np.abs(alpha - expected).max() < 1e-9 * np.abs(expected).max()
    for free in (5, 8):
        assert np.allclose(alpha[free], np.linalg.solve(information[free], eta[free]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("joint_at_origin", [True, False])
@pytest.mark.parametrize("joint", [chain.BALL, chain.HINGE, chain.SLIDE, chain.FIXED])
def test_coercion_repairs_joints_exactly(joint, joint_at_origin):
    """Valid poses, E_i <- E_i exp(alpha_i) with small alpha, coerce: joint gap < 1e-9."""
    rng = np.random.default_rng(100 + 2 * joint + joint_at_origin)
    for _ in range(20):
        model = random_model(rng, int(rng.integers(5, 16)), joints=(joint,), joint_at_origin=joint_at_origin)
        poses = valid_poses(rng, model)
        moved = np.array([e @ se3.exp(0.05 * rng.normal(size=6)) for e in poses])
        assert max_gap(model, moved) > 1e-4
        fixed = chain.coerce(moved, parent=model["parent"], rest=model["rest"], D=model["D"], rows=model["rows"])
        assert max_gap(model, fixed) < 1e-9
        assert np.array_equal(fixed[0], moved[0])


def test_coercion_of_valid_poses_is_identity():
    rng = np.random.default_rng(5)
    for _ in range(50):
        model = random_model(rng, int(rng.integers(5, 16)), joint_at_origin=bool(rng.integers(2)))
        poses = valid_poses(rng, model)
        fixed = chain.coerce(poses, parent=model["parent"], rest=model["rest"], D=model["D"], rows=model["rows"])
        assert np.abs(fixed - poses).max() < 1e-12


def test_coercion_projects_arbitrary_poses():
    """Far-off relative poses: the result satisfies every joint, coercing again changes nothing,
    a hinge keeps only the rotation about its axis, and free children are untouched."""
    rng = np.random.default_rng(6)
    for _ in range(30):
        model = random_model(rng, int(rng.integers(5, 16)), joint_at_origin=True)
        n = len(model["parent"])
        poses = np.empty((n, 4, 4))
        poses[0] = se3.from_rotvec(rng.normal(size=3), rng.normal(size=3))
        relative = np.array(
            [se3.exp(np.concatenate([rng.normal(size=3), 2.5 * unit(rng) * rng.random()])) for _ in range(n)]
        )
        for i in range(1, n):
            poses[i] = poses[model["parent"][i]] @ model["rest"][i] @ relative[i]
        fixed = chain.coerce(poses, parent=model["parent"], rest=model["rest"], D=model["D"], rows=model["rows"])
        assert max_gap(model, fixed) < 1e-9
        again = chain.coerce(fixed, parent=model["parent"], rest=model["rest"], D=model["D"], rows=model["rows"])
        assert np.abs(again - fixed).max() < 1e-12
        for i in range(1, n):
            if model["joint"][i] == chain.FREE:
                assert np.array_equal(fixed[i], poses[i])
            if model["joint"][i] == chain.HINGE:
                at_rest = se3.inverse(fixed[model["parent"][i]] @ model["rest"][i])
                d = model["axis"][i]
                twist = se3.log_so3((at_rest @ poses[i])[0:3, 0:3]) @ d
                expected = se3.exp(np.concatenate([np.zeros(3), twist * d]))
                got = at_rest @ fixed[i]
                assert np.abs(got - expected).max() < 1e-12


def test_rejects_parent_after_child():
    eye = np.tile(np.eye(4), (2, 1, 1))
    D, rows, parent = np.zeros((2, 6, 6)), np.zeros(2, dtype=np.int64), np.array([-1, 1])
    with pytest.raises(ValueError):
        chain.coerce(eye, parent=parent, rest=eye, D=D, rows=rows)
    with pytest.raises(ValueError):
        chain.solve(np.tile(np.eye(6), (2, 1, 1)), np.zeros((2, 6)), parent=parent, D=D, rows=rows, poses=eye)


def _single_joint(joint, axis=(1.0, 0.0, 0.0)):
    rows = chain.constraint_rows(joint, np.zeros(3), np.asarray(axis))
    D, n_rows = chain.pack_constraints([np.zeros((0, 6)), rows])
    return np.array([-1, 0]), np.stack([np.eye(4), se3.from_rotvec([0, 0, 0], [0.0, 0.0, -0.3])]), D, n_rows


@pytest.mark.parametrize("angle, expected", [(0.5, 0.5), (1.4, 1.0), (-0.7, -0.2)])
def test_coercion_clamps_a_hinge_to_its_limits(angle, expected):
    parent, rest, D, rows = _single_joint(chain.HINGE)
    poses = np.stack([np.eye(4), rest[1] @ se3.exp(np.array([0, 0, 0, angle, 0, 0]))])
    fixed = chain.coerce(
        poses,
        parent=parent,
        rest=rest,
        D=D,
        rows=rows,
        joint_type=[chain.FREE, chain.HINGE],
        axis=[[0, 0, 0], [1, 0, 0]],
        lower=[-np.inf, -0.2],
        upper=[np.inf, 1.0],
    )
    relative = se3.log(np.linalg.inv(rest[1]) @ fixed[1])
    np.testing.assert_allclose(relative, [0, 0, 0, expected, 0, 0], atol=1e-12)


def test_coercion_clamps_a_slide_to_its_limits():
    parent, rest, D, rows = _single_joint(chain.SLIDE, (0.0, 0.0, 1.0))
    poses = np.stack([np.eye(4), rest[1] @ se3.exp(np.array([0, 0, 0.5, 0, 0, 0]))])
    fixed = chain.coerce(
        poses,
        parent=parent,
        rest=rest,
        D=D,
        rows=rows,
        joint_type=[chain.FREE, chain.SLIDE],
        axis=[[0, 0, 0], [0, 0, 1]],
        lower=[-np.inf, 0.0],
        upper=[np.inf, 0.1],
    )
    np.testing.assert_allclose(se3.log(np.linalg.inv(rest[1]) @ fixed[1]), [0, 0, 0.1, 0, 0, 0], atol=1e-12)


def test_coercion_limits_a_ball_joint_rotation():
    rng = np.random.default_rng(11)
    parent, rest, D, rows = _single_joint(chain.BALL)
    for _ in range(20):
        w = rng.normal(size=3)
        poses = np.stack([np.eye(4), rest[1] @ se3.exp(np.concatenate([np.zeros(3), w]))])
        fixed = chain.coerce(
            poses,
            parent=parent,
            rest=rest,
            D=D,
            rows=rows,
            joint_type=[chain.FREE, chain.BALL],
            axis=np.zeros((2, 3)),
            lower=[-np.inf, 0.0],
            upper=[np.inf, 0.8],
        )
        relative = se3.log(np.linalg.inv(rest[1]) @ fixed[1])
        angle = np.linalg.norm(w)
        expected = w if angle <= 0.8 else w * 0.8 / angle
        np.testing.assert_allclose(relative, np.concatenate([np.zeros(3), expected]), atol=1e-12)


def _swing_twist(rotation: np.ndarray) -> tuple[np.ndarray, float]:
    """Brute force: the swing R exp(-tau z) and the turn tau about z whose removal leaves the smallest rotation,
    found by a dense search over tau refined four times."""

    def swing_angle(tau):
        s = rotation @ se3.exp_so3(np.array([0.0, 0.0, -tau]))
        return np.arccos(np.clip((np.trace(s) - 1) / 2, -1, 1))

    taus = np.linspace(-np.pi, np.pi, 4001)
    best = taus[np.argmin([swing_angle(t) for t in taus])]
    for step in (2e-3, 2e-5, 2e-7, 2e-9):
        around = best + np.linspace(-step, step, 401)
        best = around[np.argmin([swing_angle(t) for t in around])]
    return rotation @ se3.exp_so3(np.array([0.0, 0.0, -best])), (best + np.pi) % (2 * np.pi) - np.pi


def test_a_twist_brought_within_its_limit_keeps_the_swing():
    """within_twist against a brute-force swing-twist split (the swing is the smallest rotation left once the
    turn about z is taken out, so it has none about z)."""
    rng = np.random.default_rng(12)
    for _ in range(40):
        w = unit(rng) * rng.uniform(0.2, 3.0)
        limit = rng.uniform(0.2, 2.0)
        swing, tau = _swing_twist(se3.exp_so3(w))
        out = chain.within_twist(w, limit)
        kept_swing, kept_tau = _swing_twist(se3.exp_so3(out))
        np.testing.assert_allclose(kept_swing, swing, atol=1e-6)
        assert kept_tau == pytest.approx(np.clip(tau, -limit, limit), abs=1e-6)
        if abs(tau) <= limit:
            np.testing.assert_array_equal(out, w)


def test_coercion_limits_a_ball_joint_twist_then_its_angle():
    rng = np.random.default_rng(13)
    parent, rest, D, rows = _single_joint(chain.BALL)
    for _ in range(20):
        w = unit(rng) * rng.uniform(0.5, 3.0)
        poses = np.stack([np.eye(4), rest[1] @ se3.exp(np.concatenate([np.zeros(3), w]))])
        options = dict(parent=parent, rest=rest, D=D, rows=rows, joint_type=[chain.FREE, chain.BALL])
        options.update(axis=np.zeros((2, 3)), lower=[-np.inf, 0.0])
        twisted = chain.coerce(poses, upper=[np.inf, np.inf], twist=[np.inf, 1.0], **options)
        relative = se3.log(np.linalg.inv(rest[1]) @ twisted[1])
        np.testing.assert_allclose(relative, np.concatenate([np.zeros(3), chain.within_twist(w, 1.0)]), atol=1e-12)
        both = chain.coerce(poses, upper=[np.inf, 0.8], twist=[np.inf, 1.0], **options)
        turn = chain.within_twist(w, 1.0)
        expected = turn * min(1.0, 0.8 / np.linalg.norm(turn))
        np.testing.assert_allclose(
            se3.log(np.linalg.inv(rest[1]) @ both[1]), np.concatenate([np.zeros(3), expected]), atol=1e-12
        )


def test_the_twist_s_gradient_matches_finite_differences():
    rng = np.random.default_rng(14)
    h = 1e-6
    for _ in range(40):
        w = unit(rng) * rng.uniform(0.0, 3.0)
        expected = [(chain.twist_angle(w + h * e) - chain.twist_angle(w - h * e)) / (2 * h) for e in np.eye(3)]
        np.testing.assert_allclose(chain.twist_gradient(w), expected, atol=1e-6)
