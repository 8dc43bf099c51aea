"""Deformable superquadric shells: s, J against central differences, normals, the mesh, the
displacement interpolation and the membrane stiffness (docs/method-physics.md,
sections 1, 3 and 7)."""

import numpy as np
import pytest

from tracker.physics import superquadric as sq

# a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3
LOW = np.array([0.5, 0.1, 0.1, 0.1, 0.1, 0.1, -1.0, -1.0, -1.0, -1.0, 0.01])
HIGH = np.array([3.0, 1.0, 1.0, 1.0, 1.9, 1.9, 1.0, 1.0, 1.0, 1.0, 1.0])
PAPER_INITIAL = np.array([2.7, 0.1, 0.2, 0.7, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.2])  # Fig. 6

# equator, poles, the meridians v = 0, +-pi/2, +-pi and their crossings
SPECIAL_U = np.array([0.0, np.pi / 2, -np.pi / 2, 0.0, 0.0, 0.0, 0.0, 0.3, 0.3, -0.7, np.pi / 2])
SPECIAL_V = np.array([0.0, 0.0, 1.0, np.pi / 2, -np.pi / 2, -np.pi, np.pi, np.pi, 0.0, np.pi / 2, np.pi / 2])


def jacobian_central_difference(q_s: np.ndarray, u: np.ndarray, v: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Test oracle for ``sq.jacobian``: (s(q + h e_k) - s(q - h e_k)) / 2h, h = step max(0.1, |q_k|).

    22 shape evaluations per point (section 1); shape (..., 3, 11).
    """
    q_s = np.asarray(q_s, dtype=np.float64)
    columns = []
    for k in range(sq.N_PARAMETERS):
        h = step * max(0.1, abs(q_s[k]))
        dq = np.zeros(sq.N_PARAMETERS)
        dq[k] = h
        columns.append((sq.shape(q_s + dq, u, v) - sq.shape(q_s - dq, u, v)) / (2.0 * h))
    return np.stack(columns, axis=-1)


def _parameters(rng, count):
    return rng.uniform(LOW, HIGH, size=(count, sq.N_PARAMETERS))


def _points(rng, count):
    return rng.uniform(-np.pi / 2, np.pi / 2, count), rng.uniform(-np.pi, np.pi, count)


def _inside_outside(q, x):
    """The superquadric's implicit function (1 on its surface) for t = b = 0."""
    a0, a1, a2, a3, e1, e2 = q[:6]
    xy = np.abs(x[:, 0] / (a0 * a1)) ** (2 / e2) + np.abs(x[:, 1] / (a0 * a2)) ** (2 / e2)
    return xy ** (e2 / e1) + np.abs(x[:, 2] / (a0 * a3)) ** (2 / e1)


def _inside_outside_gradient(q, x):
    a0, a1, a2, a3, e1, e2 = q[:6]
    sx, sy, sz = (a0 * a1, a0 * a2, a0 * a3)
    xy = np.abs(x[:, 0] / sx) ** (2 / e2) + np.abs(x[:, 1] / sy) ** (2 / e2)
    outer = (e2 / e1) * xy ** (e2 / e1 - 1) * (2 / e2)
    return np.column_stack(
        [
            outer * np.sign(x[:, 0]) * np.abs(x[:, 0] / sx) ** (2 / e2 - 1) / sx,
            outer * np.sign(x[:, 1]) * np.abs(x[:, 1] / sy) ** (2 / e2 - 1) / sy,
            (2 / e1) * np.sign(x[:, 2]) * np.abs(x[:, 2] / sz) ** (2 / e1 - 1) / sz,
        ]
    )


def _edges(triangles):
    return np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])


# --- shape and Jacobian ----------------------------------------------------------------------


def test_jacobian_matches_central_differences():
    """1000 random parameter sets, each at the 123 mesh nodes, 20 random and the special points."""
    rng = np.random.default_rng(0)
    m = sq.mesh()
    worst_point, worst_entry = 0.0, 0.0
    for q in _parameters(rng, 1000):
        u, v = _points(rng, 20)
        u, v = np.concatenate([m.u, u, SPECIAL_U]), np.concatenate([m.v, v, SPECIAL_V])
        j = sq.jacobian(q, u, v)
        oracle = jacobian_central_difference(q, u, v)
        error = np.abs(j - oracle)
        assert np.isfinite(j).all()
        worst_point = max(worst_point, (error.max(axis=(1, 2)) / np.abs(oracle).max(axis=(1, 2))).max())
        # relative where the entry is not ~0; 1e-8 absolute (the oracle's rounding floor) otherwise
        worst_entry = max(worst_entry, (error / (np.abs(oracle) + 1e-2)).max())
    assert worst_point < 1e-6  # 5e-9 (the oracle's own truncation and rounding)
    assert worst_entry < 1e-6


