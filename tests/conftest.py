"""Shared fixtures: small rendered recordings with ground truth (made once per test session), and the
check that bad input gets a one-line error."""

from pathlib import Path

import pytest

from tracker.camera import save_calibration
from tracker.errors import TrackerInputError
from tracker.synth import look_at_camera, synthesize

ROOT = Path(__file__).resolve().parents[1]
HUMAN = ROOT / "models" / "human.toml"
CMU = ROOT.parent / "shared" / "data" / "cmu-mocap" / "131_01.bvh"


@pytest.fixture
def one_line_error():
    """Call a function that must raise TrackerInputError with a one-line message; returns the message."""

    def check(call) -> str:
        with pytest.raises(TrackerInputError) as error:
            call()
        message = str(error.value)
        assert "\n" not in message
        return message

    return check


@pytest.fixture(scope="session")
def tiny_recording(tmp_path_factory) -> Path:
    """A 6-frame, two-camera 320x240 rendering of the human model doing the procedural motion."""
    folder = tmp_path_factory.mktemp("tiny")
    rig = [
        look_at_camera("cam0", (0.5, -3.5, 1.3), (0.0, 0.0, 0.9), size=(320, 240), focal=280.0),
        look_at_camera("cam1", (3.3, 0.8, 1.6), (0.0, 0.0, 0.9), size=(320, 240), focal=280.0),
    ]
    save_calibration(rig, folder / "rig.toml")
    synthesize(HUMAN, folder / "rig.toml", folder / "rec", motion="procedural", frames=6, seed=1)
    return folder / "rec"
