"""tracker points: points models, a synthetic arm tracked against its truth, and the real marker files
(the committed cuts in tests/data/markers: Vicon.c3d's first 160 frames, Qualisys.c3d's first 40)."""

from __future__ import annotations

import os
import signal
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import TEST_DATA

from tracker.cli import main
from tracker.errors import TrackerInputError
from tracker.geometry.se3 import exp_so3, log_so3
from tracker.io.markers import read_markers
from tracker.io.poses import load_poses
from tracker.physics import body as bd
from tracker.physics import kinematics as kin
from tracker.physics import points as pts
from tracker.physics import superquadric as sq

ROOT = Path(__file__).resolve().parents[2]
MARKERS = TEST_DATA / "markers"
VICON_ARM = ROOT / "models" / "vicon_arm.points.toml"
WALKER = ROOT / "models" / "qualisys_walker.points.toml"

# a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3: an upper arm, a forearm and a hand, metres
SHAPES = np.array(
    [
        [1.0, 0.050, 0.045, 0.150, 0.8, 1.0, 0.1, 0.0, 0.0, 0.0, 0.5],
        [1.0, 0.040, 0.035, 0.130, 0.8, 1.0, 0.2, 0.1, 0.0, 0.0, 0.5],
        [1.0, 0.045, 0.015, 0.090, 0.9, 0.9, 0.0, 0.0, 0.0, 0.0, 0.5],
    ]
)
MESH = sq.mesh(7, 8)
MARKER_NODES = [3, 6, 17, 20, 30, 33, 44, 47, 57]  # spread over the rings and longitudes


def vicon_arm(*options: str) -> int:
    """``tracker points`` on the Vicon arm's markers with its model, and ``options``."""
    return main(["points", str(MARKERS / "Vicon.c3d"), "--model", str(VICON_ARM), *options])


def _model(path: Path = Path("synthetic.toml")) -> pts.PointsModel:
    names = ("upper_arm", "forearm", "hand")
    markers = tuple(tuple(f"{name}{k}" for k in range(len(MARKER_NODES))) for name in names)
    return pts.PointsModel(path, "arm", names, markers, (-1, 0, 1), ("elbow", "wrist"), MESH)


def _truth(frame: int) -> tuple[list[kin.Part], np.ndarray]:
    """The arm at ``frame``: the whole arm turns and moves, the elbow bends 0.06 rad a frame and the
    wrist 0.03; returns its parts and the elbow and wrist centres (2, 3)."""
    parts = []
    for shape in SHAPES:
        part = kin.Part(np.zeros(3), np.eye(3), shape, np.zeros((len(MESH.u), 3)), MESH.u, MESH.v)
        if parts:
            end = bd.material_points(parts[-1], MESH, [bd.SOUTH])[0]
            top = bd.material_points(part, MESH, [bd.NORTH])[0]
            part = replace(part, c=end - top)
        parts.append(part)
    joints = [bd.material_points(parts[p], MESH, [bd.SOUTH])[0] for p in (0, 1)]
    bends = [exp_so3(np.array([0.06 * frame, 0.0, 0.0])), exp_so3(np.array([0.0, 0.03 * frame, 0.0]))]
    for joint, bend in zip(joints, bends):  # bend each joint, carrying the parts below it
        below = 1 if joint is joints[0] else 2
        for p in range(below, 3):
            parts[p] = replace(parts[p], c=joint + bend @ (parts[p].c - joint), rotation=bend @ parts[p].rotation)
        if below == 1:
            joints[1] = joint + bend @ (joints[1] - joint)
    whole, shift = exp_so3(np.array([0.3, 0.02 * frame, 0.1])), np.array([0.2 + 0.008 * frame, 0.1, 1.0])
    parts = [replace(p, c=whole @ p.c + shift, rotation=whole @ p.rotation) for p in parts]
    return parts, np.array([whole @ j + shift for j in joints])


def _markers(frame: int) -> np.ndarray:
    parts, _ = _truth(frame)
    return np.concatenate([kin.positions(part)[MARKER_NODES] for part in parts])


