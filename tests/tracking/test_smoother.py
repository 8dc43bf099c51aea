"""The Rauch-Tung-Striebel smoother over a track (tracker.tracking.smoother): its recursion against the batch least
squares over all frames, and on the model's parts a still body, a steady motion, noise taken out and the joints."""

import dataclasses

import numpy as np
from conftest import HUMAN

from tracker.geometry import se3
from tracker.model import load_model
from tracker.tracking.settings import MotionSettings
from tracker.tracking.smoother import rts_kernel, segments, smooth_segment, smoothed_track


def _spd(rng, shape, size, rank=None):
    """Random symmetric positive (semi-)definite matrices of ``shape`` + (size, size), of ``rank`` (default full)."""
    factor = rng.normal(size=(*shape, size, rank or size))
    return factor @ np.swapaxes(factor, -1, -2) + (0.0 if rank else 0.1 * np.eye(size))


def test_rts_on_a_linear_chain_is_the_batch_least_squares_solution():
    """On random linear chains (transitions, offsets, noises, a prior), with measurements of singular information and
    a frame measuring nothing, the smoothed means equal the minimiser of the whole cost over all frames, solved
    densely, to 1e-9 of their size."""
    rng = np.random.default_rng(3)
    chains, frames = 3, 9
    transition = np.eye(6) + 0.3 * rng.normal(size=(chains, frames - 1, 6, 6))
    offset = rng.normal(size=(chains, frames - 1, 6))
    noise = _spd(rng, (chains, frames - 1), 6)
    measured = rng.normal(size=(chains, frames, 3))
    information = _spd(rng, (chains, frames), 3, rank=2)
    information[:, 4] = 0.0
    mean0, covariance0 = rng.normal(size=(chains, 6)), _spd(rng, (chains,), 6)
    found = rts_kernel(transition, offset, noise, measured, information, mean0, covariance0)
    for m in range(chains):
        hessian, gradient = np.zeros((6 * frames, 6 * frames)), np.zeros(6 * frames)

        def add(jacobian, target, weight):  # the term |jacobian s - target|^2_weight
            nonlocal hessian, gradient
            hessian += jacobian.T @ weight @ jacobian
            gradient += jacobian.T @ weight @ target

        first = np.zeros((6, 6 * frames))
        first[:, :6] = np.eye(6)
        add(first, mean0[m], np.linalg.inv(covariance0[m]))
        for k in range(frames):
            position = np.zeros((3, 6 * frames))
            position[:, 6 * k : 6 * k + 3] = np.eye(3)
            add(position, measured[m, k], information[m, k])
        for k in range(frames - 1):
            step = np.zeros((6, 6 * frames))
            step[:, 6 * k + 6 : 6 * k + 12] = np.eye(6)
            step[:, 6 * k : 6 * k + 6] = -transition[m, k]
            add(step, offset[m, k], np.linalg.inv(noise[m, k]))
        expected = np.linalg.solve(hessian, gradient).reshape(frames, 6)
        assert np.abs(found[m] - expected).max() < 1e-9 * np.abs(expected).max()


def _model_and_pose():
    """The human model and a pose of it with every joint turned a little."""
    model = load_model(HUMAN)
    rng = np.random.default_rng(5)
    poses = np.empty((model.size, 4, 4))
    for i in range(model.size):
        parent = model.parent[i]
        at = np.eye(4) if parent < 0 else poses[parent] @ model.rest[i]
        poses[i] = at @ se3.exp(np.r_[0.0, 0.0, 0.0, 0.2 * rng.normal(size=3)])
    return model, model.coerce(poses)


def _information(rng, frames, n):
    """Each frame's information about each part (F, N, 2, 3, 3): about (4 mm)^-2 and (0.03 rad)^-2, of random
    directions."""
    out = _spd(rng, (frames, n, 2), 3)
    out[:, :, 0] *= 1.0 / 0.004**2 / 3
    out[:, :, 1] *= 1.0 / 0.03**2 / 3
    return out


