"""Shared fixtures: small rendered recordings with ground truth (made once per test session), and the
check that bad input gets a one-line error; where the tests' real data is (:data:`TEST_DATA`,
:data:`SHARED_DATA`)."""

from pathlib import Path

import pytest

from tracker.camera import look_at_camera, save_calibration
from tracker.errors import TrackerInputError
from tracker.synthetic.synth import synthesize

ROOT = Path(__file__).resolve().parents[1]
HUMAN = ROOT / "models" / "human.toml"
TEST_DATA = ROOT / "tests" / "data"
"""Small real data committed with the tests (cut from ../shared/data by tests/data/cut.py; sources and
licences in tests/data/README.md): every test that reads only these runs in a plain clone."""
SHARED_DATA = ROOT.parent / "shared" / "data"
"""The large real data kept beside the repository (``../shared/data``, see its README.md), absent from a
plain clone: tests that need it are marked with :func:`needs_shared` and skip without it."""


def needs_shared(*parts: str) -> pytest.MarkDecorator:
    """Skip unless ``SHARED_DATA / parts...`` exists, naming what is missing."""
    where = "/".join(("../shared/data", *parts))
    return pytest.mark.skipif(
        not SHARED_DATA.joinpath(*parts).exists(), reason=f"{where} not present (data folder beside the repo)"
    )


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
