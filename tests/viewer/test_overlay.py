import numpy as np

from tracker.tracking.workspace import Inspection
from tracker.viewer.overlay import component_colours, draw, weight_colour


def test_search_lines_are_coloured_by_weight_and_missing_edges_grey():
    image = np.full((60, 80), 200, np.uint8)
    inspection = Inspection(
        camera=np.array([0, 0, 1]),
        component=np.array([0, 1, 0]),
        pixel=np.array([[20.0, 15.0], [20.0, 45.0], [40.0, 30.0]]),
        normal=np.array([[1.0, 0.0]] * 3),
        lo=np.array([-8, -8, -8]),
        hi=np.array([8, 8, 8]),
        offset=np.array([0.0, np.nan, 1.0]),
        weight=np.array([0.5, 0.0, 1 / 3]),
        quadric=np.array([0, 1, 0]),
        point=np.zeros((3, 3)),
        jacobian=np.zeros((3, 6)),
    )
    out = draw(image, inspection, 0, robust_c=2.0, colours=component_colours(2))
    assert out.shape == (60, 80, 3) and out.dtype == np.uint8
    green = np.array(weight_colour(1.0))
    # sample 0 (perfect fit, w c = 1) draws a green line left of its dot; sample 1 (no edge) a grey one
    assert np.abs(out[15, 13].astype(int) - green).max() < 60
    assert abs(int(out[45, 13, 0]) - 110) < 30 and np.ptp(out[45, 13].astype(int)) < 10
    assert (out[30] == 200).all()  # camera 1's sample is not drawn on camera 0
    assert np.array_equal(out[5], np.full((80, 3), 200))


def test_weight_colours_run_from_red_to_green():
    assert weight_colour(0.0) == (255, 0, 40) and weight_colour(1.0) == (0, 255, 40)
    assert len({tuple(c) for c in component_colours(15)}) == 15


def test_track_writes_an_overlay_video_of_all_cameras(tiny_recording, tmp_path):
    import cv2

    from tracker.cli import main

    video = tmp_path / "overlay.mp4"
    assert main(["track", str(tiny_recording), "--out", str(tmp_path), "--overlay", str(video), "--quiet"]) == 0
    capture = cv2.VideoCapture(str(video))
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == 6
    ok, frame = capture.read()
    assert ok and frame.shape == (240, 640, 3)  # two 320x240 cameras side by side
    assert not list(tmp_path.glob(".overlay*"))  # the temporary file was renamed into place


def test_overlay_video_of_unknown_type_is_a_one_line_error(tiny_recording, tmp_path, capsys):
    from tracker.cli import main

    assert main(["track", str(tiny_recording), "--out", str(tmp_path), "--overlay", str(tmp_path / "o.gif")]) == 2
    assert "unknown video type" in capsys.readouterr().err


def test_parts_the_images_do_not_hold_are_drawn_dim_and_the_others_in_full(behind_a_table):
    """Behind the table the legs are left to the prior (tracker.tracking.held): drawn with the frame's held codes,
    their outline samples change the image by at most the dim opacity of what the full drawing changes it by (every
    third sample drawn, at 40 %), with no search line, while the parts the images hold are drawn as in full."""
    from conftest import tracked_behind

    from tracker.status import HELD
    from tracker.viewer.overlay import DIM_OPACITY

    tracker, results = tracked_behind(behind_a_table)
    images, result = results[-1]
    inspection = tracker.inspect()
    colours = component_colours(tracker.model.size)
    loose = result.held[inspection.component] != HELD
    assert loose.any() and (~loose).any()
    for camera, image in enumerate(images):
        plain = np.repeat(image[:, :, None], 3, axis=2).astype(int)
        full = draw(image, inspection, camera, robust_c=2.0, colours=colours).astype(int)
        dim = draw(image, inspection, camera, robust_c=2.0, colours=colours, held=result.held).astype(int)
        mine = inspection.camera == camera
        u, v = np.rint(inspection.pixel[mine]).astype(int).T
        inside = (u >= 0) & (u < image.shape[1]) & (v >= 0) & (v < image.shape[0])
        changed_full = np.abs(full[v, u] - plain[v, u]).sum(axis=1)
        changed_dim = np.abs(dim[v, u] - plain[v, u]).sum(axis=1)
        hidden, seen = inside & loose[mine], inside & ~loose[mine]
        assert changed_dim[hidden].sum() <= (DIM_OPACITY + 0.02) * changed_full[hidden].sum()
        assert changed_dim[seen].sum() >= 0.9 * changed_full[seen].sum()
        assert changed_full[seen].mean() > 100  # drawn in full: the component's colours over the grey
