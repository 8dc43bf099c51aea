"""The cache of the detections (tracker.landmarks.detect_recording): a pick of the cameras keeps its own file beside
every camera's, each reused as it was, and a file of another recording is refused in one line that names the
options that choose another folder."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from tracker.io.pairing import by_offsets
from tracker.io.recording import Recording, open_recording
from tracker.landmarks.detect_recording import cache_file, cached, detect_recording, fingerprint
from tracker.landmarks.store import Keypoints, save_keypoints

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def _nobody(recording: Recording, frames: int = 3) -> Keypoints:
    """Keypoints of ``recording``'s first ``frames`` frames in which no person was found: a file the cache takes,
    made without the detector."""
    count = len(recording.cameras)
    return Keypoints(
        np.arange(frames),
        tuple(camera.name for camera in recording.cameras),
        np.full((frames, count, 33, 2), np.nan),
        np.zeros((frames, count, 33)),
        np.full((frames, count, 33, 3), np.nan),
        recording=fingerprint(recording),
    )


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_pick_of_the_cameras_keeps_its_own_cache_beside_every_cameras(tmp_path):
    """`fit-model REC --cameras cam2,cam0` then `fit-model REC` (and the other way round): each reads its own file in
    the same folder, whole and unchanged; every camera named in their order is not a pick."""
    every, pick = open_recording(DEMO), open_recording(DEMO, ["cam2", "cam0"])
    assert cache_file(tmp_path, every) == tmp_path / "keypoints.npz"
    assert cache_file(tmp_path, open_recording(DEMO, ["cam0", "cam1", "cam2"])) == tmp_path / "keypoints.npz"
    assert cache_file(tmp_path, pick) == tmp_path / "keypoints-cam2,cam0.npz"
    count, fps = pick.frame_count, pick.fps
    paired = dataclasses.replace(pick, pairing=by_offsets(np.array([0.0, 2 / fps]), count=count, fps=fps))
    assert cache_file(tmp_path, paired) == tmp_path / "keypoints-paired-cam2,cam0.npz"
    save_keypoints(cache_file(tmp_path, pick), _nobody(pick))
    held = _digest(cache_file(tmp_path, pick))
    assert cached(cache_file(tmp_path, every), every) is None  # nothing yet for every camera, and no error
    save_keypoints(cache_file(tmp_path, every), _nobody(every))
    before = {path.name: _digest(path) for path in tmp_path.iterdir()}
    assert before["keypoints-cam2,cam0.npz"] == held
    for recording in (every, pick, every):
        keypoints, detected = detect_recording(recording, 0, 3, cache=cache_file(tmp_path, recording))
        assert detected == 0 and keypoints.camera_names == tuple(camera.name for camera in recording.cameras)
    assert {path.name: _digest(path) for path in tmp_path.iterdir()} == before


def test_another_recordings_cache_is_one_line_naming_the_options_that_choose_the_folder(tmp_path, one_line_error):
    """A folder of the same name (a/rec1 and b/rec1 both default to out/rec1) or a folder chosen by mistake holds
    another recording's keypoints: refused, the file left as it was."""
    every = open_recording(DEMO)
    path = cache_file(tmp_path, every)
    save_keypoints(path, dataclasses.replace(_nobody(every), recording="cam0=1:0 cam1=1:0 cam2=1:0"))
    before = _digest(path)
    message = one_line_error(lambda: cached(path, every))
    assert message.startswith(f"{path}: holds the keypoints of another recording (cameras cam0, cam1, cam2)")
    assert "delete it" in message and "--out DIR" in message and "--cache DIR" in message
    assert _digest(path) == before
