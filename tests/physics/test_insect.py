"""The 'insect' experiment: five deformable superquadric parts, four point-to-point joints,
tracked frame to frame from dense and from sparse data (docs/method-physics.md, sections 4 and 6;
paper Figs 9-10)."""

import numpy as np
import pytest

from tracker.physics import body as bd
from tracker.physics import insect

FRAMES = 12
FIRST_STEPS = (100, 200)
STEPS = 30


@pytest.fixture(scope="module")
def runs():
    """Both runs over 12 frames (a third of the flap cycle) with shortened schedules."""
    return {sparse: insect.run(sparse, frames=FRAMES, first_steps=FIRST_STEPS, steps=STEPS) for sparse in (False, True)}


def test_truth_holds_its_joints_and_moves():
    """C = 0 in the truth at every frame; over the first quarter cycle (9 frames) the left
    wing's tip rises by 2 sin(0.5) = 0.96 (flap 0.5 rad) less its flex, and the head moves forward."""
    start, quarter = insect.true_body(0), insect.true_body(insect.PERIOD // 4)
    for frame in range(0, insect.PERIOD, 5):
        assert np.abs(bd.violation(insect.true_body(frame))).max() < 1e-12
    tip_rise = bd.all_positions(quarter)[3][-1, 2] - bd.all_positions(start)[3][-1, 2]
    assert 0.7 < tip_rise < 1.0, tip_rise
    assert quarter.parts[1].c[0] - start.parts[1].c[0] > 0.2


def test_sparse_data_are_seven_fixed_nodes_per_part_spanning_each_part():
    """The sparse points are the same 7 nodes of each part in every frame, both poles among them."""
    dense, dense_labels = insect.data(False, 3)
    sparse, labels = insect.data(True, 3)
    assert dense[0].shape == (5 * 27, 3)
    np.testing.assert_array_equal(np.bincount(labels), [7] * 5)
    rows = [[np.flatnonzero((d == x).all(axis=1))[0] for x in s] for d, s in zip(dense, sparse)]
    assert rows[0] == rows[1] == rows[2]
    np.testing.assert_array_equal(dense_labels[rows[0]], labels)
    for part in range(5):
        assert {0, 26} <= {r % 27 for r, label in zip(rows[0], labels) if label == part}


def test_dense_and_sparse_tracking_keep_the_joints_and_follow_the_insect(runs):
    """12 frames, frame 0 from moments with 100 global + 200 local steps, then 30 local steps
    per frame.  Measured: max |C| 3.1e-6 (dense) and 1.5e-6 (sparse), against joints 0.2-0.29
    (dense) and 0.26-0.54 (sparse) apart at the moment initialisation; node position error
    (RMS over the 135 nodes) dense 2e-4 at frame 0, mean 7.4e-3, max 1.06e-2 (the 30 steps
    per frame lag the flap); sparse 7.1e-2 at frame 0, mean 9.9e-2, max 0.125 (the seven
    points leave the local displacements and the taper/bend of the wings underdetermined, as
    the paper notes for Fig. 10)."""
    dense, sparse = runs[False], runs[True]
    for result in (dense, sparse):
        assert result.violation.shape == result.position_error.shape == (FRAMES,)
        assert result.violation.max() < 2e-5
    assert dense.position_error[0] < 1e-3
    assert dense.position_error.max() < 0.02
    assert sparse.position_error.max() < 0.2
    assert sparse.position_error.mean() > 5.0 * dense.position_error.mean()
    summary = sparse.summary
    assert summary["position_error_max"] == sparse.position_error.max()
    assert summary["violation_mean"] <= summary["violation_max"]


def test_tracking_beats_standing_still(runs):
    """The tracked insect follows the motion: at the last frame the frame-0 fit is 0.59 (dense)
    and 0.58 (sparse) from the truth, the tracked fit 0.010 and 0.118."""
    last = insect.true_body(FRAMES - 1)
    for result in runs.values():
        frozen = insect.position_error(result.bodies[0], last)
        assert frozen > 4.0 * result.position_error[-1], (frozen, result.position_error[-1])
