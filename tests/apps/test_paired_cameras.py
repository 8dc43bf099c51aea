"""Cameras that are not frame-locked, end to end: a render whose cameras were captured late or early, tracked with
its offsets in sync.toml, comes out as well as the same render with every camera on time, and worse without them."""

import shutil
from pathlib import Path

import pytest
from conftest import HUMAN

from tracker.camera import look_at_camera, save_calibration
from tracker.cli import main
from tracker.evaluate import evaluate
from tracker.io.poses import load_poses
from tracker.synthetic.synth import Staging, synthesize

FPS = 30.0
OFFSETS = (("cam1", 2 / FPS), ("cam2", -3 / FPS))  # whole frames: the pairing leaves nothing to carry


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> dict[str, Path]:
    """The same athletic motion seen by three 320x240 cameras, on time and with cam1 two frames late and cam2 three
    early (``offset``), and the latter again beside its true sync.toml (``synced``)."""
    folder = tmp_path_factory.mktemp("paired")
    rig = [
        look_at_camera("cam0", (0.5, -3.8, 1.4), (0.0, 0.0, 0.9), size=(320, 240), focal=260.0),
        look_at_camera("cam1", (3.6, 0.9, 1.6), (0.0, 0.0, 0.9), size=(320, 240), focal=260.0),
        look_at_camera("cam2", (-3.0, 2.2, 1.2), (0.0, 0.0, 0.9), size=(320, 240), focal=260.0),
    ]
    save_calibration(rig, folder / "rig.toml")
    render = dict(motion="athletic", frames=30, fps=FPS, seed=3, progress=False)
    synthesize(HUMAN, folder / "rig.toml", folder / "on_time", staging=Staging(texture="stripes"), **render)
    late = Staging(texture="stripes", time_offsets=OFFSETS)
    synthesize(HUMAN, folder / "rig.toml", folder / "offset", staging=late, **render)
    shutil.copytree(folder / "offset", folder / "synced")
    lines = "\n".join(f"{name} = {seconds!r}" for name, seconds in OFFSETS)
    (folder / "synced" / "sync.toml").write_text(f"[offsets]\n{lines}\n")
    return {name: folder / name for name in ("on_time", "offset", "synced")}


def _mpjpe(recording: Path, out: Path) -> float:
    assert main(["track", str(recording), "--out", str(out), "--keypoints", "off", "--quiet"]) == 0
    return evaluate(load_poses(out / "poses.npz"), load_poses(recording / "truth.npz")).mpjpe_mm


def test_views_paired_by_their_offsets_track_as_well_as_views_on_time(renders, tmp_path):
    on_time = _mpjpe(renders["on_time"], tmp_path / "on_time")
    synced = _mpjpe(renders["synced"], tmp_path / "synced")
    offset = _mpjpe(renders["offset"], tmp_path / "offset")
    # the first two and last three frames of a shifted camera repeat its first or last one: a little worse there
    assert synced < 1.3 * on_time + 5.0
    assert offset > 1.5 * synced