def test_a_still_body_stays_still():
    """Forty frames of one pose, whatever each frame's information: the smoothed poses are that pose to round-off."""
    model, pose = _model_and_pose()
    frames = 40
    poses = np.broadcast_to(pose, (frames, *pose.shape)).copy()
    rng = np.random.default_rng(1)
    smoothed = smoothed_track(
        model,
        poses,
        _information(rng, frames, model.size),
        times=np.arange(frames) / 30.0,
        starts=np.zeros(frames, bool),
        motion=MotionSettings(),
    )
    assert np.abs(smoothed - poses).max() < 1e-9


def test_a_steady_motion_is_kept():
    """Every part's origin moving at its own constant world velocity and the part turning at its own constant body
    angular velocity, without velocity decay (the model's motion then has no acceleration to take out): the smoothed
    poses are the measured ones to 1e-6 (the rotation chains' first order, and their Gauss-Newton passes)."""
    model = load_model(HUMAN)
    rng = np.random.default_rng(2)
    start = np.array([se3.from_rotvec(rng.normal(size=3), rng.normal(size=3)) for _ in range(model.size)])
    velocity, spin = 0.02 * rng.normal(size=(model.size, 3)), 0.05 * rng.normal(size=(model.size, 3))
    frames = 30
    poses = np.empty((frames, model.size, 4, 4))
    for k in range(frames):
        for i in range(model.size):
            poses[k, i] = se3.from_rotation(
                start[i, :3, :3] @ se3.exp_so3(k * spin[i]), start[i, :3, 3] + k * velocity[i]
            )
    motion = dataclasses.replace(MotionSettings(), decay=0.0)
    information = _information(rng, frames, model.size)
    smoothed = smooth_segment(poses, information, np.arange(frames) / 30.0, motion=motion)
    assert np.abs(smoothed - poses).max() < 1e-6


def test_noise_is_taken_out_and_the_joints_stay_exact():
    """A body turning its joints smoothly, each frame's parts measured with noise as large as their information
    says (4 mm, 0.03 rad): the smoothed joint centres lie nearer the truth than the measured ones (coerced onto the
    joints), by a fifth or more in the mean, and every joint of the smoothed poses holds (coercion leaves them as
    they are)."""
    model, pose = _model_and_pose()
    rng = np.random.default_rng(4)
    frames, n = 60, model.size
    times = np.arange(frames) / 30.0
    truth = np.empty((frames, n, 4, 4))
    for k, t in enumerate(times):
        for i in range(n):
            parent = model.parent[i]
            swing = np.r_[0.0, 0.0, 0.0, 0.4 * np.sin(2.0 * t + i), 0.3 * np.cos(1.5 * t + 2 * i), 0.0]
            at = (
                se3.exp(np.r_[0.3 * t, 0.0, 0.0, 0.0, 0.0, 0.2 * t]) if parent < 0 else truth[k, parent] @ model.rest[i]
            )
            truth[k, i] = at @ se3.exp(swing)
        truth[k] = model.coerce(truth[k])
    information = _information(rng, frames, n)
    measured = truth.copy()
    for k in range(frames):
        for i in range(n):
            step = np.r_[rng.normal(scale=0.004, size=3), rng.normal(scale=0.03, size=3)]
            measured[k, i] = truth[k, i] @ se3.exp(step)
    smoothed = smoothed_track(
        model, measured, information, times=times, starts=np.zeros(frames, bool), motion=MotionSettings()
    )
    coerced = np.stack([model.coerce(row) for row in measured])

    def error(poses):
        return np.linalg.norm(poses[:, :, :3, 3] - truth[:, :, :3, 3], axis=-1).mean()

    assert error(smoothed) < 0.8 * error(coerced)
    assert max(np.abs(model.coerce(row) - row).max() for row in smoothed) < 1e-9


def test_segments_restart_where_told():
    assert segments(np.array([True, False, False, True, False, True])) == [slice(0, 3), slice(3, 5), slice(5, 6)]
    assert segments(np.zeros(4, bool)) == [slice(0, 4)]
