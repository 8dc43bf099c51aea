"""The synthetic error experiment of Tables I-IV (docs/method-physics.md,
section 6): the truth follows the protocol, the a0 gauge fix keeps the shape, the claim checks
on the paper's own tables, and a reduced grid (100 / 25 % x variance 10 / 0, 4 frames) that
holds the robust claims and is deterministic for its seed."""

import numpy as np
import pytest

from tracker.physics import experiment as ex
from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq

from .test_kalman import global_leftover

FRAMES = 4


@pytest.fixture(scope="module")
def grid():
    return ex.run(densities=(100, 25), variances=(10, 0), frames=FRAMES, seed=0)


def rows_of(tables):
    return [{"density": d, "variance": v, **dict(zip(ex.ERRORS, errors))} for (d, v), errors in tables.items()]


def test_truth_follows_the_protocol():
    """123 nodes; taper and bend grow every frame; the bump is zero at frame 0, grows until
    frame 8 and then keeps its height; the body moves a little every frame; d is in the
    estimator's split (orthogonal to the rigid + global span)."""
    world = ex.truth()
    parts = world.parts
    assert len(parts) == 20 and all(len(p.u) == 123 for p in parts)
    q_s = np.array([p.q_s for p in parts])
    assert np.all(np.diff(q_s[:, [6, 7, 8]], axis=0) > 0)  # t1, t2, b1
    height = np.array([np.abs(p.d).max() for p in parts])
    assert height[0] < 1e-12
    assert np.all(np.diff(height[:9]) > 0.01)
    np.testing.assert_allclose(height[8:], height[8], rtol=0.1)
    steps = np.linalg.norm(np.diff([p.c for p in parts], axis=0), axis=1)
    assert np.all((steps > 0.005) & (steps < 0.05))
    for part in parts:
        np.testing.assert_allclose(global_leftover(part), 0.0, atol=1e-9)


def test_gauge_fix_keeps_the_shape():
    """in_gauge moves q_s to another a0 along (a0, a1, a2, a3) -> (k a0, a1/k, a2/k, a3/k):
    the shell is unchanged (docs/method-physics.md, section 1, degeneracy 4)."""
    m = sq.mesh()
    q_s = np.array([2.7, 0.15, 0.22, 0.7, 0.8, 1.1, 0.3, -0.2, 0.1, 0.05, 0.3])
    moved = ex.in_gauge(q_s, 1.0)
    assert moved[0] == 1.0 and moved[1] == pytest.approx(0.405)
    np.testing.assert_allclose(sq.shape(moved, m.u, m.v), sq.shape(q_s, m.u, m.v), atol=1e-14)


def test_frame_errors_of_a_known_offset():
    """Translation by 0.1 in x and local displacements moved by 0.01 per coordinate: the
    translation error is 0.1, local is 0.01 sqrt(3N), the rotation and global errors are 0,
    position |x| over 3N, RMS per node."""
    part = ex.truth(1).parts[0]
    shifted = kin.Part(part.c + [0.1, 0.0, 0.0], part.rotation, part.q_s, part.d + 0.01, part.u, part.v)
    errors = ex.frame_errors(shifted, part)
    position = np.linalg.norm(kin.positions(shifted) - kin.positions(part))
    np.testing.assert_allclose(
        errors, [0.1, 0.0, 0.0, 0.01 * np.sqrt(3 * 123), position, position / np.sqrt(123)], atol=1e-12
    )


def test_claims_on_the_paper_tables():
    """On the paper's own Tables I-IV: position error is monotone in noise and density and
    rotation is the smallest in every row, but local/position are not the largest in two rows
    of Table I (global 0.117 > local 0.1 at var 1; translation 0.025 > position 0.014 at var 0),
    and local/position are 22x/51x more noise-sensitive against 2.4x for translation."""
    assert len(ex.PAPER_TABLES) == 16
    claims = ex.check_claims(rows_of(ex.PAPER_TABLES))
    held = [c[1] for c in claims]
    assert held == [True, True, True, False, True]
    rows = rows_of(ex.PAPER_TABLES)
    not_largest = [
        (r["density"], r["variance"])
        for r in rows
        if min(r["local"], r["position"]) <= max(r["translation"], r["rotation"], r["global"])
    ]
    assert not_largest == [(100, 1), (100, 0)]
    ends = {r["variance"]: r for r in rows if r["density"] == 100}
    ratios = [ends[10][k] / ends[0][k] for k in ("translation", "local", "position")]
    np.testing.assert_allclose(ratios, [0.06 / 0.025, 0.65 / 0.03, 0.71 / 0.014], rtol=1e-12)


def test_reduced_grid_holds_the_robust_claims(grid):
    """100 / 25 % x variance 10 / 0 over 4 frames (each point pulled by its own node, joint
    rigid + global block, membrane as a prior with w1 = 5, b1 stiffness 10, the local/global
    split, 300 iterations per frame).  Position error grows with noise and as density falls,
    rotation is the smallest error of every row (measured: 0.019 and 0.035 at variance 10
    against translation 0.020 and 0.041), and local and position errors are far more
    noise-sensitive than translation (translation 1.18x, local 13.6x, position 17.5x); at
    variance 10 the translation error stays below 0.1 at both densities (the b1 stiffness keeps
    the frame-0 fit out of the (c_x, b1) valley: with K_g = 0 it is 0.56 at both); at
    100 %/var 10 local and position errors are the largest.  Not asserted, because it fails
    on 4 frames, where the bump is still small (measured): local/position the largest at var 0
    (100 %: 0.044 / 0.041 < global 0.139; 25 %: 0.068 / 0.091 < global 0.180)."""
    assert [(r["density"], r["variance"]) for r in grid] == [(100, 10), (100, 0), (25, 10), (25, 0)]
    claims = {c[0]: c for c in ex.check_claims(grid)}
    for name in (
        "node-position error grows with noise",
        "node-position error grows as density falls",
        "rotation error is the smallest in every row",
        "local and position errors far more noise-sensitive than translation (100 %, var 10 / var 0)",
    ):
        assert claims[name][1], claims[name]
    for row in grid:
        assert all(np.isfinite(row[k]) for k in ex.ERRORS)
        assert 0 <= row["capped"] <= FRAMES
    assert grid[0]["translation"] < 0.1
    assert grid[2]["translation"] < 0.1
    noisy = grid[0]
    assert min(noisy["local"], noisy["position"]) > max(noisy["translation"], noisy["rotation"], noisy["global"])
    assert grid[1]["position_rms"] == pytest.approx(grid[1]["position"] / np.sqrt(123))


def test_runs_are_deterministic_for_a_seed(grid):
    """A cell run alone repeats the grid's row exactly (same seed: same nodes, same noise),
    and another seed gives other errors."""
    same = ex.run(densities=(25,), variances=(10,), frames=FRAMES, seed=0)[0]
    other = ex.run(densities=(25,), variances=(10,), frames=FRAMES, seed=1)[0]
    row = grid[2]
    for key in ex.ERRORS + ("position_rms", "iterations", "capped"):
        assert same[key] == row[key]
    assert other["position"] != row["position"]
