"""The second-order Kalman motion prior (tracker/tracking/motion_prior.py; docs/method-physics.md, sections 3, 5)."""

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from tracker.evaluate import evaluate
from tracker.geometry import se3
from tracker.io.posefile import load_pose_file
from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.model import joint_centres, load_model
from tracker.status import LOST
from tracker.tracking import motion_prior
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "recordings" / "demo"


def update(state: motion_prior.MotionState, measured: np.ndarray, information: np.ndarray) -> motion_prior.MotionState:
    """The Kalman update from measured poses ``z`` with information ``W = V^-1`` per block (N,2,3,3):
    ``x+ = x + P_xx+ W (z - x)`` (information form of ``x + K (z - H x)``), then
    :func:`tracker.tracking.motion_prior.correct`."""
    diff = motion_prior._difference(state.poses, np.asarray(measured, dtype=np.float64))
    posterior = np.linalg.inv(np.linalg.inv(state.covariance[..., :3, :3]) + information)
    step = np.einsum("nbij,nbj->nbi", posterior @ information, diff)
    poses = state.poses.copy()
    poses[:, :3, 3] += step[:, motion_prior.TRANSLATION]
    poses[:, :3, :3] = state.poses[:, :3, :3] @ se3.exp_so3_many(np.ascontiguousarray(step[:, motion_prior.ROTATION]))
    return motion_prior.correct(state, poses, information)


def fitting_step(
    x: np.ndarray,
    cov: np.ndarray,
    force: np.ndarray,
    hessian: np.ndarray,
    dt: float,
    stiffness: np.ndarray | None = None,
    q: float = 0.0,
    riccati: bool = True,
):
    """One inner iteration of the method's first-order continuous EKF for one block (section 5):

        x <- x + dt (P g - K x),   P <- P + dt (-K P - P K + q I - P A P),   P <- (P + P^T) / 2

    with ``g = H^T V^-1 r`` (``force``) and ``A = H^T V^-1 H`` (``hessian``), both at the current ``x``.
    With ``riccati=False`` and ``P = I`` this is dynamic fitting (eqs. 16/18).  For comparison and tests;
    the tracker uses the discrete form (:func:`tracker.tracking.motion_prior.correct`)."""
    k = np.zeros_like(cov) if stiffness is None else stiffness
    x = x + dt * (cov @ force - k @ x)
    if riccati:
        cov = cov + dt * (-k @ cov - cov @ k + q * np.eye(len(x)) - cov @ hessian @ cov)
        cov = 0.5 * (cov + cov.T)
    return x, cov


def _spd(rng, n=6, scale=1.0):
    a = rng.normal(size=(n, n))
    return scale * (a @ a.T + 0.5 * np.eye(n))


def _drift(decay):
    """F = [[0, I3], [0, -gamma I3]] and G = [0; I3] of the model per block."""
    f = np.zeros((6, 6))
    f[:3, 3:] = np.eye(3)
    f[3:, 3:] = -decay * np.eye(3)
    g = np.zeros((6, 3))
    g[3:] = np.eye(3)
    return f, g


def _random_poses(rng, n):
    return np.stack([se3.exp(np.concatenate([rng.normal(size=3), rng.normal(size=3)])) for _ in range(n)])


@pytest.mark.parametrize(
    "dt, q, decay", [(1 / 60, 2.5, 0.0), (0.05, 40.0, 0.0), (1 / 60, 3.0, 4.0), (0.1, 1.0, 1e-5), (0.2, 0.7, 12.0)]
)
def test_discrete_propagation_equals_the_continuous_riccati_solution(dt, q, decay):
    """Phi P Phi^T + q Bq (x) I3 solves dP/dt = F P + P F^T + G q G^T over dt (RK4 with 4000 small steps)."""
    rng = np.random.default_rng(1)
    p0 = _spd(rng, scale=0.01)
    f, g = _drift(decay)
    noise = q * g @ g.T

    def rhs(p):
        return f @ p + p @ f.T + noise

    p, h = p0.copy(), dt / 4000
    for _ in range(4000):
        k1 = rhs(p)
        k2 = rhs(p + 0.5 * h * k1)
        k3 = rhs(p + 0.5 * h * k2)
        k4 = rhs(p + h * k3)
        p = p + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    exact = motion_prior.propagate_covariance(p0, dt, q=q, decay=decay)
    np.testing.assert_allclose(exact, p, rtol=1e-9, atol=1e-14 * np.abs(p).max())
    # the mean's transition is exp(F dt), and the noise term alone is the integral with P0 = 0
    np.testing.assert_allclose(
        np.kron(motion_prior.transition(dt, decay), np.eye(3)), expm(f * dt), rtol=1e-12, atol=1e-15
    )


