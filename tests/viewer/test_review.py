import hashlib
from pathlib import Path

import numpy as np

from tracker.cli import main
from tracker.io.recording import open_recording
from tracker.model import load_model
from tracker.tracking.frame_loop import Tracker
from tracker.viewer.review import Review, truth_rows
from tracker.viewer.scene import Scene


def _review(server, tracked):
    recording, results = tracked
    rec = open_recording(recording)
    model = load_model(rec.model_path)
    from tracker.io.poses import load_poses

    truth = load_poses(rec.truth_path)
    scene = Scene(server, model, rec.cameras, truth_names=list(truth["joint_names"]))
    return Review(scene, rec, Tracker(model, rec.cameras, results["poses"][0]), results, truth), scene


def test_review_draws_any_row_with_its_edge_search(server, tracked):
    review, scene = _review(server, tracked)
    try:
        for row in (3, 0, 5, 4):  # seeks backwards and forwards
            review.show(row)
            assert review.row == row
            pose = review.results["poses"][row]
            np.testing.assert_allclose(scene.meshes[0].position, pose[0, 0:3, 3])
            assert f"frame {review.frames[row]}:" in scene.status.content
            panel = scene.panels[0].image
            assert panel.shape == (240, 320, 3) and panel.std() > 5  # an image, not a blank
        review.step(-1)
        assert review.row == 3 and int(review.slider.value) == 3
    finally:
        review.close()


def test_review_of_poses_without_status_or_residual_labels_the_frame_alone(server, tracked):
    """A truth.npz holds poses but no status or residual: its rows are drawn, labelled with their frame only."""
    recording, results = tracked
    truth_like = {key: value for key, value in results.items() if key not in ("status", "residual")}
    review, scene = _review(server, (recording, truth_like))
    try:
        review.show(2)
        assert scene.status.content.endswith(f"frame {review.frames[2]}")
    finally:
        review.close()


def test_record_writes_a_viser_file_growing_with_the_frames(server, tracked, tmp_path):
    review, _ = _review(server, tracked)
    try:
        review.record(tmp_path / "session.viser", progress=False)
    finally:
        review.close()
    data = (tmp_path / "session.viser").read_bytes()
    assert len(data) > 6 * 5000  # six frames of three camera images at least
    assert not list(tmp_path.glob(".*.tmp"))  # written atomically, no temporary left


def test_truth_rows_match_frames_and_leave_gaps_nan():
    truth = {"frame": np.array([2, 3, 4]), "joints": np.arange(3 * 2 * 3, dtype=float).reshape(3, 2, 3)}
    rows = truth_rows(truth, np.array([3, 7, 2]))
    np.testing.assert_array_equal(rows[0], truth["joints"][1])
    assert np.isnan(rows[1]).all()
    np.testing.assert_array_equal(rows[2], truth["joints"][0])