@pytest.mark.parametrize("dynamics", pts.DYNAMICS)
def test_synthetic_arm_is_tracked_with_its_joints(dynamics: str) -> None:
    """Nine markers per part at nodes of the true superquadrics, 100 frames a second; over 12 frames
    the elbow bends by 0.66 rad and the wrist by 0.33 while the arm turns and moves (the elbow
    travels 5.6 cm, the wrist 17).  The fit keeps the joints (|C| < 0.1 mm) and puts the elbow and
    wrist within 3.5 cm of the true centres, from a model that knows only its markers: measured
    22 mm at frame 0 (nearest-node fitting of 9 markers settles with the upper arm 2.7 cm too
    long), then 20-24 mm (second-order) or 25-28 mm (first-order); RMS marker-to-node distance
    under 3 cm for every part (the second-order hand, lagging its fast bend, reaches 26 mm)."""
    model = _model()
    frames = [_markers(f) for f in range(12)]
    fits = list(pts.track(frames, model, settings=pts.PointsSettings(dynamics=dynamics), interval=0.01))
    assert len(fits) == 12
    for f, fitted in enumerate(fits):
        _, true_joints = _truth(f)
        assert fitted.violation < 1e-4
        assert np.linalg.norm(fitted.joints - true_joints, axis=1).max() < 0.035, f
        assert np.all(fitted.residual < 0.03) and np.all(fitted.seen == len(MARKER_NODES))
        assert fitted.rms == pytest.approx(np.sqrt(np.mean(fitted.residual**2)))
    moved = np.linalg.norm(_truth(11)[1] - _truth(0)[1], axis=1)
    assert moved.min() > 0.05  # the joints travel: following them is not standing still


def test_a_part_without_markers_keeps_moving_on_its_joint() -> None:
    """The hand's markers vanish for frames 6-9.  Second-order: undamped without data, the hand goes
    on turning about the wrist, the way it turned before, while the wrist joint holds (measured:
    0.18 rad a frame relative to the forearm, more than the true 0.03, since the velocity it carries
    is the noisy one of the fit); it stays within 7 cm of the true hand and is reported unseen."""
    model = _model()
    frames = [_markers(f) for f in range(10)]
    for f in range(6, 10):
        frames[f] = frames[f].copy()
        frames[f][model.labels == 2] = np.nan
    fits = list(pts.track(frames, model, settings=pts.PointsSettings(dynamics="second-order"), interval=0.01))
    turned = [
        np.linalg.norm(
            log_so3(fit.body.parts[1].rotation.T @ fit.body.parts[2].rotation)
            - log_so3(fits[5].body.parts[1].rotation.T @ fits[5].body.parts[2].rotation)
        )
        for fit in fits[6:]
    ]
    assert turned[0] > 0.0 and np.all(np.diff(turned) > 0.0)  # it keeps turning the way it was
    for f, fitted in enumerate(fits[6:], start=6):
        assert np.isnan(fitted.residual[2]) and fitted.seen[2] == 0 and fitted.violation < 1e-4
        assert np.linalg.norm(fitted.body.parts[2].c - _truth(f)[0][2].c) < 0.07


@pytest.mark.parametrize("dynamics", pts.DYNAMICS)
def test_missing_markers_at_the_start_and_a_frame_without_any(dynamics: str) -> None:
    """A start frame with a marker hidden on each part, a later frame with no marker at all (the
    first-order body stays, the second-order one coasts; NaN residual) and then the markers again."""
    model = _model()
    frames = [_markers(f).copy() for f in range(6)]
    frames[0][[0, 9, 18]] = np.nan
    frames[3][:] = np.nan
    fits = list(pts.track(frames, model, settings=pts.PointsSettings(dynamics=dynamics), interval=0.01))
    assert np.all(fits[0].seen == len(MARKER_NODES) - 1) and np.isfinite(fits[0].poses).all()
    assert np.isnan(fits[3].rms) and np.all(fits[3].seen == 0) and np.isfinite(fits[3].poses).all()
    if dynamics == "first-order":
        assert np.array_equal(fits[3].poses, fits[2].poses)
    else:
        assert not np.array_equal(fits[3].poses, fits[2].poses)
    for f in (4, 5):
        assert np.linalg.norm(fits[f].joints - _truth(f)[1], axis=1).max() < 0.035


