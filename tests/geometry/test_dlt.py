"""The linear triangulation against points known exactly: noiseless rays meet at the point."""

from pathlib import Path

import numpy as np

from tracker.geometry.dlt import triangulate_many
from tracker.io.recording import open_recording

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def test_noiseless_rays_give_the_point_back_and_one_view_gives_none():
    cameras = open_recording(DEMO).cameras
    points = np.random.default_rng(5).normal([0.0, 0.0, 1.0], 0.5, size=(8, 3))
    normalised = np.stack([camera.undistort_pixels(camera.project(points)) for camera in cameras], axis=1)
    projections = np.array([camera.camera_from_world[:3] for camera in cameras])
    seen = np.ones((8, len(cameras)), bool)
    seen[1, 0] = False  # two views of three
    seen[2, 1:] = False  # one view
    normalised[1, 0] = np.nan  # an unseen view's ray does not count, whatever it holds
    found = triangulate_many(projections, normalised, seen)
    np.testing.assert_allclose(np.delete(found, 2, axis=0), np.delete(points, 2, axis=0), atol=1e-9)
    assert np.isnan(found[2]).all()
