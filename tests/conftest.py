"""Shared fixtures: small rendered recordings with ground truth (made once per test session; one of a seated body
behind a table, and the tracker run on it, :func:`tracked_behind`), a small poses file,
the check that bad input gets a one-line error, the hashes that show a command left a user's files alone, perfect
keypoint detections, a progress bar that stops the run with a signal (:func:`stopping_after`) and a terminal that
closes (:func:`closing_terminal`); where the tests' real data is (:data:`TEST_DATA`, :data:`SHARED_DATA`)."""

import contextlib
import errno
import hashlib
import io
import os
import shutil
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tracker.camera import look_at_camera, save_calibration
from tracker.cli import main
from tracker.errors import TrackerInputError
from tracker.synthetic.synth import Staging, synthesize

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


def file_hashes(*paths: Path) -> dict[Path, str]:
    """The SHA-256 of every file at ``paths`` (a file, or every file in a folder), by path: equal before and after a
    command when it changed no byte of them and added or removed no file."""
    files = [file for path in paths for file in ([path] if path.is_file() else sorted(path.rglob("*")))]
    return {file: hashlib.sha256(file.read_bytes()).hexdigest() for file in files if file.is_file()}


def stopping_after(frame: int, number: int, desc: str | None = None, *, then=None):
    """A progress bar (``tracker.commands.options.bar``) that sends this process the signal ``number`` once the run has
    done frame ``frame`` of the loop whose bar is ``desc`` (the tracked frames' by default), as a service manager
    would; ``then()``, if given, is called just before (:func:`closing_terminal`'s close, with SIGHUP)."""
    from tracker.commands import options

    bar = options.bar

    def stopping(args, shown, unit, *, leave=False):
        wrap = bar(args, shown, unit, leave=leave)
        if shown != desc:
            return wrap

        def items(iterable, total=None):
            for item in wrap(iterable, total=total):
                yield item  # the loop does the frame, then asks for the next
                if item[0] == frame:
                    assert signal.getsignal(number) not in (signal.SIG_DFL, signal.SIG_IGN), "it would end the tests"
                    if then is not None:
                        then()
                    os.kill(os.getpid(), number)

        return items

    return stopping


def closing_terminal(monkeypatch):
    """Standard output and error on a terminal (stand-ins for them), and the function that closes it: from then on
    writing to either fails with EIO, as it does once a terminal has hung up (SIGHUP)."""
    closed = []

    class Terminal(io.StringIO):
        def write(self, text: str) -> int:
            if closed:
                raise OSError(errno.EIO, os.strerror(errno.EIO))
            return super().write(text)

    monkeypatch.setattr(sys, "stdout", Terminal())
    monkeypatch.setattr(sys, "stderr", Terminal())
    return lambda: closed.append(True)


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


@pytest.fixture
def small_poses(tmp_path) -> Path:
    """A poses file of three frames of two joints at 30 frames a second, in the test's folder (run/poses.npz)."""
    path = tmp_path / "run" / "poses.npz"
    path.parent.mkdir()
    frame = np.arange(3)
    np.savez(path, joint_names=np.array(["a", "b"]), joints=np.zeros((3, 2, 3)), frame=frame, time=frame / 30.0)
    return path


