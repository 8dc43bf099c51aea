"""MPJPE, PA-MPJPE, PCK and lost frames on hand-made poses and truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracker.errors import TrackerInputError
from tracker.evaluate import evaluate, format_report

NAMES = ["pelvis", "knee_l", "knee_r", "head", "hand_l"]


def truth(frames: int = 10, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"joint_names": np.array(NAMES), "joints": rng.normal(scale=0.5, size=(frames, len(NAMES), 3))}


def tracked(joints: np.ndarray, names: list[str] = NAMES) -> dict[str, np.ndarray]:
    frames = len(joints)
    return {
        "frame": np.arange(frames),
        "joint_names": np.array(names),
        "joints": joints,
        "status": np.zeros(frames, np.int8),
    }


def test_known_offsets_give_known_errors() -> None:
    true = truth()
    offsets = np.array([0.01, 0.03, 0.07, 0.03, 0.01])  # metres, along x, per joint
    moved = true["joints"].copy()
    moved[..., 0] += offsets
    report = evaluate(tracked(moved), true)
    assert report.mpjpe_mm == pytest.approx(1000 * offsets.mean())
    assert report.pck == pytest.approx(4 / 5)
    assert (report.lost_frames, report.frames) == (0, 10)
    for name, offset in zip(NAMES, offsets):
        assert report.per_joint[name][0] == pytest.approx(1000 * offset)
        assert report.per_joint[name][1] == (1.0 if offset < 0.05 else 0.0)
    assert evaluate(tracked(moved), true, pck_threshold=0.1).pck == 1.0


def test_pa_mpjpe_of_a_similar_copy_is_zero() -> None:
    true = truth()
    rotation = cv2.Rodrigues(np.array([0.3, -0.5, 1.2]))[0]
    moved = 1.3 * true["joints"] @ rotation.T + np.array([1.0, -2.0, 0.5])
    report = evaluate(tracked(moved), true)
    assert report.pa_mpjpe_mm < 1e-9
    assert report.mpjpe_mm > 100


def test_pa_mpjpe_never_exceeds_mpjpe() -> None:
    true = truth()
    noisy = true["joints"] + np.random.default_rng(3).normal(scale=0.02, size=true["joints"].shape)
    report = evaluate(tracked(noisy), true)
    assert 0 < report.pa_mpjpe_mm < report.mpjpe_mm


def test_lost_frames_count_as_failures() -> None:
    true = truth()
    true["frame"] = np.arange(100, 110)
    moved = true["joints"].copy()
    moved[..., 2] += 0.02
    poses = tracked(moved)
    poses["frame"] = np.arange(100, 110)
    poses["status"][1] = 2  # lost by status
    poses["joints"][2, 3] = np.nan  # lost by a NaN joint
    keep = np.arange(10) != 3  # frame 103 missing from the poses
    poses = {key: value[keep] if key != "joint_names" else value for key, value in poses.items()}
    report = evaluate(poses, true)
    assert (report.lost_frames, report.frames) == (3, 10)
    assert report.mpjpe_mm == pytest.approx(20.0)
    assert report.pck == pytest.approx(7 / 10)


def test_truth_subset_matched_by_name() -> None:
    full = truth()
    subset = {"joint_names": np.array(["head", "knee_l"]), "joints": full["joints"][:, [3, 1]]}
    report = evaluate(tracked(full["joints"]), subset)
    assert list(report.per_joint) == ["head", "knee_l"]
    assert report.mpjpe_mm == pytest.approx(0.0) and report.pck == 1.0


def test_no_common_joint_is_an_input_error() -> None:
    with pytest.raises(TrackerInputError, match="no joint name"):
        evaluate(tracked(truth()["joints"], names=list("abcde")), truth())


def test_format_report_lists_every_joint() -> None:
    text = format_report(evaluate(tracked(truth()["joints"]), truth()))
    assert "MPJPE" in text and "PA-MPJPE" in text and "PCK@50mm" in text
    for name in NAMES:
        assert name in text


def test_unknown_truth_joints_are_left_out_of_every_mean() -> None:
    """NaN truth joints (no camera saw them) are not scored: whatever is tracked there changes nothing."""
    true = truth()
    unseen = np.zeros(true["joints"].shape[:2], dtype=bool)
    unseen[:, 1] = True  # knee_l never seen
    unseen[4:, 2] = True  # knee_r unseen from frame 4 on
    unseen[7] = True  # frame 7: nothing seen
    tracked_joints = true["joints"].copy()
    tracked_joints[..., 0] += 0.02
    hidden = dict(true, joints=np.where(unseen[..., None], np.nan, true["joints"]))
    wild = tracked_joints.copy()
    wild[unseen] += 5.0  # far off where the truth is unknown
    report = evaluate(tracked(wild), hidden)
    assert report.mpjpe_mm == pytest.approx(20.0)
    assert report.pa_mpjpe_mm < 1e-9  # a pure shift of the joints scored
    assert report.pck == pytest.approx(1.0)
    assert (report.lost_frames, report.frames) == (0, 10)
    assert np.isnan(report.per_joint["knee_l"][0]) and np.isnan(report.per_joint["knee_l"][1])
    assert report.per_joint["knee_r"][0] == pytest.approx(20.0)
    wild[..., 0] += 0.05  # now 70 mm off everywhere: PCK counts the known joint-frames only
    assert evaluate(tracked(wild), hidden).pck == 0.0
