"""Which views' landmarks agree, and where the agreeing views place the body in another view."""

from __future__ import annotations

import numpy as np
import pytest

from tracker.camera import look_at_camera
from tracker.landmarks.guided import MARGIN, agreeing_views, fits, placed, placed_points

CAMERAS = [
    look_at_camera("cam0", (3.0, 0.0, 1.2)),
    look_at_camera("cam1", (0.0, 3.0, 1.2)),
    look_at_camera("cam2", (-2.5, -2.0, 1.5)),
]


@pytest.fixture
def body() -> np.ndarray:
    """33 landmarks of a standing body (1.7 m tall, 0.4 m wide) around (0, 0, 0.9)."""
    rng = np.random.default_rng(7)
    return np.c_[rng.uniform(-0.2, 0.2, 33), rng.uniform(-0.15, 0.15, 33), rng.uniform(0.05, 1.75, 33)]


def _views(points: np.ndarray) -> np.ndarray:
    return np.array([camera.project(points) for camera in CAMERAS])


def test_views_of_one_body_agree(body):
    assert agreeing_views(CAMERAS, _views(body), np.ones((3, 33))).all()


def test_a_view_that_follows_something_else_agrees_with_none(body):
    pixels = _views(body)
    pixels[1] = CAMERAS[1].project(body + [1.0, 0.0, 0.8])  # a chair beside him, read as a person
    assert agreeing_views(CAMERAS, pixels, np.ones((3, 33))).tolist() == [True, False, True]


def test_a_few_landmarks_that_meet_by_chance_do_not_make_views_agree(body):
    pixels = _views(body)
    pixels[1, 10:] = CAMERAS[1].project(body[10:] + [1.0, 0.0, 0.8])  # 10 of 33 agree
    assert agreeing_views(CAMERAS, pixels, np.ones((3, 33))).tolist() == [True, False, True]


def test_unsure_or_missing_landmarks_are_not_judged(body):
    pixels, confidence = _views(body), np.ones((3, 33))
    confidence[0, 5:] = 0.2  # five sure landmarks: fewer than two views need in common
    pixels[2] = np.nan  # nobody found
    assert not agreeing_views(CAMERAS, pixels, confidence).any()


def test_the_square_where_the_others_place_the_body_is_around_its_image(body):
    pixels = _views(body)
    truth = pixels[1].copy()
    pixels[1] = np.nan
    points = placed_points(CAMERAS, pixels, np.ones((3, 33)), among=np.array([True, False, True]))
    np.testing.assert_allclose(points, body, atol=1e-9)
    square = placed(CAMERAS[1], points)
    low, high = truth.min(axis=0), truth.max(axis=0)
    np.testing.assert_allclose(square.centre, (low + high) / 2.0, atol=1e-6)
    assert square.side == pytest.approx(MARGIN * (high - low).max())


def test_no_square_for_a_body_outside_the_view_or_behind_it(body):
    assert placed(CAMERAS[1], body + [0.0, 8.0, 0.0]) is None  # beyond cam1, behind it
    assert placed(CAMERAS[1], body + [0.0, 0.0, 6.0]) is None  # far above its image's top


def test_a_reading_fits_only_where_the_others_place_the_body(body):
    camera, confidence = CAMERAS[1], np.ones(33)
    assert fits(camera, body, camera.project(body), confidence=confidence)
    # someone beside him along the epipolar lines of a pair of views is still off where the others place him
    assert not fits(camera, body, camera.project(body) + [230.0, 0.0], confidence=confidence)
    half = camera.project(body)
    half[:20] += 100.0
    assert not fits(camera, body, half, confidence=confidence)
    assert not fits(camera, body, camera.project(body), confidence=np.r_[np.ones(5), np.zeros(28)])  # too few to judge