def test_start_frame_waits_for_three_markers_per_part() -> None:
    model = _model()
    frames = np.stack([_markers(f) for f in range(3)])
    frames[0, model.labels == 1] = np.nan
    frames[1, np.nonzero(model.labels == 1)[0][2:]] = np.nan  # two markers seen: not enough
    assert pts.start_frame(frames, model) == 2
    assert pts.start_frame(frames, model, 2) == 2
    with pytest.raises(TrackerInputError, match="part 'forearm' has 2 markers seen in frame 1, fewer than 3"):
        pts.start_frame(frames, model, 1)
    with pytest.raises(TrackerInputError, match="--start 3 is outside"):
        pts.start_frame(frames, model, 3)
    frames[2, model.labels == 1] = np.nan
    with pytest.raises(TrackerInputError, match="part 'forearm' never has 3 of its markers seen"):
        pts.start_frame(frames, model)


@pytest.mark.parametrize(
    "text, problem",
    [
        ("name = 'x'\n", "no [[part]] tables"),
        ("[[part]]\nname = 'a'\nmarkers = ['p', 'q']\n", "part 'a' has 2 markers"),
        (
            "[[part]]\nname = 'a'\nmarkers = ['p', 'q', 'r']\n[[part]]\nname = 'a'\nmarkers = ['s', 't', 'u']\n",
            "part 'a' is defined twice",
        ),
        ("[[part]]\nname = 'a'\nparent = 'z'\nmarkers = ['p', 'q', 'r']\n", "parent 'z', which is not a part"),
        (
            "[[part]]\nname = 'a'\nparent = 'b'\nmarkers = ['p', 'q', 'r']\n"
            "[[part]]\nname = 'b'\nparent = 'a'\nmarkers = ['s', 't', 'u']\n",
            "form a loop",
        ),
        (
            "[[part]]\nname = 'a'\nmarkers = ['p', 'q', 'r']\n[[part]]\nname = 'b'\nmarkers = ['r', 't', 'u']\n",
            "marker 'r' is listed on two parts",
        ),
        ("mesh = [0, 8]\n[[part]]\nname = 'a'\nmarkers = ['p', 'q', 'r']\n", "mesh = [0, 8]"),
        ("[[part]]\nname = 'a'\nmarkers = 'p'\n", "needs markers = "),
        ("mesh = [11]\n[[part]]\nname = 'a'\nmarkers = ['p', 'q', 'r']\n", "must be [rings, longitudes]"),
        (
            "[[part]]\nname = 'a'\nmarkers = ['p', 'q', 'r']\n[[part]]\nname = 'b'\nparent = 'a'\njoint = 'j'\n"
            "markers = ['s', 't', 'u']\n[[part]]\nname = 'c'\nparent = 'a'\njoint = 'j'\nmarkers = ['v', 'w', 'x']\n",
            "joint 'j' is named twice",
        ),
    ],
)
def test_bad_points_models_are_one_line_errors(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "model.toml"
    path.write_text(text)
    with pytest.raises(TrackerInputError) as error:
        pts.load_points_model(path)
    message = str(error.value)
    assert "\n" not in message and str(path) in message and problem in message


def test_bundled_models_name_markers_their_files_have() -> None:
    for model_path, file in ((VICON_ARM, "Vicon.c3d"), (WALKER, "Qualisys.c3d")):
        model = pts.load_points_model(model_path)
        points = read_markers(MARKERS / file).select(model.marker_names)
        assert np.isfinite(points[0]).all() and pts.start_frame(points, model) == 0
        assert len(model.joint_names) == len(model.parts) - 1 == len(set(model.joint_names))


def test_points_command_on_the_vicon_arm(tmp_path: Path, capsys) -> None:
    """The real Vicon.c3d raising arm, frames 0-29: every part seen, joints held to a micrometre,
    every part's RMS marker-to-node distance under 2.5 cm (measured over all 580 frames of the full
    file in ../shared/data: medians 13-21 mm, see README)."""
    code = vicon_arm("--out", str(tmp_path), "--frames", "30", "--quiet")
    assert code == 0
    report = capsys.readouterr().out
    assert "fitted 30 frames" in report and "30 with every part seen" in report
    poses = load_poses(tmp_path / "poses.npz")
    assert list(poses["component_names"]) == ["thorax", "upper_arm", "forearm", "hand"]
    assert list(poses["joint_names"]) == ["shoulder", "elbow", "wrist"]
    assert poses["poses"].shape == (30, 4, 4, 4) and np.all(poses["status"] == 0)
    assert np.allclose(poses["time"], np.arange(30) / 100.0)  # the file's 100 Hz
    assert np.all(poses["residual"] < 25.0)  # mm
    shapes = np.load(tmp_path / "shapes.npz")
    assert shapes["q_s"].shape == (30, 4, 11) and shapes["d"].shape == (30, 4, 11 * 11 + 2, 3)
    assert np.all(shapes["residual"] < 0.025) and np.all(shapes["violation"] < 1e-6)
    assert np.all(shapes["q_s"][:, :, 0] == 1.0)  # the a0 gauge


def test_every_other_frame_keeps_the_file_s_clock(tmp_path: Path) -> None:
    assert vicon_arm("--out", str(tmp_path), "--start", "10", "--frames", "6", "--every", "2", "--quiet") == 0
    poses = load_poses(tmp_path / "poses.npz")
    assert list(poses["frame"]) == [10, 12, 14] and np.allclose(poses["time"], [0.0, 0.02, 0.04])


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_a_stop_keeps_both_files_of_the_frames_done(stop, tmp_path: Path, monkeypatch, capsys) -> None:
    """Ctrl-C, or SIGTERM as a service manager sends it, after three frames: both files hold those frames, one line
    says so, and the exit code is the signal's (130, 143)."""
    real_track = pts.track

    def interrupted(*args, **kwargs):
        for count, fitted in enumerate(real_track(*args, **kwargs)):
            if count == 3:
                if stop == "ctrl-c":
                    raise KeyboardInterrupt
                os.kill(os.getpid(), signal.SIGTERM)
            yield fitted

    monkeypatch.setattr(pts, "track", interrupted)
    assert vicon_arm("--out", str(tmp_path), "--frames", "10", "--quiet") == (130 if stop == "ctrl-c" else 143)
    printed = capsys.readouterr()
    assert "interrupted after 3 frames" in printed.out
    assert printed.err.splitlines()[-1] == "tracker: interrupted: the frames done so far are saved"
    poses, shapes = load_poses(tmp_path / "poses.npz"), np.load(tmp_path / "shapes.npz")
    assert list(poses["frame"]) == list(shapes["frame"]) == [0, 1, 2]


def test_points_command_errors_are_one_line(tmp_path: Path, capsys) -> None:
    model = tmp_path / "arm.toml"
    model.write_text("[[part]]\nname = 'a'\nmarkers = ['NOSUCH', 'STER', 'XIPH']\n")
    assert main(["points", str(MARKERS / "Vicon.c3d"), "--model", str(model), "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "Vicon.c3d" in error[0] and "'NOSUCH'" in error[0]
    assert main(["points", str(tmp_path / "none.c3d"), "--model", str(VICON_ARM)]) == 2
    assert "marker file not found" in capsys.readouterr().err
    assert vicon_arm("--start", "9999") == 2
    assert "--start 9999 is outside the marker file's frames 0..159" in capsys.readouterr().err
    assert main(["experiment", "insect", "--densities", "50"]) == 2
    assert "the insect has neither" in capsys.readouterr().err


def test_fit_option_and_its_old_name(tmp_path: Path, capsys) -> None:
    """--fit second-order fits with mass and momentum; the old spelling --dynamics (the motion prior's
    name in track) gives the same poses, with a warning that names --fit."""
    common = ["--frames", "5", "--quiet"]
    assert vicon_arm(*common, "--fit", "second-order", "--out", str(tmp_path / "new")) == 0
    assert "is now" not in capsys.readouterr().err
    assert vicon_arm(*common, "--dynamics", "second-order", "--out", str(tmp_path / "old")) == 0
    assert "--dynamics is now --fit" in capsys.readouterr().err
    new, old = (load_poses(tmp_path / name / "poses.npz") for name in ("new", "old"))
    np.testing.assert_array_equal(new["poses"], old["poses"])
    first = load_poses(tmp_path / "new" / "poses.npz")
    assert vicon_arm(*common, "--out", str(tmp_path / "first")) == 0
    assert not np.array_equal(load_poses(tmp_path / "first" / "poses.npz")["poses"], first["poses"])
