"""Viewer fixtures: a tracked tiny recording and a viser server on a free loopback port."""

from pathlib import Path

import pytest

from tracker.cli import main
from tracker.io.poses import load_poses
from tracker.viewer.scene import start_server


@pytest.fixture(scope="session")
def tracked(tiny_recording, tmp_path_factory) -> tuple[Path, dict]:
    """The tiny recording and the poses.npz that `tracker track` wrote for it."""
    out = tmp_path_factory.mktemp("tracked")
    assert main(["track", str(tiny_recording), "--out", str(out), "--quiet"]) == 0
    return tiny_recording, load_poses(out / "poses.npz")


@pytest.fixture
def server():
    server = start_server("127.0.0.1", 0, quiet=True)
    yield server
    server.stop()


@pytest.fixture(scope="session")
def tracked_demo(tmp_path_factory) -> dict:
    """poses.npz of the bundled demo's first 60 frames."""
    out = tmp_path_factory.mktemp("demo")
    demo = Path(__file__).resolve().parents[2] / "recordings" / "demo"
    assert main(["track", str(demo), "--out", str(out), "--frames", "60", "--quiet"]) == 0
    return load_poses(out / "poses.npz")
