"""Point-to-point constraints: Baumgarte decay laws under explicit Euler, the fast constraint-force
solve against a dense KKT solve, chains and redundant closed loops (docs/method-physics.md, sections 4 and 7)."""

import numpy as np

from tracker.geometry.se3 import exp_so3
from tracker.physics import constraints as con
from tracker.physics import kinematics as kin

Q_S = np.array([1.0, 0.4, 0.3, 0.6, 0.8, 1.2, 0.2, -0.1, 0.1, 0.2, 0.3])
NODE_U = np.array([-1.0, 0.2, 0.9, 0.1])
NODE_V = np.array([0.3, 2.0, -1.5, -2.8])
MASSES = np.array([1.0, 1.5, 0.7, 1.2])
RIGID = kin.RIGID


def _part(rng, centre):
    return kin.Part(
        c=np.asarray(centre, dtype=np.float64),
        rotation=exp_so3(rng.normal(size=3)),
        q_s=Q_S + 0.05 * rng.normal(size=len(Q_S)),
        d=0.05 * rng.normal(size=(len(NODE_U), 3)),
        u=NODE_U,
        v=NODE_V,
    )


def _chain(rng, n_parts, gap=0.25):
    """Parts whose node 1 lies near the next part's node 0, and the links (a, node, b, node)."""
    parts = [_part(rng, np.zeros(3))]
    for _ in range(n_parts - 1):
        part = _part(rng, np.zeros(3))
        offset = kin.positions(parts[-1])[1] + gap * rng.normal(size=3) / np.sqrt(3) - kin.positions(part)[0]
        parts.append(kin.retract(part, np.concatenate([offset, np.zeros(part.n_coordinates - 3)])))
    links = [(p, 1, p + 1, 0) for p in range(n_parts - 1)]
    return parts, links


def _pad(part, qdot):
    """A velocity of the free coordinates (the first len(qdot)) as one of all coordinates."""
    return np.concatenate([qdot, np.zeros(part.n_coordinates - len(qdot))])


def _kinematics(parts, qdots):
    """Per part: node positions, L restricted to the free coordinates (the first len(qdot)), and
    the velocity products."""
    return (
        [kin.positions(p) for p in parts],
        [kin.jacobians(p)[:, :, : len(q)] for p, q in zip(parts, qdots)],
        [kin.velocity_products(p, _pad(p, q)) for p, q in zip(parts, qdots)],
    )


def _constraint_terms(kinematics, sizes, links):
    """C, G and Gdot qdot of the links (a, node, b, node)."""
    x, big_l, vp = kinematics
    c = con.stack_differences([x[a][i] for a, i, _, _ in links], [x[b][j] for _, _, b, j in links])
    g = con.stack_jacobian(
        [big_l[a][i] for a, i, _, _ in links],
        [big_l[b][j] for _, _, b, j in links],
        parts_a=[a for a, _, _, _ in links],
        parts_b=[b for _, _, b, _ in links],
        sizes=sizes,
    )
    gdot_qdot = con.stack_differences([vp[a][i] for a, i, _, _ in links], [vp[b][j] for _, _, b, j in links])
    return c, g, gdot_qdot


def _rigid_dynamics(kinematics, external):
    """Lumped masses M_p of the rigid coordinates and F_p = g_q + external force, per part."""
    _, big_l, vp = kinematics
    blocks = [kin.lumped_mass(lp, MASSES) for lp in big_l]
    forces = [-np.einsum("i,iak,ia->k", MASSES, lp, v) + f for lp, v, f in zip(big_l, vp, external)]
    return blocks, np.concatenate(forces)


def _simulate_second_order(parts, qdots, links, a, dt, duration, external):
    """Explicit Euler of rigid parts under Baumgarte-stabilised constraints; C at every step."""
    history = []
    sizes = [RIGID] * len(parts)
    for _ in range(int(round(duration / dt)) + 1):
        kinematics = _kinematics(parts, qdots)
        c, g, gdot_qdot = _constraint_terms(kinematics, sizes, links)
        history.append(c)
        blocks, forces = _rigid_dynamics(kinematics, external)
        qdot = np.concatenate(qdots)
        n, r = con.second_order_system(g, blocks, forces, qdot=qdot, gdot_qdot=gdot_qdot, violation=c, a=a)
        qddot = con.block_solve(blocks, forces + g.T @ con.solve_forces(n, r))
        parts = [kin.retract(p, _pad(p, dt * q)) for p, q in zip(parts, qdots)]
        qdots = list((qdot + dt * qddot).reshape(len(parts), RIGID))
    return np.array(history)


def _second_order_law(c0, cdot0, a, t):
    return (c0 + np.outer(t, cdot0 + a * c0)) * np.exp(-a * t)[:, None]