def test_corrected_j_1_11():
    """ds1/db3 = -pi b1 sin(r) (e3 + b2)/A; the printed -pi b1 sin(r) r is pi b3 times too large."""
    rng = np.random.default_rng(1)
    for q in _parameters(rng, 200):
        u, v = _points(rng, 30)
        a0, a3, b1, b2, b3 = q[0], q[3], q[8], q[9], q[10]
        e3 = sq.shape(q, u, v)[:, 2]
        r = np.pi * b3 * (e3 + b2) / (a0 * a3)
        column = sq.jacobian(q, u, v)[:, 0, 10]
        oracle = jacobian_central_difference(q, u, v)[:, 0, 10]
        assert np.abs(column - oracle).max() < 1e-7 * max(1.0, np.abs(oracle).max())
        assert np.allclose(column, -b1 * r * np.sin(r) / b3, rtol=1e-12, atol=1e-12 * np.abs(column).max())
        printed = -b1 * np.pi * np.sin(r) * r
        big = np.abs(column) > 1e-6
        assert np.allclose(printed[big] / column[big], np.pi * b3, rtol=1e-10)
    # finite, and zero, at b3 = 0 where the r/b3 form is 0/0
    q = PAPER_INITIAL.copy()
    q[8], q[10] = 0.5, 0.0
    assert np.all(sq.jacobian(q, SPECIAL_U, SPECIAL_V)[:, 0, 10] == 0.0)


def test_shell_lies_on_the_implicit_superquadric():
    rng = np.random.default_rng(2)
    for q in _parameters(rng, 200):
        q[6:10] = 0.0  # no taper, no bend (b1 = 0)
        u, v = _points(rng, 50)
        u, v = np.concatenate([u, SPECIAL_U]), np.concatenate([v, SPECIAL_V])
        assert np.abs(_inside_outside(q, sq.shape(q, u, v)) - 1.0).max() < 1e-12


def test_shape_is_eq_20_and_21():
    """A hand-evaluated point: taper scales x and y by 1 + t Su, the bend shifts x by b1 cos r."""
    q = np.array([2.0, 0.5, 0.4, 0.8, 1.0, 1.0, 0.3, -0.2, 0.1, 0.25, 0.5])
    u, v = np.pi / 6, np.pi / 3
    e = 2.0 * np.array([0.5 * np.cos(u) * np.cos(v), 0.4 * np.cos(u) * np.sin(v), 0.8 * np.sin(u)])
    a = 2.0 * 0.8
    r = np.pi * 0.5 * (e[2] + 0.25) / a
    expected = [(1 + 0.3 * e[2] / a) * e[0] + 0.1 * np.cos(r), (1 - 0.2 * e[2] / a) * e[1], e[2]]
    assert np.allclose(sq.shape(q, u, v), expected, rtol=1e-14)


def test_singular_points_are_finite_and_the_poles_collapse():
    for eps in (0.1, 0.5, 1.0, 1.9):
        q = np.array([1.5, 0.6, 0.4, 0.9, eps, eps, 0.5, -0.4, 0.3, 0.2, 0.6])
        for values in (
            sq.shape(q, SPECIAL_U, SPECIAL_V),
            sq.jacobian(q, SPECIAL_U, SPECIAL_V),
            sq.normals(q, SPECIAL_U, SPECIAL_V),
            jacobian_central_difference(q, SPECIAL_U, SPECIAL_V),
        ):
            assert np.isfinite(values).all()
        # a pole is one point for every v, on the (bent) axis: cos(pi/2) = 6e-17 is taken as 0
        v = np.linspace(-np.pi, np.pi, 9)
        for pole in (np.pi / 2, -np.pi / 2):
            points = sq.shape(q, np.full_like(v, pole), v)
            assert np.all(points == points[0]) and points[0, 1] == 0.0
        # v = -pi and v = pi are the same point
        u = np.linspace(-1.5, 1.5, 7)
        assert np.array_equal(sq.shape(q, u, np.full_like(u, -np.pi)), sq.shape(q, u, np.full_like(u, np.pi)))


