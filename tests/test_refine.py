"""Rig refinement from a tracked body: the camera Jacobian's adjoint, and a disturbed camera recovered."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tracker.apps.bench import HUMAN
from tracker.calibrate.refine import camera_rows, refine_rig
from tracker.camera import load_calibration, save_calibration
from tracker.cli import main
from tracker.geometry import se3
from tracker.io.poses import load_poses
from tracker.io.readers import FrameSeeker
from tracker.io.recording import open_recording
from tracker.model import joint_centres, load_model
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings


def test_camera_rows_move_the_body_as_the_camera_moves():
    """exp(xi) T = T exp(J xi) with J = camera_rows(I, ...) and T = P_k E_i: the camera's twist as a body twist."""
    rng = np.random.default_rng(4)
    rig_pose = np.array([se3.exp(rng.normal(0.0, 0.8, 6)) for _ in range(3)])
    poses = np.array([se3.exp(rng.normal(0.0, 0.8, 6)) for _ in range(4)])
    for _ in range(20):
        k, i = rng.integers(3), rng.integers(4)
        xi = rng.normal(0.0, 0.3, 6)
        rows = camera_rows(np.eye(6), np.full(6, k), np.full(6, i), rig_pose=rig_pose, poses=poses)
        transform = rig_pose[k] @ poses[i]
        np.testing.assert_allclose(transform @ se3.exp(rows @ xi), se3.exp(xi) @ transform, atol=1e-12)


def disturbed(camera, degrees: float, metres: float, seed: int):
    rng = np.random.default_rng(seed)
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    turn = se3.exp_so3(np.radians(degrees) * axis / np.linalg.norm(axis))
    centre = camera.center + metres * direction / np.linalg.norm(direction)
    rotation = turn @ camera.rotation
    return replace(camera, rotation=rotation, translation=-rotation @ centre)


def test_refine_rig_recovers_a_disturbed_camera(tiny_recording):
    recording = open_recording(tiny_recording)
    model = load_model(HUMAN)
    truth = load_poses(tiny_recording / "truth.npz")["poses"]
    true_rig = recording.cameras
    rig = [true_rig[0], disturbed(true_rig[1], 1.5, 0.04, seed=2)]
    smooth = Tracker(model, rig, truth[0]).smooth
    seekers = [FrameSeeker(source) for source in recording.sources]
    frames = [[smooth(seeker.read(index)) for seeker in seekers] for index in range(len(truth))]
    refined = refine_rig(model, rig, truth, frames=frames, settings=Settings(), fixed=[0], refit=False)
    fixed, moved = refined.cameras
    assert fixed == rig[0] and refined.rotation_deg[0] == 0.0 and refined.shift_m[0] == 0.0
    joints = np.concatenate([joint_centres(pose) for pose in truth])

    def offset(camera) -> float:
        """Mean pixel distance between the joints' images through ``camera`` and through the true camera."""
        return float(np.linalg.norm(camera.project(joints) - true_rig[1].project(joints), axis=1).mean())

    assert offset(rig[1]) > 5.0 and offset(moved) < 1.0  # measured 8.1 -> 0.44 px
    # a body in one place barely separates a sideways shift from a turn: the pose itself comes closer
    turn = np.degrees(np.linalg.norm(se3.log_so3(moved.rotation @ true_rig[1].rotation.T)))
    assert turn < 1.0 and np.linalg.norm(moved.center - true_rig[1].center) < 0.04  # 0.51 deg, 22 mm
    assert refined.residual_after[1] < 0.5 * refined.residual_before[1]  # 1.94 -> 0.40 px
    np.testing.assert_allclose(refined.rotation_deg[1], 1.5, atol=1.0)
    # refitting the bodies too: both views fit again (two views let the body and cam1 trade a little)
    refitted = refine_rig(model, rig, truth, frames=frames, settings=Settings(), rounds=2, fixed=[0])
    assert refitted.residual_after.max() < 0.5 * refined.residual_before[1]  # 1.94 -> 0.53 px measured
    assert offset(refitted.cameras[1]) < 0.8 * offset(rig[1])


def test_refine_command_writes_a_calibration_that_track_takes(tiny_recording, tmp_path, capsys):
    recording = open_recording(tiny_recording)
    true_rig = load_calibration(tiny_recording / "calibration.toml")
    disturbed_rig = tmp_path / "disturbed.toml"
    save_calibration([true_rig[0], disturbed(true_rig[1], 1.5, 0.04, seed=2)], disturbed_rig)
    refined_rig = tmp_path / "refined.toml"
    assert (
        main(
            [
                "refine",
                str(tiny_recording),
                "--model",
                str(HUMAN),
                "--poses",
                str(tiny_recording / "truth.npz"),
                "--calib",
                str(disturbed_rig),
                "--fix",
                "cam0",
                "--hold-poses",
                "--out",
                str(refined_rig),
                "--quiet",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "cam0: turned 0.00 deg, moved 0 mm" in printed and "(fixed)" in printed
    truth = load_poses(tiny_recording / "truth.npz")["joints"].reshape(-1, 3)
    moved = load_calibration(refined_rig)[1]
    assert np.linalg.norm(moved.project(truth) - true_rig[1].project(truth), axis=1).mean() < 1.0
    np.testing.assert_array_equal(
        open_recording(tiny_recording, calibration=refined_rig).cameras[1].rotation, moved.rotation
    )
    assert recording.calibration_path == tiny_recording / "calibration.toml"
    assert (
        main(["track", str(tiny_recording), "--calib", str(refined_rig), "--out", str(tmp_path / "run"), "--quiet"])
        == 0
    )


def test_refine_command_errors(tiny_recording, tmp_path, capsys):
    def error(*argv: str) -> str:
        assert (
            main(["refine", str(tiny_recording), "--model", str(HUMAN), "--out", str(tmp_path / "r.toml"), *argv]) == 2
        )
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1
        return lines[0]

    truth = str(tiny_recording / "truth.npz")
    assert "--fix names cam9" in error("--poses", truth, "--fix", "cam9")
    assert "no frame in 100..105" in error("--poses", truth, "--start", "100", "--frames", "6")
    assert "nowhere.toml" in error("--poses", truth, "--calib", str(tmp_path / "nowhere.toml"))
    assert not (tmp_path / "r.toml").exists()
    message = error("--poses", truth, "--out", str(tiny_recording / "calibration.toml"))
    assert "is the calibration being refined" in message