def test_identity_covariance_and_no_data_is_plain_dynamic_fitting():
    """Section 5: with P = I held (no Riccati step) the filter's iteration x <- x + dt (P g - K x) is the
    dynamic-fitting Euler step of qdot = H^T V^-1 r - K q (eqs. 16/18), with the same fixed point as
    the full filter; without data (g = 0, A = 0, K = 0, q = 0) the Riccati equation keeps P = I, so
    the filter started at P = I stays plain dynamic fitting."""
    rng = np.random.default_rng(2)
    h = rng.normal(size=(8, 3))
    sigma2 = 0.3
    z = rng.normal(size=8)
    k = _spd(rng, 3, 0.05)
    a = h.T @ h / sigma2

    def force(x):
        return h.T @ (z - h @ x) / sigma2

    x = rng.normal(size=3)
    stepped, cov = fitting_step(x, np.eye(3), force(x), a, 0.01, k, riccati=False)
    np.testing.assert_allclose(stepped, x + 0.01 * (force(x) - k @ x), rtol=1e-15)
    np.testing.assert_array_equal(cov, np.eye(3))

    # rigid blocks (K = 0, ours): one fixed point, H^T V^-1 r = 0, whether P is held at I or runs the Riccati step
    fixed_point = np.linalg.solve(a, h.T @ z / sigma2)
    fitting, kalman, p = x.copy(), x.copy(), np.eye(3)
    for _ in range(3000):
        fitting, _ = fitting_step(fitting, np.eye(3), force(fitting), a, 0.02, riccati=False)
        kalman, p = fitting_step(kalman, p, force(kalman), a, 0.02, q=0.1)
    np.testing.assert_allclose(fitting, fixed_point, rtol=1e-9)
    np.testing.assert_allclose(kalman, fixed_point, rtol=1e-9)
    assert not np.allclose(p, np.eye(3))  # the Riccati step changed the metric, not the answer
    # with stiffness the method's "same fixed point (H^T V^-1 r = K q)" holds for P = I only: the filter
    # stops where P g = K x
    fitting, kalman, p = x.copy(), x.copy(), np.eye(3)
    for _ in range(6000):
        fitting, _ = fitting_step(fitting, np.eye(3), force(fitting), a, 0.02, k, riccati=False)
        kalman, p = fitting_step(kalman, p, force(kalman), a, 0.02, k, q=0.1)
    np.testing.assert_allclose(fitting, np.linalg.solve(a + k, h.T @ z / sigma2), rtol=1e-9)
    np.testing.assert_allclose(p @ force(kalman), k @ kalman, atol=1e-9)
    assert np.abs(force(kalman) - k @ kalman).max() > 1e-3

    still, p = fitting_step(x, np.eye(3), np.zeros(3), np.zeros((3, 3)), 0.5)
    np.testing.assert_array_equal(p, np.eye(3))
    np.testing.assert_array_equal(still, x)


