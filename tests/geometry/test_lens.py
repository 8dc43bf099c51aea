"""The kernels' lens models (tracker.geometry.lens) against OpenCV's projections, their Jacobians against
finite differences and the inverse against the forward map, for every lens a calibration file can give."""

import cv2
import numpy as np
import pytest

from tracker.camera import Camera
from tracker.geometry.lens import distort, undistort
from tracker.tracking.rig import Rig

K = np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])
LENSES = {  # name: (distortions in OpenCV's order, fisheye)
    "fisheye": ([0.08, -0.02, 0.01, 0.003], True),
    "4": ([-0.2, 0.05, 0.001, -0.002], False),
    "5": ([-0.25, 0.08, 0.001, -0.0015, -0.01], False),
    "8": ([-0.25, 0.08, 0.001, -0.0015, -0.01, 0.02, 0.3, 0.05], False),
    "12": ([-0.25, 0.08, 0.001, -0.0015, -0.01, 0.02, 0.3, 0.05, 0.003, -0.002, 0.001, 0.004], False),
    "14": ([-0.25, 0.08, 0.001, -0.0015, -0.01, 0.02, 0.3, 0.05, 0.003, -0.002, 0.001, 0.004, 0.03, -0.05], False),
}


def normalised_points(fisheye, count=300, seed=0):
    """Ideal normalised points up to 60 degrees off the axis for the fisheye, 0.6 for the others (where
    these lenses are one to one), with the centre and points next to it."""
    rng = np.random.default_rng(seed)
    reach = np.tan(np.radians(60.0)) if fisheye else 0.6
    radius = reach * np.sqrt(rng.uniform(0.0, 1.0, count))
    angle = rng.uniform(-np.pi, np.pi, count)
    radius[:4] = (0.0, 3e-9, 1e-6, 1e-3)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


def lens_of(name, matrix=K):
    distortions, fisheye = LENSES[name]
    camera = Camera("c", (640, 480), matrix, np.array(distortions), np.eye(3), np.zeros(3), fisheye)
    rig = Rig.from_cameras([camera])
    return camera, rig.lens[0], rig.distortion[0]


def kernel_pixels(matrix, kind, coef, xn):
    """distort() at the ideal pixels K x_n: rows (u, v, j00, j01, j10, j11)."""
    ideal = np.column_stack([xn, np.ones(len(xn))]) @ matrix.T
    return np.array([distort(matrix, kind, coef, px, py) for px, py in ideal[:, :2]])


@pytest.mark.parametrize("name", list(LENSES))
def test_projection_matches_opencv(name):
    """The pixels equal cv2.projectPoints' (cv2.fisheye.projectPoints') to 1e-9 px, and Camera.project's
    with a skewed camera matrix (which OpenCV's fisheye functions ignore, as Camera does)."""
    camera, kind, coef = lens_of(name)
    xn = normalised_points(camera.fisheye)
    points = np.column_stack([xn, np.ones(len(xn))])[:, None, :] * 2.5
    if camera.fisheye:
        opencv, _ = cv2.fisheye.projectPoints(points, np.zeros(3), np.zeros(3), K, camera.distortions)
    else:
        opencv, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, camera.distortions)
    np.testing.assert_allclose(kernel_pixels(K, kind, coef, xn)[:, :2], opencv.reshape(-1, 2), rtol=0, atol=1e-9)

    skewed = K.copy()
    skewed[0, 1] = 4.0
    camera, kind, coef = lens_of(name, skewed)
    expected = camera.project(points.reshape(-1, 3))
    np.testing.assert_allclose(kernel_pixels(skewed, kind, coef, xn)[:, :2], expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(LENSES))
def test_jacobian_matches_finite_differences(name):
    """J_d = d(recorded pixel)/d(ideal pixel) against central differences of distort() itself."""
    skewed = K.copy()
    skewed[0, 1] = 4.0
    camera, kind, coef = lens_of(name, skewed)
    xn = normalised_points(camera.fisheye, 100, seed=1)
    ideal = np.column_stack([xn, np.ones(len(xn))]) @ skewed.T
    step = 1e-3
    for (px, py), row in zip(ideal[:, :2], kernel_pixels(skewed, kind, coef, xn)):
        numeric = np.empty((2, 2))
        for axis in range(2):
            e = step * np.eye(2)[axis]
            plus = distort(skewed, kind, coef, px + e[0], py + e[1])[:2]
            minus = distort(skewed, kind, coef, px - e[0], py - e[1])[:2]
            numeric[:, axis] = (np.array(plus) - np.array(minus)) / (2 * step)
        np.testing.assert_allclose(row[2:].reshape(2, 2), numeric, rtol=0, atol=1e-8)


@pytest.mark.parametrize("name", list(LENSES))
def test_undistort_inverts_distort(name):
    skewed = K.copy()
    skewed[0, 1] = 4.0
    camera, kind, coef = lens_of(name, skewed)
    xn = normalised_points(camera.fisheye, seed=2)
    recorded = kernel_pixels(skewed, kind, coef, xn)[:, :2]
    back = np.array([undistort(skewed, kind, coef, u, v) for u, v in recorded])
    np.testing.assert_allclose(back, xn, rtol=0, atol=1e-11)  # 5e-9 px
    np.testing.assert_allclose(back, camera.undistort_pixels(recorded), rtol=0, atol=1e-10)


def test_an_unknown_coefficient_count_is_refused(one_line_error):
    """A camera made in code with a distortion OpenCV has no model for (a file cannot give one)."""
    for distortions, fisheye in (([0.1] * 6, False), ([0.1] * 5, True)):
        camera = Camera("odd", (640, 480), K, np.array(distortions), np.eye(3), np.zeros(3), fisheye)
        assert "'odd'" in one_line_error(lambda camera=camera: Rig.from_cameras([camera]))