@pytest.fixture(scope="session")
def perfect_detections():
    """Draw a detector's perfect landmarks: ``draw(cameras, world)`` of world points ``world`` (33, 3) (NaN where
    the model has no such point) gives their exact pixels (C, 33, 2) in ``cameras`` and confidence (C, 33), 1
    where known and 0 elsewhere; with ``seen_by=n`` only the first n cameras see them."""

    def draw(cameras, world: np.ndarray, seen_by: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        known = np.isfinite(world).all(axis=1)
        pixels = np.full((len(cameras), len(world), 2), np.nan)
        for k, camera in enumerate(cameras):
            pixels[k, known] = camera.project(world[known])
        confidence = np.where(known, 1.0, 0.0)[None].repeat(len(cameras), axis=0)
        if seen_by is not None:
            confidence[seen_by:] = 0.0
        return pixels, confidence

    return draw


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


@dataclass(frozen=True)
class Synced:
    """A render and ``tracker sync`` of it: ``render`` as rendered; ``rec`` a copy of it that ``tracker sync REC --out
    OUT`` (``out``) ran on, printing ``lines``."""

    render: Path
    rec: Path
    out: Path
    lines: list[str]


@pytest.fixture(scope="session")
def late_render(tmp_path_factory) -> Synced:
    """Three seconds whose cam1 runs 0.04 s late and cam2 0.025 s early (athletic motion, patterned clothes, the room,
    calib/demo3.toml at 30 fps), and ``tracker sync`` on a copy of it: rendered and detected once (by the full
    landmark model, the lighter of the two that place this body well) for the tests of the landmarks' offsets and of
    their refinement by the edges (which reuses the detections)."""
    folder = tmp_path_factory.mktemp("late")
    render, rec, out = folder / "render", folder / "rec", folder / "out"
    args = ["synth", "--model", str(HUMAN), "--calib", str(ROOT / "calib" / "demo3.toml"), "--out", str(render)]
    staging = ["--motion", "athletic", "--fps", "30", "--frames", "90", "--seed", "4", "--texture", "mixed"]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(args + staging + ["--backdrop", "room", "--time-offsets", "cam1=0.04,cam2=-0.025", "--quiet"]) == 0
    shutil.copytree(render, rec)
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        assert main(["sync", str(rec), "--out", str(out), "--quiet", "--landmark-model", "full"]) == 0
    return Synced(render, rec, out, printed.getvalue().splitlines())


@pytest.fixture
def person_masks():
    """Draw a segmenter's perfect person masks: ``draw(model, cameras, poses)`` gives each camera's silhouette of the
    body at ``poses`` as the detector hands it over (:meth:`tracker.tracking.frame_loop.Tracker.see_person`): masks
    (C, S, S) uint8, 255 on the body, over squares (C, 3: centre x, y and side) that cover the whole image."""

    def draw(model, cameras, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from tracker.raycast import RayCaster

        side = max(max(camera.size) for camera in cameras)
        masks = np.zeros((len(cameras), side, side), np.uint8)
        squares = np.zeros((len(cameras), 3))
        for k, camera in enumerate(cameras):
            width, height = camera.size
            masks[k, :height, :width] = np.where(RayCaster(model, camera).cast(poses)[0] >= 0, 255, 0)
            squares[k] = (side / 2.0 - 0.5, side / 2.0 - 0.5, side)
        return masks, squares

    return draw


@pytest.fixture(scope="session")
def behind_a_table(tmp_path_factory) -> Path:
    """Eight frames at 30 fps of the human model seated behind a table that hides its pelvis and legs from both
    cameras, on plain backgrounds without noise (three 320x240 views, from 1.7 m up)."""
    folder = tmp_path_factory.mktemp("table")
    rig = [
        look_at_camera("a", (0.4, -2.6, 1.7), (0.0, 0.0, 0.75), size=(320, 240), focal=280.0),
        look_at_camera("b", (-2.4, -1.2, 1.7), (0.0, 0.0, 0.75), size=(320, 240), focal=280.0),
        look_at_camera("c", (2.4, -1.2, 1.7), (0.0, 0.0, 0.75), size=(320, 240), focal=280.0),
    ]
    save_calibration(rig, folder / "rig.toml")
    synthesize(
        HUMAN,
        folder / "rig.toml",
        folder / "rec",
        motion="seated",
        frames=8,
        fps=30.0,
        seed=2,
        codec="png",
        noise=0.0,
        backgrounds=[],
        progress=False,
        staging=Staging(tables=("all",)),
    )
    return folder / "rec"


def tracked_behind(rec_path: Path):
    """The tracker on the render :func:`behind_a_table`, from its first true pose, and each frame's images and
    result, in order."""
    from tracker.io.posefile import load_pose_file
    from tracker.io.recording import frames, open_recording
    from tracker.model import load_model
    from tracker.tracking.frame_loop import Tracker

    rec = open_recording(rec_path)
    model = load_model(rec_path / "model.toml")
    tracker = Tracker(model, rec.cameras, load_pose_file(rec.init_path, model))
    return tracker, [(images, tracker.step(images)) for _, images in frames(rec)]