def _second_order_error(n_parts, links_of, dt, seed):
    rng = np.random.default_rng(seed)
    parts, links = _chain(rng, n_parts)
    links = links_of(links)
    qdots = list(rng.normal(size=(n_parts, RIGID)))
    external = list(rng.normal(size=(n_parts, RIGID)))
    a, duration = 6.0, 1.0
    history = _simulate_second_order(parts, qdots, links, a, dt, duration, external)
    c0, g, _ = _constraint_terms(_kinematics(parts, qdots), [RIGID] * n_parts, links)
    t = dt * np.arange(len(history))
    exact = _second_order_law(c0, g @ np.concatenate(qdots), a, t)
    scale = np.abs(exact).max()
    return np.abs(history - exact).max() / scale, np.abs(history[-1]).max() / scale


def test_second_order_violation_follows_the_corrected_decay_law():
    """Two rigid parts, a = 6: C(t) = (C0 + (Cdot0 + a C0) t) e^{-at}, Euler error O(a dt)."""
    coarse, final = _second_order_error(2, lambda links: links, 2e-3, seed=10)
    fine, _ = _second_order_error(2, lambda links: links, 1e-3, seed=10)
    assert coarse < 2 * 6.0 * 2e-3, coarse
    assert 1.8 < coarse / fine < 2.2, (coarse, fine)
    assert final < 0.05


def test_second_order_is_not_the_papers_shorthand():
    """C0 e^{-at} is off unless Cdot0 = -a C0 (the note: 0.16 at |C0| = 0.44)."""
    rng = np.random.default_rng(10)
    parts, links = _chain(rng, 2)
    qdots = list(rng.normal(size=(2, RIGID)))
    c0, g, _ = _constraint_terms(_kinematics(parts, qdots), [RIGID] * 2, links)
    t = np.linspace(0.0, 1.5, 301)
    law = _second_order_law(c0, g @ np.concatenate(qdots), 6.0, t)
    shorthand = c0 * np.exp(-6.0 * t)[:, None]
    assert np.abs(law - shorthand).max() > 0.05


def test_second_order_chain_of_three_parts():
    """Three rigid parts, two constraints (k = 2, assembled N)."""
    error, final = _second_order_error(3, lambda links: links, 2e-3, seed=11)
    assert error < 2 * 6.0 * 2e-3, error
    assert final < 0.05


def _closed_loop(links):
    """A-B, B-C and C-A all at the same node of each part: C_AB + C_BC + C_CA = 0 identically."""
    return [(0, 0, 1, 0), (1, 0, 2, 0), (2, 0, 0, 0)]


def test_redundant_closed_loop_uses_least_squares_and_decays():
    rng = np.random.default_rng(12)
    parts, links = _chain(rng, 3)
    links = _closed_loop(links)
    qdots = list(rng.normal(size=(3, RIGID)))
    external = list(rng.normal(size=(3, RIGID)))
    kinematics = _kinematics(parts, qdots)
    c, g, gdot_qdot = _constraint_terms(kinematics, [RIGID] * 3, links)
    blocks, forces = _rigid_dynamics(kinematics, external)
    n, r = con.second_order_system(
        g, blocks, forces, qdot=np.concatenate(qdots), gdot_qdot=gdot_qdot, violation=c, a=6.0
    )
    assert np.linalg.matrix_rank(n) == 6
    f = con.solve_forces(n, r)
    assert np.abs(n @ f + r).max() < 1e-9 * np.abs(r).max()
    qddot = con.block_solve(blocks, forces + g.T @ f)
    kkt_qddot, _ = _kkt_solve(g, blocks, forces, -(r - g @ con.block_solve(blocks, forces)))
    np.testing.assert_allclose(qddot, kkt_qddot, atol=1e-9 * np.abs(kkt_qddot).max())

    error, final = _second_order_error(3, _closed_loop, 2e-3, seed=12)
    assert error < 2 * 6.0 * 2e-3, error
    assert final < 0.05


def _block_diag(blocks):
    out = np.zeros((sum(b.shape[0] for b in blocks),) * 2)
    start = 0
    for b in blocks:
        out[start : start + len(b), start : start + len(b)] = b
        start += len(b)
    return out


def _kkt_solve(g, blocks, forces, rhs):
    """Dense least squares of [[M, -G^T], [G, 0]] [y; f_c] = [F; rhs] -> (y, f_c)."""
    m = _block_diag(blocks)
    size, k = m.shape[0], g.shape[0]
    kkt = np.block([[m, -g.T], [g, np.zeros((k, k))]])
    solution = np.linalg.lstsq(kkt, np.concatenate([forces, rhs]), rcond=1e-12)[0]
    return solution[:size], solution[size:]


def _deformable_loop(rng):
    """A deformable part and two rigid ones joined A-B, B-C, C-A at distinct nodes (k = 3)."""
    parts, links = _chain(rng, 3)
    links = links + [(2, 1, 0, 2)]
    qdots = [rng.normal(size=parts[0].n_coordinates), rng.normal(size=RIGID), rng.normal(size=RIGID)]
    c, g, gdot_qdot = _constraint_terms(_kinematics(parts, qdots), [len(q) for q in qdots], links)
    return parts, qdots, c, g, gdot_qdot


