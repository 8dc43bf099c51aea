import itertools

import numpy as np

from tracker.io.posefile import load_pose_file
from tracker.io.recording import frames, open_recording
from tracker.model import load_model
from tracker.tracking.frame_loop import Tracker
from tracker.viewer.live_view import LiveView
from tracker.viewer.scene import Scene


def test_live_view_shows_the_newest_frame_and_records_the_session(server, tiny_recording, tmp_path):
    rec = open_recording(tiny_recording)
    model = load_model(rec.model_path)
    init = load_pose_file(rec.init_path, model)
    tracker = Tracker(model, rec.cameras, init)
    scene = Scene(server, model, rec.cameras)
    live = LiveView(scene, tracker, rate=30.0, record=tmp_path / "live.viser")
    last = None
    for index, images in itertools.islice(frames(rec, prepare=tracker.smooth), 6):
        last = tracker.step(images, smoothed=True)
        live.offer(index, images, last, elapsed=0.01)
    live.close()
    assert live.shown >= 1
    assert scene.status.content.startswith("frame 5:")  # close() shows the newest frame
    np.testing.assert_allclose(scene.meshes[0].position, last.poses[0, 0:3, 3])
    frames_plotted, fps = live.plots["fps"].data
    np.testing.assert_array_equal(frames_plotted, np.arange(6.0))
    np.testing.assert_allclose(fps, 100.0)
    assert (tmp_path / "live.viser").stat().st_size > 5000


def test_the_scene_draws_the_parts_the_images_do_not_hold_grey_and_see_through(server, tiny_recording):
    from tracker.status import HELD, LOOSE, UNSEEN
    from tracker.viewer.scene import BODY, LOOSE_OPACITY, Frame

    rec = open_recording(tiny_recording)
    model = load_model(rec.model_path)
    scene = Scene(server, model, rec.cameras)
    poses = load_pose_file(rec.init_path, model)
    held = np.full(model.size, HELD, np.int8)
    held[[model.index("shin_l"), model.index("foot_l")]] = LOOSE, UNSEEN
    scene.show(Frame(poses, held=held))
    dim = [k for k, mesh in enumerate(scene.meshes) if mesh.opacity is not None]
    assert dim == sorted([model.index("shin_l"), model.index("foot_l")])
    assert scene.meshes[dim[0]].opacity == LOOSE_OPACITY and tuple(scene.meshes[dim[0]].color) != BODY
    scene.show(Frame(poses))  # a frame that does not say: every part as held
    assert all(mesh.opacity is None and tuple(mesh.color) == BODY for mesh in scene.meshes)
