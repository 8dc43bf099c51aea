"""The hard suite: its definition covers every hardship, make / run / score work end to end, and a stopped run lets
the render being tracked save its frames."""

from __future__ import annotations

import json
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA, needs_shared

from tracker.camera import load_calibration
from tracker.cli import main
from tracker.commands import suite as suite_command
from tracker.io.poses import PosesWriter, load_poses
from tracker.landmarks.body_landmarks import LANDMARKS, landmark_points
from tracker.landmarks.landmark_models import RECORDED
from tracker.landmarks.store import Keypoints, save_keypoints
from tracker.model import load_model
from tracker.synthetic import suite
from tracker.synthetic.texture import KINDS

ROOT = Path(__file__).resolve().parents[2]
SMALL = "turn-6fps-table"  # procedural, ring4 at 640x480: the cheapest render to make in a test


def hardships(render: suite.Render) -> set[str]:
    """What the render departs from a plain 60 fps render of the model by."""
    staging = render.staging
    found = {staging.texture} - {"none"}
    found |= {"capsules"} if staging.body == "capsules" else set()
    found |= {"table"} if staging.tables else set()
    found |= {"border"} if staging.zoom > 1.0 else set()
    found |= {"far"} if staging.distance > 1.0 else set()
    found |= {"motion blur"} if staging.motion_blur > 1 else set()
    found |= {"30 fps"} if render.rate == 30.0 else {"low fps"} if 6.0 <= render.rate <= 10.0 else set()
    found |= {"athletic"} if render.motion == "athletic" else set()
    found |= {"bystanders"} if staging.backdrop == "photos" else set()
    return found


def test_the_suite_covers_clips_motions_rigs_and_every_hardship():
    renders = suite.SUITE
    assert len(renders) >= 8 and len({r.name for r in renders}) == len(renders)
    assert {r.motion for r in renders} == {"131_01.bvh", "131_02.bvh", "procedural", "athletic"}
    assert {r.rig for r in renders} == {"demo3", "ring4", "corner3"}
    assert all((ROOT / "calib" / f"{r.rig}.toml").is_file() for r in renders)
    every = {*KINDS, "mixed", "capsules", "table", "border", "far", "motion blur", "30 fps", "low fps", "athletic"}
    assert set().union(*map(hardships, renders)) == every | {"bystanders"}
    assert all(r.staging.face for r in renders)  # a detector can tell each body's front from its back
    assert [r.name for r in renders if r.staging.backdrop == "photos"] == ["dance-print-bystanders"]  # else a room
    assert all(len(hardships(r)) >= 2 for r in renders)  # each combines a few
    assert all(60 <= r.frames <= 120 for r in renders)
    clips = [r for r in renders if r.motion in suite.CLIPS]
    assert all(r.start + r.stride * (r.frames - 1) < {"131_01.bvh": 994, "131_02.bvh": 1247}[r.motion] for r in clips)


def _write_poses(path: Path, truth: dict, shift: float) -> None:
    """A poses.npz of the true poses with every joint moved ``shift`` metres along x."""
    with PosesWriter(path, list(truth["component_names"]), list(truth["joint_names"]), 6.0) as writer:
        for frame, poses in zip(truth["frame"], truth["poses"]):
            joints = poses[:, 0:3, 3] + [shift, 0.0, 0.0]
            writer.append(int(frame), poses, joints, status=0, residual=0.5)