def test_a0_gauge_is_a_null_vector_of_j():
    """(a0, a1, a2, a3) -> (k a0, a1/k, a2/k, a3/k) leaves s unchanged: J (a0, -a1, -a2, -a3, 0..) = 0."""
    rng = np.random.default_rng(3)
    for q in _parameters(rng, 100):
        u, v = _points(rng, 50)
        gauge = np.zeros(sq.N_PARAMETERS)
        gauge[:4] = q[0], -q[1], -q[2], -q[3]
        j = sq.jacobian(q, u, v)
        assert np.abs(j @ gauge).max() < 1e-12 * np.abs(j).max()
        scaled = q.copy()
        scaled[:4] = 1.7 * q[0], q[1] / 1.7, q[2] / 1.7, q[3] / 1.7
        assert np.allclose(sq.shape(scaled, u, v), sq.shape(q, u, v), rtol=1e-13, atol=1e-13)


def test_broadcasting_shapes():
    q = PAPER_INITIAL
    u = np.linspace(-1.5, 1.5, 4)[:, None]
    v = np.linspace(-3.0, 3.0, 5)[None, :]
    assert sq.shape(q, u, v).shape == (4, 5, 3)
    assert sq.jacobian(q, u, v).shape == (4, 5, 3, 11)
    assert sq.normals(q, u, v).shape == (4, 5, 3)
    assert np.allclose(sq.jacobian(q, u, v)[2, 3], sq.jacobian(q, u[2], v[0, 3])[0])


def test_clamp():
    q = np.array([0.0, -1.0, 2.0, 1e-9, 0.0, 3.0, -2.0, 2.0, -5.0, 7.0, -0.5])
    clamped = sq.clamp(q)
    assert np.array_equal(clamped, [1e-3, 1e-3, 2.0, 1e-3, 0.1, 1.9, -1.0, 1.0, -5.0, 7.0, 1e-2])
    assert np.isfinite(sq.jacobian(clamped, SPECIAL_U, SPECIAL_V)).all()
    assert np.array_equal(sq.clamp(PAPER_INITIAL), PAPER_INITIAL)


# --- normals ---------------------------------------------------------------------------------


def test_normals_match_the_implicit_gradient():
    rng = np.random.default_rng(4)
    for q in _parameters(rng, 100):
        q[6:10] = 0.0
        u, v = _points(rng, 50)
        u = np.clip(u, -1.5, 1.5)  # the gradient of the implicit function is 0/0 at the poles
        u, v = np.concatenate([u, [0.0, 0.0, 0.4]]), np.concatenate([v, [0.0, np.pi / 2, -np.pi]])
        n = sq.normals(q, u, v)
        g = _inside_outside_gradient(q, sq.shape(q, u, v))
        g /= np.linalg.norm(g, axis=1, keepdims=True)
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
        assert np.abs(n - g).max() < 1e-5


def test_normals_of_deformed_shells_are_normal_and_point_out():
    rng = np.random.default_rng(5)
    m = sq.mesh(60, 120)
    for q in _parameters(rng, 30):
        # orthogonal to secants in random directions (a different step and direction than n's);
        # not at u = 0 with eps1 near 2, where the shell is nearly creased and secants tilt
        u, v = _points(rng, 200)
        u = np.clip(u, -1.5, 1.5)
        n = sq.normals(q, u, v)
        angle = rng.uniform(0, 2 * np.pi, len(u))
        du, dv = 1e-5 * np.cos(angle), 1e-5 * np.sin(angle)
        secant = sq.shape(q, u + du, v + dv) - sq.shape(q, u - du, v - dv)
        secant /= np.linalg.norm(secant, axis=1, keepdims=True)
        assert np.abs(np.einsum("ij,ij->i", n, secant)).max() < 1e-4
        # outward: int n . x dA = 3 V > 0 (node normals, lumped areas, the mesh's volume)
        points = sq.shape(q, m.u, m.v)
        p = points[m.triangles]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        lumped = np.bincount(m.triangles.ravel(), weights=np.repeat(area / 3, 3))
        flux = np.sum(lumped * np.einsum("ij,ij->i", sq.normals(q, m.u, m.v), points))
        volume = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
        assert volume > 0 and flux == pytest.approx(3 * volume, rel=0.05)


