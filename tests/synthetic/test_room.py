"""The room backdrop: one static image per camera, a view of one 3-D room, seeded, furniture that never
hides the capture volume, and nothing in it that the person detector takes for a person."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracker.camera import Camera, load_calibration, look_at_camera, save_calibration
from tracker.errors import TrackerInputError
from tracker.landmarks.detector import Detector, detect_views
from tracker.model import joint_centres, load_model
from tracker.synthetic import render, room, synth
from tracker.synthetic.props import box_corners, cast_boxes

MODEL = Path(__file__).resolve().parents[2] / "models" / "human.toml"
VOLUME = (np.array([-1.0, -1.2, 0.0]), np.array([1.0, 1.2, 2.2]))


@pytest.fixture(scope="module")
def human():
    return load_model(MODEL)


def _rig(tmp_path) -> Path:
    path = tmp_path / "rig.toml"
    save_calibration(
        [
            look_at_camera(
                "a", (0.5, -4.0, 1.4), (0, 0, 0.9), size=(160, 120), focal=140.0, distortions=(-0.05, 0.01, 0, 0)
            ),
            look_at_camera("b", (4.0, 0.5, 1.2), (0, 0, 0.9), size=(160, 120), focal=140.0),
        ],
        path,
    )
    return path


def _smaller(camera: Camera, factor: int) -> Camera:
    """The camera with its image ``factor`` times smaller (the same view)."""
    matrix = camera.matrix.copy()
    matrix[0:2] /= factor
    return dataclasses.replace(camera, size=(camera.size[0] // factor, camera.size[1] // factor), matrix=matrix)


def test_every_frame_shows_the_one_backdrop_off_the_body_and_the_cameras_see_different_views(tmp_path, human):
    out = tmp_path / "rec"
    staging = synth.Staging(backdrop="room")
    rig = _rig(tmp_path)
    synth.synthesize(MODEL, rig, out, frames=3, seed=1, codec="png", noise=0.0, progress=False, staging=staging)
    cameras = load_calibration(rig)  # as synthesize read them (calibration.toml holds them rounded)
    with np.load(out / "truth.npz") as truth:
        poses = truth["poses"]
    backdrops = synth.room_backdrops(cameras, joint_centres(poses), seed=1)
    for camera, backdrop in zip(cameras, backdrops):
        images = [cv2.imread(str(path)) for path in sorted((out / camera.name).glob("*.png"))]
        renderer = render.Renderer(human, camera, backdrop, noise=0.0)
        covered = np.any([renderer.cast(p)[0] >= 0 for p in poses], axis=0).astype(np.uint8)
        off_body = cv2.dilate(covered, np.ones((7, 7), np.uint8)) == 0
        assert 0.5 < off_body.mean() < 0.99  # the body is there, small
        for image, pose in zip(images, poses):
            np.testing.assert_array_equal(image[off_body], backdrop[off_body])  # the room, as rendered once
            np.testing.assert_array_equal(image, renderer.render(pose))
        assert np.any(images[0] != images[2])  # the body moved
    assert np.abs(backdrops[0].astype(int) - backdrops[1]).mean() > 20  # two views of the room, not one picture
    with pytest.raises(TrackerInputError, match="exclude each other"):
        synth.synthesize(MODEL, rig, tmp_path / "both", frames=1, backgrounds=[], progress=False, staging=staging)


def test_the_room_is_seeded():
    rig = [_smaller(camera, 8) for camera in synth.ring4_rig()]
    first, again, other = (room.make_room(rig, *VOLUME, seed=seed) for seed in (3, 3, 4))
    np.testing.assert_array_equal(room.room_backdrop(first, rig[0]), room.room_backdrop(again, rig[0]))
    assert np.abs(room.room_backdrop(first, rig[0]).astype(int) - room.room_backdrop(other, rig[0])).mean() > 10
    assert [d.s0 for d in first.decor] == [d.s0 for d in again.decor] != [d.s0 for d in other.decor]


@pytest.mark.parametrize("rig", ["demo3", "ring4", "corner3"])
def test_the_furniture_stands_in_the_room_clear_of_the_volume_and_hides_none_of_it(rig):
    cameras = synth.RIGS[rig]()
    targets = np.stack(np.meshgrid(*(np.linspace(VOLUME[0][a], VOLUME[1][a], 7) for a in range(3))), -1).reshape(-1, 3)
    for seed in range(3):
        made = room.make_room(cameras, *VOLUME, seed=seed)
        assert len(made.parts) >= 10 and {d.kind for d in made.decor} == {"door", "window", "poster"}
        centres = np.array([camera.center for camera in cameras])
        assert np.all((centres > made.low) & (centres < made.high))  # the cameras are inside
        boxes = [part.box for part in made.parts]
        corners = np.concatenate([box_corners(box) for box in boxes])
        assert np.all((corners >= made.low - 1e-9) & (corners <= made.high + 1e-9))
        for box in boxes:  # no volume point inside a box
            local = (targets - box.world_from_box[0:3, 3]) @ box.world_from_box[0:3, 0:3]
            assert not np.any(np.all(np.abs(local) <= box.half, axis=1))
        for camera in cameras:  # and none behind one: the boxes along each point's ray lie beyond it
            seen = targets @ camera.rotation.T + camera.translation
            depth, _, _ = cast_boxes(boxes, camera, seen[:, 0:2] / seen[:, 2:3])
            assert np.all(depth > seen[:, 2])


def test_the_detector_finds_no_person_in_the_rooms_but_finds_the_body_in_one(human):
    """The rooms of the suite's three rigs, at a quarter of their size: BlazePose finds nobody, where it
    finds somebody in both background photos and the body standing in a room."""
    images = []
    for name, rig in synth.RIGS.items():
        cameras = [_smaller(camera, 2) for camera in rig()]
        images += synth.room_backdrops(cameras, np.array(VOLUME), seed=len(name))
    photos = render.load_backgrounds(synth.demo3_rig()[:2])[0]
    cameras = [_smaller(camera, 2) for camera in synth.demo3_rig()]
    backdrop = synth.room_backdrops(cameras, np.array(VOLUME), seed=5)[0]
    body = render.Renderer(human, cameras[0], backdrop, noise=0.0, face=synth.head_face(human))
    pose = synth.motion_poses(human, "procedural", 1)[0][0]

    def found(image: np.ndarray) -> bool:
        detector = Detector(landmark_model="full")
        try:
            return bool(detect_views([detector], [image], cameras=cameras[:1])[0].confidence.max() > 0.0)
        finally:
            detector.close()

    assert [found(image) for image in images] == [False] * len(images)
    assert found(photos[0]) and found(photos[1]) and found(body.render(pose))
