"""The keypoints' learnt noise (tracker.tracking.landmark_noise): zones from the recent misfits, how firmly the
edges hold each landmark's limb, and what a frame teaches, on small cases worked out by hand."""

import numpy as np

from tracker.tracking.landmark_noise import NOISE_WINDOW, LandmarkNoise, learnt_tolerance


def test_each_landmark_zone_is_learnt_from_its_misfits():
    history = np.full((30, 4), np.nan)
    history[:10, 0] = 0.01  # a close landmark: the floor
    history[:10, 1] = np.linspace(0.04, 0.06, 10)  # median 0.05: twice that
    history[:10, 2] = 0.5  # far off: the ceiling
    history[:3, 3] = 0.1  # seen too rarely: the floor
    np.testing.assert_allclose(
        learnt_tolerance(history, floor=0.03, multiple=2.0, ceiling=0.15, least=5), [0.03, 0.10, 0.15, 0.03]
    )


def test_held_falls_from_one_to_zero_about_the_limit():
    noise = LandmarkNoise.start(landmarks=5, components=4, floor=0.03)
    noise = LandmarkNoise(noise.misfits, noise.row, noise.tolerance, np.array([0.0, 0.6, 0.8, 1.0]))
    placer = np.array([-1, 0, 1, 2, 3])  # a landmark on the surface, then one at each component's joint
    held = noise.held(placer, 0.8)  # 1 below 3/4 of the limit (0.6), 0 beyond 5/4 (1.0), linear between
    np.testing.assert_allclose(held, [1.0, 1.0, 1.0, 0.5, 0.0], atol=1e-12)


def test_a_frame_teaches_the_held_landmarks_the_median_of_their_cameras_and_nothing_else():
    noise = LandmarkNoise.start(landmarks=3, components=1, floor=0.03)
    misfit = np.array([[0.04, 0.2, np.nan], [0.06, 0.4, np.nan], [0.05, np.nan, np.nan]])  # (cameras, landmarks)
    held = np.array([1.0, 0.4, 1.0])  # the second landmark's limb not held
    taught = noise.learnt(misfit, held, floor=0.03, multiple=1.5, ceiling=0.15)
    np.testing.assert_array_equal(taught.misfits[0], [0.05, np.nan, np.nan])
    assert taught.row == 1 and noise.row == 0 and np.isnan(noise.misfits).all()  # the old noise stays as it was
    np.testing.assert_array_equal(taught.tolerance, [0.03, 0.03, 0.03])  # seen once: not learnt yet
    for _ in range(NOISE_WINDOW + 2):  # the window wraps round
        taught = taught.learnt(misfit, held, floor=0.03, multiple=1.5, ceiling=0.15)
    assert taught.row == NOISE_WINDOW + 3
    np.testing.assert_allclose(taught.tolerance, [0.075, 0.03, 0.03])  # 1.5 times 0.05
    assert noise.learnt(misfit, held, floor=0.03, multiple=0.0, ceiling=0.15) is noise  # multiple 0: fixed zones