def test_normals_at_the_poles():
    rng = np.random.default_rng(6)
    v = np.linspace(-np.pi, np.pi, 8, endpoint=False)
    for q in _parameters(rng, 50):
        assert np.array_equal(sq.normals(q, [-np.pi / 2, np.pi / 2], [0.0, 1.0]), [[0, 0, -1], [0, 0, 1]])
        # approaching a pole the normal tends to +-z (quickly for eps1 <= 1)
        q[4] = min(q[4], 1.0)
        assert np.all(sq.normals(q, np.full_like(v, np.pi / 2 - 1e-5), v)[:, 2] > 1 - 1e-6)
        assert np.all(sq.normals(q, np.full_like(v, -np.pi / 2 + 1e-5), v)[:, 2] < -1 + 1e-6)


# --- mesh ------------------------------------------------------------------------------------


@pytest.mark.parametrize("rings, longitudes, nodes", [(11, 11, 123), (5, 5, 27), (1, 3, 5), (8, 10, 82)])
def test_mesh_is_a_closed_oriented_sphere(rings, longitudes, nodes):
    m = sq.mesh(rings, longitudes)
    assert len(m.u) == len(m.v) == nodes
    edges = _edges(m.triangles)
    undirected = np.unique(np.sort(edges, axis=1), axis=0)
    assert nodes - len(undirected) + len(m.triangles) == 2  # Euler characteristic
    # each directed edge once, and its reverse once: closed, consistently oriented
    directed = {tuple(e) for e in edges}
    assert len(directed) == len(edges) == 2 * len(undirected)
    assert all((b, a) in directed for a, b in directed)
    assert np.all((m.triangles >= 0) & (m.triangles < nodes))
    # no duplicate nodes (v = pi is v = -pi; one node per pole), even for a box-like shell
    q = np.array([1.0, 1.0, 0.8, 0.6, 0.1, 0.1, 0.2, 0.1, 0.1, 0.0, 0.5])
    p = sq.shape(q, m.u, m.v)
    distance = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(nodes)
    assert distance.min() > 1e-3