def test_section5_filter_over_unit_pseudo_time_is_the_discrete_update():
    """The continuous filter of docs/method-physics.md on one frame's linear measurement
    (x' = P H^T W (z - H x),
    P' = -P H^T W H P, H = [I3 0]) integrated over unit pseudo-time lands on our discrete update
    (position, velocity and covariance; Euler error O(1/steps))."""
    rng = np.random.default_rng(3)
    cov = np.zeros((1, 2, 6, 6))
    cov[0, 0] = _spd(rng, scale=0.02)
    cov[0, 1] = _spd(rng, scale=0.02)
    state = motion_prior.MotionState(np.eye(4)[None], rng.normal(size=(1, 2, 3)), cov)
    info = np.stack([_spd(rng, 3, 50.0), _spd(rng, 3, 50.0)])[None]
    measured = np.eye(4)[None].copy()
    measured[0, :3, 3] = rng.normal(size=3) * 0.05
    updated = update(state, measured, info)

    hm = np.hstack([np.eye(3), np.zeros((3, 3))])
    x = np.concatenate([np.zeros(3), state.velocity[0, 0]])
    p = cov[0, 0].copy()
    steps = 20000
    for _ in range(steps):
        g = hm.T @ info[0, 0] @ (measured[0, :3, 3] - x[:3])
        x, p = fitting_step(x, p, g, hm.T @ info[0, 0] @ hm, 1.0 / steps)
    np.testing.assert_allclose(x[:3], updated.poses[0, :3, 3], rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(x[3:], updated.velocity[0, 0], rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(p, updated.covariance[0, 0], rtol=5e-3, atol=1e-3 * np.abs(p).max())


def test_update_is_the_textbook_kalman_update():
    """K = P H^T (H P H^T + V)^-1, x+ = x + K (z - H x), P+ = (I - K H) P with V = W^-1, per block (the
    rotation block in body coordinates of the reference, then re-expressed about the new rotation)."""
    rng = np.random.default_rng(4)
    n = 3
    poses = _random_poses(rng, n)
    cov = np.stack([np.stack([_spd(rng, scale=0.01), _spd(rng, scale=0.01)]) for _ in range(n)])
    state = motion_prior.MotionState(poses, rng.normal(size=(n, 2, 3)), cov)
    info = np.stack([np.stack([_spd(rng, 3, 100.0), _spd(rng, 3, 100.0)]) for _ in range(n)])
    measured = np.stack([poses[i] @ se3.exp(rng.normal(size=6) * 0.05) for i in range(n)])
    updated = update(state, measured, info)
    hm = np.hstack([np.eye(3), np.zeros((3, 3))])
    for i in range(n):
        for b in range(2):
            p = cov[i, b]
            gain = p @ hm.T @ np.linalg.inv(hm @ p @ hm.T + np.linalg.inv(info[i, b]))
            if b == 0:
                residual = measured[i, :3, 3] - poses[i, :3, 3]
            else:
                residual = se3.log_so3(poses[i, :3, :3].T @ measured[i, :3, :3])
            x = np.concatenate([np.zeros(3), state.velocity[i, b]]) + gain @ residual
            p_plus = (np.eye(6) - gain @ hm) @ p
            if b == 0:
                np.testing.assert_allclose(updated.poses[i, :3, 3], poses[i, :3, 3] + x[:3], rtol=1e-10)
                np.testing.assert_allclose(updated.velocity[i, 0], x[3:], rtol=1e-9, atol=1e-12)
                np.testing.assert_allclose(updated.covariance[i, 0], p_plus, rtol=1e-8, atol=1e-12)
            else:
                turn = se3.exp_so3(x[:3])
                np.testing.assert_allclose(updated.poses[i, :3, :3], poses[i, :3, :3] @ turn, atol=1e-12)
                t = np.kron(np.eye(2), turn.T)
                np.testing.assert_allclose(updated.velocity[i, 1], turn.T @ x[3:], rtol=1e-9, atol=1e-12)
                np.testing.assert_allclose(updated.covariance[i, 1], t @ p_plus @ t.T, rtol=1e-8, atol=1e-12)


def _trajectory(rng, n, frames, dt):
    """Constant world velocity of the origins and constant body angular velocity: E_k (frames, n, 4, 4)."""
    start = _random_poses(rng, n)
    velocity = rng.normal(size=(n, 3))
    spin = rng.normal(size=(n, 3)) * 2.0
    out = np.empty((frames, n, 4, 4))
    for k in range(frames):
        for i in range(n):
            out[k, i] = np.eye(4)
            out[k, i, :3, :3] = start[i, :3, :3] @ se3.exp_so3(spin[i] * k * dt)
            out[k, i, :3, 3] = start[i, :3, 3] + velocity[i] * k * dt
    return out, velocity, spin


def test_a_constant_velocity_trajectory_is_tracked_exactly_without_lag():
    rng = np.random.default_rng(5)
    dt, count = 1 / 60, 120
    truth, velocity, spin = _trajectory(rng, 4, count, dt)
    state = motion_prior.initial_state(truth[0])
    info = np.broadcast_to(np.diag([1e4, 1e4, 1e4]), (4, 2, 3, 3))
    errors = []
    for k in range(1, count):
        state = motion_prior.predict(state, dt, q=(1.0, 30.0))
        errors.append(max(np.abs(state.poses - truth[k]).max() for _ in [0]))
        state = update(state, truth[k], info)
    assert errors[0] > 1e-3  # started at rest: the first prediction lags
    assert max(errors[-20:]) < 1e-10  # converged: the prediction is the next true pose (no lag)
    np.testing.assert_allclose(state.velocity[:, 0], velocity, atol=1e-9)
    np.testing.assert_allclose(state.velocity[:, 1], spin, atol=1e-8)


def test_a_component_without_measurements_keeps_moving_and_its_covariance_grows():
    rng = np.random.default_rng(6)
    dt, count = 1 / 60, 150
    truth, _, _ = _trajectory(rng, 2, count, dt)
    state = motion_prior.initial_state(truth[0])
    info = np.broadcast_to(np.diag([1e5, 1e5, 1e5]), (2, 2, 3, 3)).copy()
    floor = (10.0, 0.1)
    priors, traces = [], []
    for k in range(1, count):
        state = motion_prior.predict(state, dt, q=(1.0, 30.0))
        if k > 100:
            np.testing.assert_allclose(state.poses, truth[k], atol=1e-9)  # still on its trajectory
            priors.append(motion_prior.prior_information(state, scale=1.0, floor=floor))
            traces.append(np.trace(state.covariance, axis1=-2, axis2=-1))
            info[1] = 0.0  # component 1 loses its data
        before = state
        state = motion_prior.correct(
            state, np.where(np.arange(2)[:, None, None] == 1, state.poses, truth[k]) if k > 100 else truth[k], info
        )
        if k > 100:  # no data: correct changes nothing for component 1
            np.testing.assert_allclose(state.velocity[1], before.velocity[1], rtol=1e-14, atol=1e-15)
            np.testing.assert_allclose(
                state.covariance[1], before.covariance[1], rtol=1e-12, atol=1e-13 * np.abs(before.covariance[1]).max()
            )
    traces = np.array(traces)[1:, 1]  # component 1, both blocks, after it lost its data
    assert np.all(np.diff(traces, axis=0) > 0)
    position_info = np.array([np.linalg.eigvalsh(p[1, :3, :3]).max() for p in priors[1:]])
    above = position_info > floor[0] * (1 + 1e-9)
    assert np.all(np.diff(position_info[above]) < 0) and above[:10].all()  # weakens frame by frame ...
    np.testing.assert_allclose(position_info[~above], floor[0], rtol=1e-9)  # ... down to the floor
    held = np.array([np.linalg.eigvalsh(p[0, :3, :3]).min() for p in priors[1:]])
    assert held.min() > 100 * position_info[-1]  # the measured component keeps a firm prior


def test_prior_information_is_the_inverse_position_covariance_in_body_twist_coordinates():
    rng = np.random.default_rng(7)
    poses = _random_poses(rng, 2)
    cov = np.stack([np.stack([_spd(rng, scale=1e-4), _spd(rng, scale=1e-3)]) for _ in range(2)])
    state = motion_prior.MotionState(poses, np.zeros((2, 2, 3)), cov)
    prior = motion_prior.prior_information(state, scale=0.5)
    for i in range(2):
        r = poses[i, :3, :3]
        # a body twist (v, 0) moves the origin by R v: its cost is (R v)^T Pt^-1 (R v)
        np.testing.assert_allclose(prior[i, :3, :3], 0.5 * r.T @ np.linalg.inv(cov[i, 0, :3, :3]) @ r, rtol=1e-9)
        np.testing.assert_allclose(prior[i, 3:, 3:], 0.5 * np.linalg.inv(cov[i, 1, :3, :3]), rtol=1e-9)
        np.testing.assert_array_equal(prior[i, :3, 3:], 0.0)
    floored = motion_prior.prior_information(state, scale=1e-9, floor=(7.0, 3.0))
    np.testing.assert_allclose(floored[:, :3, :3], np.broadcast_to(7.0 * np.eye(3), (2, 3, 3)), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(floored[:, 3:, 3:], np.broadcast_to(3.0 * np.eye(3), (2, 3, 3)), rtol=1e-6, atol=1e-12)


def test_block_information_is_the_marginal_information_of_each_block():
    rng = np.random.default_rng(8)
    poses = _random_poses(rng, 3)
    c = np.stack([_spd(rng, scale=100.0) for _ in range(3)])
    blocks = motion_prior.block_information(c, poses)
    for i in range(3):
        cov = np.linalg.inv(c[i])
        r = poses[i, :3, :3]
        np.testing.assert_allclose(blocks[i, 0], r @ np.linalg.inv(cov[:3, :3]) @ r.T, rtol=1e-6)
        np.testing.assert_allclose(blocks[i, 1], np.linalg.inv(cov[3:, 3:]), rtol=1e-6)
    np.testing.assert_array_equal(motion_prior.block_information(np.zeros((2, 6, 6)), poses[:2]), 0.0)


def _track(settings, count, blank=()):
    rec = open_recording(DEMO)
    model = load_model(rec.model_path)
    tracker = Tracker(model, rec.cameras, load_pose_file(rec.init_path, model), settings)
    results, priors, predicted = [], [], []
    for index, images in itertools.islice(frames(rec), count):
        if index in blank:
            images = [np.full_like(image, 128) for image in images]
        results.append(tracker.step(images))
        priors.append(tracker.prior.copy())
        predicted.append(tracker.anchor.copy())
    return model, rec, results, priors, predicted


def test_demo_first_frames_with_the_kalman_prior_meet_the_accuracy_bar():
    model, rec, results, _, _ = _track(Settings().but(motion=dict(dynamics="kalman")), 40)
    poses = np.stack([r.poses for r in results])
    tracked = {
        "frame": np.arange(40),
        "joint_names": np.array(model.joint_names),
        "joints": joint_centres(poses),
        "status": np.array([r.status for r in results], np.int8),
    }
    truth = load_poses(rec.truth_path)
    truth = {"joint_names": truth["joint_names"], "joints": truth["joints"][:40], "frame": np.arange(40)}
    report = evaluate(tracked, truth)
    assert report.mpjpe_mm <= 20.0 and report.pck >= 0.98 and report.lost_frames == 0
    assert all(r.status != LOST for r in results)


def test_tracker_without_images_keeps_the_body_moving_and_weakens_its_prior():
    """Frames 20-22 blank in every camera: the poses follow the filter's constant-velocity prediction and
    the prior about it weakens frame by frame; afterwards the images take over again."""
    model, rec, results, priors, predicted = _track(
        Settings().but(motion=dict(dynamics="kalman")), 30, blank={20, 21, 22}
    )
    for k in (20, 21, 22):
        np.testing.assert_allclose(results[k].poses, predicted[k], atol=1e-6)
    root = results[19].poses[0, :3, 3]
    assert np.linalg.norm(results[22].poses[0, :3, 3] - root) > 0.01  # walked on, about 1 cm per frame
    translation = [np.trace(p[:, :3, :3], axis1=-2, axis2=-1).sum() for p in priors]
    rotation = [np.trace(p[:, 3:, 3:], axis1=-2, axis2=-1).sum() for p in priors]
    assert rotation[20] > rotation[21] > rotation[22] > rotation[23]
    floor = 3 * model.size * Settings().solve.prior_translation  # the weakest it may get
    assert translation[20] > translation[21] > translation[22] >= translation[23] >= floor * (1 - 1e-9)
    assert translation[25] > 2 * floor  # data again: firm again
    truth = load_poses(rec.truth_path)["joints"]
    error = np.linalg.norm(joint_centres(results[29].poses[None])[0] - truth[29], axis=1).mean()
    assert error < 0.02


def test_variance_factor_is_the_weighted_residual_variance_per_component():
    """sigma0_i^2 = sum w m^2 / (n_i - 6) (weighted least squares), shrunk towards the pooled value with the
    weight of 12 samples; samples without an edge (w = 0, m = NaN) do not count."""
    rng = np.random.default_rng(10)
    component = np.repeat([0, 1, 3], [400, 30, 7])
    offset = np.concatenate([rng.normal(0, 0.5, 400), rng.normal(0, 3.0, 30), rng.normal(0, 1.0, 7)])
    weight = 1.0 / (2.0 + np.abs(offset))
    offset[::10], weight[::10] = np.nan, 0.0
    factor = motion_prior.variance_factor(component, offset, weight, n_components=4)
    found = weight > 0
    sums = np.array([np.sum((weight * offset**2)[found & (component == i)]) for i in range(4)])
    counts = np.array([np.sum(found & (component == i)) for i in range(4)])
    pooled = sums.sum() / (counts.sum() - 6 * 3)
    np.testing.assert_allclose(factor, (sums + 12 * pooled) / (np.maximum(counts - 6, 0) + 12), rtol=1e-12)
    assert factor[1] > 5 * factor[0]  # the noisy component is trusted less
    assert factor[2] == pytest.approx(pooled)  # no samples: the pooled value
    np.testing.assert_array_equal(
        motion_prior.variance_factor(component[:0], offset[:0], weight[:0], n_components=2), 1.0
    )
    np.testing.assert_array_equal(
        motion_prior.variance_factor(component[:0], offset[:0], weight[:0], n_components=2, fallback=[0.2, 0.3]),
        [0.2, 0.3],
    )
