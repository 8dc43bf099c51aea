"""``tracker sync --refine`` (tracker.apps.sync): a render's offsets refined by each camera's edges against the body
tracked in the other cameras."""

import numpy as np
from conftest import HUMAN, ROOT

from tracker.cli import main
from tracker.io.poses import load_poses
from tracker.io.sync import load_offsets


def test_tracker_sync_refines_the_offsets_of_a_render_by_the_edges(tmp_path, capsys):
    """End to end: a render whose cameras run 0.04 s late and 0.025 s early (athletic motion, patterned clothes, the
    room); each camera's offset refined by its edges against the body tracked in the two others (on r30a, docs/sync.md,
    within 0.6 ms; a test allows 5 ms, since the last bits differ between machines)."""
    rec = tmp_path / "rec"
    args = ["synth", "--model", str(HUMAN), "--calib", str(ROOT / "calib" / "demo3.toml"), "--out", str(rec)]
    staging = ["--motion", "athletic", "--fps", "30", "--frames", "45", "--seed", "4", "--texture", "mixed"]
    assert main(args + staging + ["--backdrop", "room", "--time-offsets", "cam1=0.04,cam2=-0.025", "--quiet"]) == 0
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["sync", str(rec), "--refine", "--out", str(out), "--quiet"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("cam0  +0.0000 s  reference") and lines[-1] == f"wrote {rec / 'sync.toml'}"
    assert all("by the edges (landmarks " in line for line in lines[1:3]), lines
    written = load_offsets(rec / "sync.toml", ["cam0", "cam1", "cam2"], 1.5)
    assert abs(written["cam1"] - 0.04) < 0.005 and abs(written["cam2"] + 0.025) < 0.005
    for left_out in ("cam1", "cam2"):
        poses = load_poses(out / "sync" / f"without-{left_out}" / "poses.npz")
        assert len(poses["frame"]) == 45 and np.isfinite(poses["poses"]).all()
    assert (out / "keypoints.npz").is_file()