def test_view_without_poses_is_a_one_line_error(tiny_recording, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["view", str(tiny_recording), "--port", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no poses to review" in err and "tracker track" in err


def test_view_of_poses_from_another_model_is_a_one_line_error(tracked, tmp_path, capsys):
    recording, results = tracked
    other = dict(results)
    other["component_names"] = np.array([f"part{i}" for i in range(len(results["component_names"]))])
    np.savez(tmp_path / "poses.npz", **other)
    assert main(["view", str(recording), "--poses", str(tmp_path / "poses.npz"), "--port", "0"]) == 2
    assert "do not match the model" in capsys.readouterr().err


def test_view_record_writes_the_session_and_says_only_that(tracked, tmp_path, capsys):
    """--record writes a file: no viewer address, no banner of viser's server and no "Server stopped"."""
    recording, results = tracked
    np.savez(tmp_path / "poses.npz", **results)
    session = tmp_path / "review.viser"
    argv = ["view", str(recording), "--poses", str(tmp_path / "poses.npz"), "--record", str(session), "--quiet"]
    assert main([*argv, "--port", "0"]) == 0
    printed = capsys.readouterr()
    assert printed.out == f"wrote {session}\n"
    assert "viser" not in printed.err and "http" not in printed.err
    assert session.stat().st_size > 6 * 5000


def test_record_into_a_place_that_cannot_be_written_is_one_line_before_any_work(tmp_path, capsys):
    """--record of view (and of track --view) into a folder that is a file: the one error line, before a server
    starts or a frame is drawn or tracked (no banner, no progress bar, no "Server stopped"), and every file as it
    was."""
    demo = Path(__file__).resolve().parents[2] / "recordings" / "demo"
    with np.load(demo / "truth.npz") as truth:  # its first three frames, as tracked
        poses = {key: truth[key][:3] for key in ("frame", "poses", "joints")} | {"joint_names": truth["joint_names"]}
        poses |= {"component_names": truth["component_names"], "status": np.zeros(3, np.int8), "residual": np.zeros(3)}
    np.savez(tmp_path / "poses.npz", **poses)
    taken = tmp_path / "taken"
    taken.write_bytes(b"a file where the session's folder would be")
    given = (taken, tmp_path / "poses.npz", *demo.iterdir())
    before = {path: hashlib.sha256(path.read_bytes()).hexdigest() for path in given}
    session = str(taken / "review.viser")
    for argv in (
        ["view", str(demo), "--poses", str(tmp_path / "poses.npz"), "--record", session, "--port", "0"],
        ["track", str(demo), "--out", str(tmp_path / "out"), "--view", "--record", session, "--port", "0"],
    ):
        assert main(argv) == 2
        printed = capsys.readouterr()
        assert printed.out == "" and len(printed.err.splitlines()) == 1
        assert printed.err == (
            f"tracker: error: {taken}: cannot write there (File exists); {taken} is a file, not a folder; choose "
            "another output path\n"
        )
    assert {path: hashlib.sha256(path.read_bytes()).hexdigest() for path in before} == before
    assert not (tmp_path / "out").exists()


def test_record_without_view_is_refused(tiny_recording, tmp_path, capsys):
    assert main(["track", str(tiny_recording), "--out", str(tmp_path), "--record", str(tmp_path / "a.viser")]) == 2
    assert "add --view" in capsys.readouterr().err


def test_a_non_loopback_host_warns_and_every_server_says_its_url(capsys):
    from tracker.viewer.scene import start_server

    server = start_server("0.0.0.0", 0)
    try:
        err = capsys.readouterr().err
        assert "warning" in err and "0.0.0.0" in err
        assert f"http://127.0.0.1:{server.get_port()}" in err
    finally:
        server.stop()


def test_truth_skeleton_and_root_trajectory_are_drawn(server, tracked):
    review, scene = _review(server, tracked)
    try:
        review.show(2)
        truth = review.truth[2]
        segments = scene.truth.points
        assert segments.shape == (review.results["poses"].shape[1] - 1, 2, 3)
        assert np.abs(segments).max() > 0.1 and np.isfinite(truth).all()
        path = scene.trajectory.points  # one segment between consecutive root positions
        np.testing.assert_allclose(path[:, 0], review.results["poses"][:-1, 0, 0:3, 3], atol=1e-6)
    finally:
        review.close()


def test_play_advances_the_timeline(server, tracked):
    import threading

    review, _ = _review(server, tracked)
    reached_end = threading.Event()
    show = review.show

    def watched(row):
        show(row)
        if row == len(review.frames) - 1:
            reached_end.set()

    review.show = watched
    try:
        review.speed.value = "4x"
        review.play.value = True
        assert reached_end.wait(timeout=30)  # the player thread walked to the last frame
        assert review.row == len(review.frames) - 1
    finally:
        review.close()


def test_review_against_a_background_shows_the_difference_images(server, tracked, monkeypatch):
    """With the run's empty scene the panels show and search |I - B| summed over colour, as tracking did."""
    from tracker.io.readers import FrameSeeker
    from tracker.tracking.foreground import Background

    recording, results = tracked
    rec = open_recording(recording)
    model = load_model(rec.model_path)
    rng = np.random.default_rng(3)
    background = Background(tuple(rng.integers(0, 256, (c.size[1], c.size[0], 3), dtype=np.uint8) for c in rec.cameras))
    scene = Scene(server, model, rec.cameras)
    searched = []  # the images each inspection is given
    inspect = Tracker.inspect

    def recorded(self, images, **given):
        searched.append(images)
        return inspect(self, images, **given)

    monkeypatch.setattr(Tracker, "inspect", recorded)
    review = Review(scene, rec, Tracker(model, rec.cameras, results["poses"][0]), results, None, background)
    try:
        review.show(2)
        seeker = FrameSeeker(rec.sources[0], colour=True)
        expected = background.difference(0, seeker.read(int(review.frames[2])))
        seeker.close()
        np.testing.assert_array_equal(searched[-1][0], expected)  # the edge search's input, before its smoothing
    finally:
        review.close()
