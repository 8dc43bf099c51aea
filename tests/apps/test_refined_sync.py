"""``tracker sync --refine`` (tracker.apps.sync): a render's offsets refined by each camera's edges against the body
tracked in the other cameras."""

import re
import shutil

import numpy as np
import pytest

from tracker.apps.sync import REACH, _track
from tracker.cli import main
from tracker.io.poses import load_poses
from tracker.io.sync_file import load_offsets
from tracker.status import LOST, TRACKED

SOURCE = (
    r"(?P<camera>\S+)  (?P<seconds>\S+) s  \+-\S+  "
    r"by the (?:edges \(landmarks \S+\)|landmarks \(edges (?P<edges>\S+), undecided\))"
)
"""A camera's line: its offset, its sigma, and the cue that decided it (with the other's offset)."""


def test_tracker_sync_refines_the_offsets_of_a_render_by_the_edges(late_render, tmp_path, capsys):
    """End to end: a render whose cameras run 0.04 s late and 0.025 s early (athletic motion, patterned clothes, the
    room); each camera's offset refined by its edges against the body tracked in the two others.  Each camera's line
    says which cue decided its offset, and that offset is the one written: within a quarter of a frame (8 ms) of the
    truth, whichever cue decided it (a cue decides only where its offset spreads less than that, UNDECIDED; the
    renders of docs/sync.md come within 2 ms by the landmarks, 3.1 ms by the edges; a frame off is 33 ms).  Whether
    the edges decide is a bar that this short render sits near (under OPENBLAS_CORETYPE=Haswell or on an AVX-512
    machine cam1's rise falls just short of it): where they do not, their least is bound only to lie among the
    offsets searched, REACH frames either side of the landmarks'."""
    rec, out = tmp_path / "rec", tmp_path / "out"
    shutil.copytree(late_render.render, rec)
    out.mkdir()
    shutil.copy2(late_render.out / "keypoints-full.npz", out / "keypoints-full.npz")
    detected = (out / "keypoints-full.npz").stat()
    assert main(["sync", str(rec), "--refine", "--out", str(out), "--quiet", "--landmark-model", "full"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("cam0  +0.0000 s  reference") and lines[-1] == f"wrote {rec / 'sync.toml'}"
    written = load_offsets(rec / "sync.toml", ["cam0", "cam1", "cam2"], 3.0)
    for name, line, true in zip(("cam1", "cam2"), lines[1:3], (0.04, -0.025)):
        said = re.fullmatch(SOURCE, line)
        assert said is not None and said["camera"] == name, lines
        decided = float(said["seconds"])
        assert written[name] == pytest.approx(decided, abs=5e-5) and abs(decided - true) < 0.25 / 30, lines
        if said["edges"] is not None:  # the edges undecided: their least lies among the offsets searched
            assert abs(float(said["edges"]) - decided) <= REACH / 30 + 1e-4, lines
    for left_out in ("cam1", "cam2"):
        poses = load_poses(out / "sync" / f"without-{left_out}" / "poses.npz")
        assert len(poses["frame"]) == 90 and np.isfinite(poses["poses"]).all()
    kept = (out / "keypoints-full.npz").stat()  # the detections reused, not made again
    assert (kept.st_ino, kept.st_mtime_ns) == (detected.st_ino, detected.st_mtime_ns)


def test_a_camera_is_timed_against_the_longest_run_of_frames_held(tmp_path):
    """The track of the other cameras may start late, lose the body and pick it up again: the camera is timed
    against its longest run of frames held, from that run's first frame; a track that held none gives nothing."""
    rows = np.array([2, 3, 4, 6, 7, 8, 9, 10, 11])
    poses = np.tile(np.eye(4), (len(rows), 2, 1, 1))
    poses[:, 0, 0, 3] = rows  # each frame's pose names its frame
    for status, name in ((np.where(rows == 7, LOST, TRACKED), "held"), (np.full(len(rows), LOST), "lost")):
        names = {"component_names": np.array(["a", "b"]), "joint_names": np.array(["j"])}
        joints = np.zeros((len(rows), 1, 3))
        np.savez(tmp_path / f"{name}.npz", frame=rows, status=status, poses=poses, joints=joints, **names)
    begin, held = _track(tmp_path / "held.npz", 14)
    assert begin == 8 and held.shape == (4, 2, 4, 4) and list(held[:, 0, 0, 3]) == [8, 9, 10, 11]
    assert _track(tmp_path / "lost.npz", 14) is None