def test_fast_second_order_solve_equals_the_dense_kkt_solve():
    """M qddot - G^T f_c = F, G qddot = -(Gdot qdot + 2a Cdot + a^2 C), with a regularised
    deformable lumped mass (it is singular on its own)."""
    rng = np.random.default_rng(13)
    parts, qdots, c, g, gdot_qdot = _deformable_loop(rng)
    blocks = [kin.lumped_mass(kin.jacobians(parts[0]), MASSES, regularizer=1e-2)]
    blocks += [kin.lumped_mass(kin.jacobians(p)[:, :, :RIGID], MASSES) for p in parts[1:]]
    forces = rng.normal(size=g.shape[1])
    qdot = np.concatenate(qdots)
    a = 6.0
    n, r = con.second_order_system(g, blocks, forces, qdot=qdot, gdot_qdot=gdot_qdot, violation=c, a=a)
    f = con.solve_forces(n, r)
    _, kkt_f = _kkt_solve(g, blocks, forces, -(gdot_qdot + 2 * a * g @ qdot + a * a * c))
    assert np.abs(f - kkt_f).max() < 1e-9 * max(1.0, np.abs(kkt_f).max())


def test_fast_first_order_solve_equals_the_dense_kkt_solve():
    """D qdot - G^T f_c = F, G qdot = -a C, with D = I as in the paper and a general SPD D."""
    rng = np.random.default_rng(14)
    parts, _, c, g, _ = _deformable_loop(rng)
    spd = rng.normal(size=(RIGID, RIGID))
    for blocks in (
        [np.eye(parts[0].n_coordinates), np.eye(RIGID), np.eye(RIGID)],
        [np.eye(parts[0].n_coordinates), spd @ spd.T + np.eye(RIGID), np.eye(RIGID)],
    ):
        forces = rng.normal(size=g.shape[1])
        n, r = con.first_order_system(g, blocks, con.block_solve(blocks, forces), violation=c, a=2.0)
        f = con.solve_forces(n, r)
        _, kkt_f = _kkt_solve(g, blocks, forces, -2.0 * c)
        assert np.abs(f - kkt_f).max() < 1e-9 * max(1.0, np.abs(kkt_f).max())


def _first_order_error(parts, links, free, dt, duration, forces, a):
    """Explicit Euler of D qdot = F + G^T f_c with D = I: max |C - C0 e^{-at}| and C0."""
    c0 = None
    worst = 0.0
    for step in range(int(round(duration / dt)) + 1):
        qdots = [np.zeros(n) for n in free]
        c, g, _ = _constraint_terms(_kinematics(parts, qdots), free, links)
        c0 = c if c0 is None else c0
        worst = max(worst, np.abs(c - c0 * np.exp(-a * dt * step)).max())
        blocks = [np.eye(n) for n in free]
        n, r = con.first_order_system(g, blocks, forces, violation=c, a=a)
        qdot = forces + g.T @ con.solve_forces(n, r)
        pieces = np.split(qdot, np.cumsum(free)[:-1])
        parts = [kin.retract(p, _pad(p, dt * q)) for p, q in zip(parts, pieces)]
    return worst, np.abs(c0).max()


def test_first_order_violation_decays_exponentially_rigid():
    """Two rigid parts, a = 4: C(t) = C0 e^{-at}; Euler's own error on e^{-at} peaks near
    a dt / 2e, so the bound is a dt / 2 and halving dt halves it."""
    rng = np.random.default_rng(15)
    parts, links = _chain(rng, 2)
    forces = rng.normal(size=2 * RIGID)
    coarse, c0 = _first_order_error(parts, links, [RIGID] * 2, 4e-3, 1.0, forces, 4.0)
    fine, _ = _first_order_error(parts, links, [RIGID] * 2, 2e-3, 1.0, forces, 4.0)
    assert coarse < 0.5 * 4.0 * 4e-3 * c0, (coarse, c0)
    assert 1.8 < coarse / fine < 2.2, (coarse, fine)


def test_first_order_violation_decays_exponentially_deformable():
    """Two deformable parts (J and S in L), k = 1, a = 4, dt = 2e-3."""
    rng = np.random.default_rng(16)
    parts, links = _chain(rng, 2)
    free = [p.n_coordinates for p in parts]
    forces = 0.2 * rng.normal(size=sum(free))
    error, c0 = _first_order_error(parts, links, free, 2e-3, 1.0, forces, 4.0)
    assert error < 0.5 * 4.0 * 2e-3 * c0, (error, c0)


def test_solve_forces_branches():
    rng = np.random.default_rng(17)
    a = rng.normal(size=(6, 6))
    r = rng.normal(size=6)
    well = a @ a.T + np.eye(6)
    np.testing.assert_allclose(con.solve_forces(well, r), -np.linalg.solve(well, r), rtol=1e-10)
    b = rng.normal(size=(6, 4))
    singular = b @ b.T
    consistent = singular @ rng.normal(size=6)
    f = con.solve_forces(singular, consistent)
    np.testing.assert_allclose(singular @ f, -consistent, atol=1e-10)
    np.testing.assert_allclose(f, -np.linalg.pinv(singular, rcond=1e-10) @ consistent, atol=1e-10)
