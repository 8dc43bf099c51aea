"""tracker points --record/--view: the parts rebuilt from poses.npz and shapes.npz, drawn frame by frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import TEST_DATA
from scipy.spatial import cKDTree

from tracker.cli import main
from tracker.io.markers import read_markers
from tracker.io.poses import load_poses
from tracker.physics import superquadric as sq
from tracker.viewer.marker_view import PointsView, node_positions

ROOT = Path(__file__).resolve().parents[2]
VICON = TEST_DATA / "markers" / "Vicon.c3d"  # its first 160 frames
MODEL = ROOT / "models" / "vicon_arm.points.toml"


def test_points_run_is_rebuilt_and_recorded_for_the_viewer(tmp_path: Path) -> None:
    """The nodes rebuilt from the two files reproduce each part's residual (RMS distance of its markers
    to their nearest nodes) to round-off, and --record writes a playable .viser file of every frame."""
    recording = tmp_path / "arm.viser"
    assert (
        main(
            [
                "points",
                str(VICON),
                "--model",
                str(MODEL),
                "--out",
                str(tmp_path),
                "--frames",
                "4",
                "--record",
                str(recording),
                "--port",
                "0",
                "--quiet",
            ]
        )
        == 0
    )
    assert recording.stat().st_size > 10_000
    results, shapes = load_poses(tmp_path / "poses.npz"), dict(np.load(tmp_path / "shapes.npz"))
    markers = read_markers(VICON).select([str(name) for name in shapes["marker_names"]])
    mesh = sq.mesh(*shapes["mesh"])
    for row, frame in enumerate(results["frame"]):
        nodes = node_positions(results["poses"][row], shapes["q_s"][row], shapes["d"][row], mesh=mesh)
        for p, part_nodes in enumerate(nodes):
            mine = markers[frame][shapes["marker_part"] == p]
            distances = cKDTree(part_nodes).query(mine)[0]
            assert np.sqrt(np.mean(distances**2)) == pytest.approx(shapes["residual"][row, p], rel=1e-9)


def test_view_draws_each_frame_and_skips_unseen_markers(tmp_path: Path, server) -> None:
    assert main(["points", str(VICON), "--model", str(MODEL), "--out", str(tmp_path), "--frames", "2", "--quiet"]) == 0
    results, shapes = load_poses(tmp_path / "poses.npz"), dict(np.load(tmp_path / "shapes.npz"))
    markers = read_markers(VICON).select([str(name) for name in shapes["marker_names"]])[:2].copy()
    markers[1, :3] = np.nan
    view = PointsView(server, results, shapes, markers, 100.0)
    view.show(1)
    assert len(view.dots.points) == len(shapes["marker_names"]) - 3
    assert np.allclose(view.joints.points, results["joints"][1], atol=1e-3)  # viser sends float16
    view.show(99)  # clamped to the last row
    assert view.slider.value == 1 and view.row == 1
    assert "frame 1:" in view.status.content
    view.show(0)
    assert view.row == 0 and np.allclose(view.joints.points, results["joints"][0], atol=1e-3)