def test_make_then_score_known_errors(tmp_path, capsys):
    out, results = tmp_path / "suite", tmp_path / "results"
    assert main(["suite", "make", str(out), "--only", SMALL, "--frames", "3", "--quiet"]) == 0
    folder = out / SMALL
    assert {"calibration.toml", "model.toml", "truth.npz", "truth_init.toml", "README.md"} <= {
        p.name for p in folder.iterdir()
    }
    assert not (folder / "init.toml").exists()  # the tracker must find the start itself
    assert sorted(p.name for p in folder.glob("*.avi")) == ["cam0.avi", "cam1.avi", "cam2.avi", "cam3.avi"]
    truth = load_poses(folder / "truth.npz")
    assert len(truth["frame"]) == 3
    capsys.readouterr()
    for shift, mpjpe, pck in ((0.0, 0.0, 1.0), (0.03, 30.0, 1.0), (0.07, 70.0, 0.0)):
        _write_poses(results / SMALL / "poses.npz", truth, shift)
        assert main(["suite", "score", str(out), str(results), "--json"]) == 0
        scores = json.loads(capsys.readouterr().out)
        row = scores["renders"][0]
        assert row["name"] == SMALL and row["frames"] == 3 and row["lost_frames"] == 0 and row["fps"] == 6.0
        assert row["mpjpe_mm"] == pytest.approx(mpjpe, abs=1e-3)
        assert row["pa_mpjpe_mm"] == pytest.approx(0.0, abs=1e-3)  # a shift, aligned away
        assert row["pck"] == pck and scores["worst_pck"] == pck and scores["mean_mpjpe_mm"] == row["mpjpe_mm"]
    assert main(["suite", "score", str(out), str(results)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[1].split()[:5] == [SMALL, "ring4", "6", "70.0", "0.0"]
    # the detector's landmarks scored against the truth: landmarks at the true joints' images score zero
    cameras = load_calibration(folder / "calibration.toml")
    component = landmark_points(load_model(folder / "model.toml"), LANDMARKS)[0]
    pixels = np.full((3, len(cameras), len(LANDMARKS), 2), np.nan)
    for k, camera in enumerate(cameras):
        for j in np.flatnonzero(component >= 0):
            pixels[:, k, j] = camera.project(truth["poses"][:, component[j], 0:3, 3])
    found = Keypoints(
        truth["frame"], tuple(c.name for c in cameras), pixels, np.ones(pixels.shape[:3]), np.zeros((3, 4, 33, 3))
    )
    save_keypoints(tmp_path / "kp" / SMALL / "keypoints.npz", found)
    assert main(["suite", "landmarks", str(out), str(tmp_path / "kp"), "--json"]) == 0
    row = json.loads(capsys.readouterr().out)[0]
    assert row["name"] == SMALL and row["median"] == 0.0 and row["wrong"] == 0.0 and row["swapped"] == 0.0
    assert row["views"] == row["found"] == row["on_body"] == 12 and 12 * 9 <= row["scored"] < 12 * 12  # cam0's table
    assert row["triangulated_mm"] == pytest.approx(0.0, abs=1e-6) and row["coverage"] == 1.0  # every known joint, true
    assert main(["suite", "landmarks", str(out), str(tmp_path / "kp"), "--landmark-model", "lite"]) == 2  # none made
    lite = tmp_path / "kp" / SMALL / "keypoints-lite.npz"
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"tracker: error: {lite}: not found; detect it with tracker keypoints {out / SMALL} --out {lite.parent} "
        "--landmark-model lite"
    )
    # the same landmarks beside the results: triangulated frame by frame they are the true joints, so the
    # baseline is 0 mm while the tracker, 70 mm off (then 200 mm: every frame beyond 150 mm), keeps its number
    save_keypoints(results / SMALL / "keypoints.npz", found)
    for shift, far in ((0.07, 0.0), (0.2, 1.0)):
        _write_poses(results / SMALL / "poses.npz", truth, shift)
        assert main(["suite", "score", str(out), str(results), "--json"]) == 0
        row = json.loads(capsys.readouterr().out)["renders"][0]
        assert row["landmarks_mm"] == pytest.approx(0.0, abs=1e-6)
        assert row["tracker_same_mm"] == pytest.approx(1000 * shift, abs=1e-3) and row["far_share"] == far


def test_run_tracks_with_the_options_given(tmp_path, capsys):
    out, results = tmp_path / "suite", tmp_path / "results"
    assert main(["suite", "make", str(out), "--only", SMALL, "--frames", "2", "--quiet"]) == 0
    # no init.toml and no keypoints to fit a first pose to: tracker track refuses, and run says so in one line
    assert main(["suite", "run", "--quiet", str(out), str(tmp_path / "refused"), "--", "--keypoints", "off"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--init" in err[0] and "track.log" in err[0]
    assert "no init.toml" in (tmp_path / "refused" / SMALL / "track.log").read_text()
    assert (
        main(
            ["suite", "run", "--quiet", "--json", str(out), str(results)]
            + ["--", "--init", "{rec}/truth_init.toml", "--keypoints", "off"]
        )
        == 0
    )
    row = json.loads(capsys.readouterr().out)["renders"][0]
    assert row["frames"] == 2 and row["lost_frames"] == 0 and row["mpjpe_mm"] < 50.0  # edges from the true start
    assert len(load_poses(results / SMALL / "poses.npz")["frame"]) == 2
    assert (results / SMALL / "track.log").read_text().splitlines()[0].endswith(f"--landmark-model {RECORDED}")


STOPPED_TRACK = """
import os, signal, sys
from pathlib import Path

number, out = int(sys.argv[1]), Path(sys.argv[sys.argv.index("--out") + 1])
stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
for stop in stops:
    signal.signal(stop, signal.SIG_DFL)
signal.pthread_sigmask(signal.SIG_BLOCK, stops)
os.kill(os.getppid(), number)  # the suite is stopped while this tracks
got = signal.sigtimedwait(stops, 60)
if got is None:
    sys.exit("the stop was not passed on")
(out / "poses.npz").write_text(signal.Signals(got.si_signo).name)
print(f"wrote {out / 'poses.npz'} (3 frames)")
print("tracker: interrupted: the frames done so far are saved", file=sys.stderr)
sys.exit(128 + got.si_signo)
"""


@pytest.mark.parametrize("number", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_stopped_run_passes_the_stop_on_and_waits_for_the_render_tracked(number, tmp_path, monkeypatch, capsys):
    """Ctrl-C, SIGTERM or SIGHUP while ``tracker track`` (stood in for) tracks a render: the child gets the same
    signal (SIGINT for Ctrl-C) and saves its frames, its log is written, and the suite stops with the signal's code."""
    out, results = tmp_path / "suite", tmp_path / "results"
    (out / SMALL).mkdir(parents=True)
    np.savez(out / SMALL / "truth.npz", joint_names=np.array(["pelvis"]), joints=np.zeros((1, 1, 3)))
    monkeypatch.setattr(suite_command, "TRACK", (sys.executable, "-c", STOPPED_TRACK, str(int(number))))
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C raises KeyboardInterrupt
    try:
        assert main(["suite", "run", "--quiet", str(out), str(results)]) == 128 + number
    finally:
        signal.signal(signal.SIGINT, handler)
    assert capsys.readouterr().err == "tracker: interrupted\n"
    assert (results / SMALL / "poses.npz").read_text() == signal.Signals(number).name
    log = (results / SMALL / "track.log").read_text()
    assert "(3 frames)" in log and "tracker: interrupted: the frames done so far are saved" in log


@pytest.mark.parametrize(
    "argv",
    [
        ["suite", "score", "{out}", "{tmp}/no-results"],  # results folder missing
        ["suite", "score", "{tmp}/no-suite", "{tmp}"],  # suite folder missing
        ["suite", "score", "{out}", "{tmp}", "--only", "kick-spin-blur"],  # a render not made
        ["suite", "make", "{tmp}/x", "--only", "no-such-render"],
        ["suite", "make", "{tmp}/x", "--only", ""],  # a list that names no render
        ["suite", "make", "{tmp}/x", "--only", ","],
        ["suite", "make", "{tmp}/x", "--only", "far-walk"],  # a CMU render without --clips
        ["suite", "run", "{out}", "{tmp}/r", "--json", "--", "--init", "x"],  # suite option after RESULTS
        ["suite", "run", "{out}", "{tmp}/r", "--", "--landmark-model", "lite"],  # it names the detections scored too
        ["suite", "landmarks", "{out}", "{tmp}/no-keypoints"],
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv):
    out = tmp_path / "suite"
    (out / SMALL).mkdir(parents=True)
    np.savez(out / SMALL / "truth.npz", joint_names=np.array(["pelvis"]), joints=np.zeros((1, 1, 3)))
    (tmp_path / "empty").mkdir()
    words = [w.replace("{out}", str(out)).replace("{tmp}", str(tmp_path)) for w in argv]
    assert main(words) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tracker: error: ") and "Traceback" not in err[0]


@needs_shared("cmu-mocap", "131_01.bvh")
def test_cmu_renders_make_from_the_clips(tmp_path):
    names = ["webcam-8fps", "walk-capsules-stripes"]
    summaries = suite.make(tmp_path, suite.select(names), clips=SHARED_DATA / "cmu-mocap", frames=2, progress=False)
    assert [s["fps"] for s in summaries] == [30.0, 8.0]  # in suite order
    assert [len(load_poses(tmp_path / name / "truth.npz")["frame"]) for name in names] == [2, 2]