def test_mesh_faces_point_out_and_enclose_the_ellipsoid_volume():
    q = np.array([1.0, 1.2, 0.9, 0.7, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    m = sq.mesh(60, 120)
    p = sq.shape(q, m.u, m.v)[m.triangles]
    faces = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.einsum("ij,ij->i", faces, p.mean(axis=1)) > 0)
    volume = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
    assert abs(volume / (4 / 3 * np.pi * 1.2 * 0.9 * 0.7) - 1) < 2e-3


def test_mesh_rejects_too_few_nodes():
    with pytest.raises(ValueError, match="n_longitudes >= 3"):
        sq.mesh(3, 2)


def test_mesh_matches_the_design_note():
    """Section 3/5 figures that depend on the 123-node triangulation."""
    m = sq.mesh()
    points = sq.shape(PAPER_INITIAL, m.u, m.v)
    k = sq.membrane_stiffness(points, m.triangles, w0=0.1, w1=0.5).toarray()
    # explicit Euler with D = I on qdot = -K q is stable for dt < 2/lambda_max = 0.26
    assert 2 / np.linalg.eigvalsh(k)[-1] == pytest.approx(0.26, abs=0.005)
    # the paper's P(0) (1 on the diagonal, 0.4 on the mesh edges) is indefinite: -0.166
    edges = _edges(m.triangles)
    p0 = np.eye(len(m.u))
    p0[edges[:, 0], edges[:, 1]] = p0[edges[:, 1], edges[:, 0]] = 0.4
    assert np.linalg.eigvalsh(p0)[0] == pytest.approx(-0.166, abs=0.001)


# --- displacement interpolation -----------------------------------------------------------------


def test_interpolation_at_nodes_selects_the_node():
    m = sq.mesh()
    n = sq.interpolation_matrix(m, m.u, m.v)
    assert np.abs(n.toarray() - np.eye(len(m.u))).max() < 1e-12


def test_interpolation_weights_are_linear_elements_of_the_mesh():
    rng = np.random.default_rng(7)
    m = sq.mesh(6, 7)
    u, v = _points(rng, 5000)
    u = np.concatenate([u, [-np.pi / 2, np.pi / 2, 0.0]])
    v = np.concatenate([v, [0.3, -2.0, np.pi - 1e-13]])
    n = sq.interpolation_matrix(m, u, v)
    dense = n.toarray()
    assert np.all(dense >= -1e-15) and np.allclose(dense.sum(axis=1), 1.0)
    assert np.allclose(n @ m.u, u)  # u is linear on every element, fans included
    # every point's nodes are the corners of one mesh triangle
    triangles = {frozenset(t) for t in m.triangles.tolist()}
    for row in range(len(u)):
        nodes = frozenset(n.indices[n.indptr[row] : n.indptr[row + 1]].tolist())
        assert any(nodes <= t for t in triangles)
    # v is taken modulo 2 pi, and the field is continuous across v = +-pi
    assert np.allclose(sq.interpolation_matrix(m, u, v + 2 * np.pi).toarray(), dense)
    edge = np.linspace(-1.4, 1.4, 9)
    a = sq.interpolation_matrix(m, edge, np.full_like(edge, np.pi - 1e-12)).toarray()
    b = sq.interpolation_matrix(m, edge, np.full_like(edge, -np.pi)).toarray()
    assert np.abs(a - b).max() < 1e-10


def test_interpolation_is_continuous_across_element_edges():
    rng = np.random.default_rng(8)
    m = sq.mesh(5, 6)
    d = rng.normal(size=(len(m.u), 3))
    u, v = _points(rng, 3000)
    h = 1e-9
    for du, dv in ((h, 0.0), (0.0, h), (h, h), (h, -h)):
        moved = sq.interpolation_matrix(m, np.clip(u + du, -np.pi / 2, np.pi / 2), v + dv) @ d
        assert np.abs(moved - sq.interpolation_matrix(m, u, v) @ d).max() < 1e-7


# --- membrane stiffness ----------------------------------------------------------------------


def _element_energy(points, triangles, w0, w1, d):
    """1/2 int w0 |d|^2 (lumped) + w1 |grad d|^2 over each flat triangle, gradients solved directly."""
    total = 0.0
    for t in triangles:
        p = points[t]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        area = 0.5 * np.linalg.norm(normal)
        frame = np.array([p[1] - p[0], p[2] - p[0], normal])
        # grad f: (p1 - p0).g = f1 - f0, (p2 - p0).g = f2 - f0, normal.g = 0
        grad = np.linalg.solve(frame, np.array([d[t[1]] - d[t[0]], d[t[2]] - d[t[0]], np.zeros(3)]))
        total += 0.5 * w1 * area * np.sum(grad**2) + 0.5 * w0 * area / 3 * np.sum(d[t] ** 2)
    return total


def test_stiffness_is_the_membrane_energy_and_psd():
    rng = np.random.default_rng(9)
    m = sq.mesh()
    for q in _parameters(rng, 5):
        points = sq.shape(q, m.u, m.v)
        k = sq.membrane_stiffness(points, m.triangles, w0=0.1, w1=0.5)
        dense = k.toarray()
        assert abs(dense - dense.T).max() < 1e-12 * abs(dense).max()
        eig = np.linalg.eigvalsh(dense)
        assert eig[0] > 0  # w0 > 0: positive definite
        d = rng.normal(size=(len(m.u), 3))
        energy = 0.5 * np.sum(d * (k @ d))
        assert energy == pytest.approx(_element_energy(points, m.triangles, 0.1, 0.5, d), rel=1e-10)
        # K_dd = K_node (x) I3 acting on q_d = d.ravel()
        k_dd = np.kron(dense, np.eye(3))
        assert np.allclose(k_dd @ d.ravel(), (k @ d).ravel())


def test_membrane_term_null_space_is_the_rigid_translations():
    rng = np.random.default_rng(10)
    m = sq.mesh()
    for q in _parameters(rng, 5):
        k = sq.membrane_stiffness(sq.shape(q, m.u, m.v), m.triangles, w0=0.0, w1=1.0)
        eig = np.linalg.eigvalsh(k.toarray())
        assert abs(eig[0]) < 1e-12 * eig[-1] and eig[1] > 1e-6 * eig[-1]  # exactly one zero mode
        translation = np.tile(rng.normal(size=3), (len(m.u), 1))
        assert np.abs(k @ translation).max() < 1e-12 * eig[-1]


def test_stiffness_converges_to_the_continuum_dirichlet_energy():
    """On the unit sphere int |grad_S z|^2 dA = int (1 - n_z^2) dA = 8 pi / 3, and int z^2 = 4 pi / 3."""
    q = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    m = sq.mesh(60, 120)
    points = sq.shape(q, m.u, m.v)
    z = points[:, 2]
    assert z @ (sq.membrane_stiffness(points, m.triangles, w0=0.0, w1=1.0) @ z) == pytest.approx(
        8 * np.pi / 3, rel=2e-3
    )
    assert z @ (sq.membrane_stiffness(points, m.triangles, w0=1.0, w1=0.0) @ z) == pytest.approx(
        4 * np.pi / 3, rel=2e-3
    )
