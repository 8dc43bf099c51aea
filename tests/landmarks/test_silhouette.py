"""The person's segmentation (tracker.landmarks.silhouette): the square's map, and the mask on the demo's body."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.landmarks.crop import Region
from tracker.landmarks.detect_recording import detect_recording
from tracker.landmarks.silhouette import PersonMask, Segmenter
from tracker.model import load_model
from tracker.synthetic.render import Renderer

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def test_covers_reads_the_square_at_each_image_point():
    """A square of side 64 centred at (100, 50), read at 256 x 256: image x maps to crop 4 (x - 100) + 128.
    The person fills the crop's left half; points outside the square or not finite are not on him."""
    person = np.zeros((256, 256), bool)
    person[:, :128] = True
    mask = PersonMask(Region((100.0, 50.0), 64.0), person)
    points = np.array([[80.0, 50.0], [99.9, 30.0], [100.1, 50.0], [120.0, 70.0], [60.0, 50.0], [np.nan, 50.0]])
    np.testing.assert_array_equal(mask.covers(points), [True, True, False, False, False, False])


def test_the_mask_covers_the_demo_body_and_little_else():
    """cam0 of the demo's first frames: the rendered body's pixels lie on the mask, and the rest of the square
    around it mostly not (the mask is widened by a few pixels, so a band around the outline is allowed)."""
    recording = open_recording(DEMO)
    keypoints, _ = detect_recording(recording, 0, 3, landmark_model="full")
    model, truth = load_model(DEMO / "model.toml"), load_poses(DEMO / "truth.npz")
    segmenter = Segmenter()
    try:
        for index, images in frames(recording, 0, 3, colour=True):
            mask = segmenter.mask(images[0], keypoints.pixels[index, 0])
            assert mask is not None
            component, _, _ = Renderer(model, recording.cameras[0], noise=0.0, blur=0.0).cast(truth["poses"][index])
            ys, xs = np.mgrid[0 : component.shape[0], 0 : component.shape[1]]
            pixels = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)
            on = mask.covers(pixels).reshape(component.shape)
            body = component >= 0
            near = np.zeros_like(body)  # within 8 pixels of the body
            rows, columns = np.nonzero(body)
            for dy in range(-8, 9, 2):
                for dx in range(-8, 9, 2):
                    near[np.clip(rows + dy, 0, body.shape[0] - 1), np.clip(columns + dx, 0, body.shape[1] - 1)] = True
            x0, y0 = mask.region.centre[0] - mask.region.side / 2, mask.region.centre[1] - mask.region.side / 2
            square = (xs >= x0) & (xs < x0 + mask.region.side) & (ys >= y0) & (ys < y0 + mask.region.side)
            assert on[body].mean() > 0.9
            assert on[square & ~near].mean() < 0.05
    finally:
        segmenter.close()


def test_landmarks_off_their_own_detections_mask_are_dropped():
    """Two views of one frame with masks over squares of side 64 about (100, 50), the person filling the crop's
    left half (image x < 100; widened by FAR_OFF, 15 crop pixels, 3.75 image pixels): the landmarks left of x 103.75
    keep their confidence, those from it on get none; a view without a mask, or keypoints without masks, keep
    theirs."""
    from tracker.landmarks.silhouette import on_person
    from tracker.landmarks.store import Keypoints

    pixels = np.zeros((1, 3, 33, 2))
    pixels[..., 0] = np.linspace(80.0, 120.0, 33)
    pixels[..., 1] = 50.0
    confidence = np.full((1, 3, 33), 0.9)
    mask = np.zeros((1, 3, 256, 256), np.uint8)
    mask[:, :, :, :128] = 255
    square = np.tile([100.0, 50.0, 64.0], (1, 3, 1))
    square[0, 2] = np.nan
    keypoints = Keypoints(np.array([0]), ("a", "b", "c"), pixels, confidence, np.zeros((1, 3, 33, 3)))
    kept = on_person(dataclasses.replace(keypoints, mask=mask, square=square)).confidence[0]
    on = pixels[0, 0, :, 0] < 103.7
    for view in (0, 1):
        np.testing.assert_array_equal(kept[view], np.where(on, 0.9, 0.0))
    np.testing.assert_array_equal(kept[2], 0.9)
    assert on_person(keypoints) is keypoints
