"""Legs the detector guessed behind a table: bones that triangulate under half their length, on the demo's rig
and true pose, and what the tracker does with them."""

from pathlib import Path

import numpy as np
import pytest

from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.landmarks.body_landmarks import LANDMARKS, cue_points, landmark_world
from tracker.landmarks.guessed import BONES, SHORT, axis_points, bone_lengths, guessed, hidden_parts, leg_landmarks
from tracker.model import load_model
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"
LEGS = ("knee", "ankle", "heel", "foot_index")


@pytest.fixture(scope="module")
def demo():
    """The demo's cameras, model, first images and true first pose, and its landmarks' world points there."""
    rec = open_recording(DEMO)
    model = load_model(rec.model_path)
    poses = load_poses(DEMO / "truth.npz")["poses"][0]
    images = next(iter(frames(rec, 0, 1)))[1]
    return rec.cameras, model, images, poses, landmark_world(poses, *cue_points(model))


def _index(side: str, names) -> list[int]:
    return [LANDMARKS.index(f"{side}_{name}") for name in names]


def _folded(world: np.ndarray, side: str, thigh: float, shin: float) -> np.ndarray:
    """``world`` with one leg drawn as the detector guesses it behind a table: the knee ``thigh`` of the way from
    the hip to its true place, and the ankle, heel and toes moved with it, their offsets from the knee scaled by
    ``shin``."""
    out = world.copy()
    hip, knee = _index(side, ("hip",))[0], _index(side, ("knee",))[0]
    out[knee] = world[hip] + thigh * (world[knee] - world[hip])
    for j in _index(side, LEGS[1:]):
        out[j] = out[knee] + shin * (world[j] - world[knee])
    return out


def test_true_legs_are_not_guessed_and_legs_folded_behind_a_table_are(demo, perfect_detections):
    cameras, model, _, poses, world = demo
    lengths = bone_lengths(poses, *cue_points(model))
    np.testing.assert_allclose(
        lengths, [np.linalg.norm(world[upper] - world[lower]) for upper, lower in BONES], rtol=1e-12
    )
    assert not guessed(cameras, *perfect_detections(cameras, world), lengths=lengths).any()
    above = 1.2 * SHORT  # the bones a fifth longer than the rule's limit
    assert not guessed(
        cameras, *perfect_detections(cameras, _folded(world, "left", above, above)), lengths=lengths
    ).any()

    both = _folded(_folded(world, "left", 0.4, 0.4), "right", 0.4, 0.4)  # as table-booth's: under half
    assert set(np.flatnonzero(guessed(cameras, *perfect_detections(cameras, both), lengths=lengths))) == set(
        _index("left", LEGS) + _index("right", LEGS)
    )
    shin_only = _folded(world, "right", 1.0, 0.3)
    assert set(np.flatnonzero(guessed(cameras, *perfect_detections(cameras, shin_only), lengths=lengths))) == set(
        _index("right", LEGS[1:])
    )
    one_view = perfect_detections(cameras, both, seen_by=1)  # nothing to triangulate
    assert not guessed(cameras, *one_view, lengths=lengths).any()


def test_a_guessed_knee_hides_the_leg_below_the_hip_and_a_guessed_ankle_the_shin_down(demo):
    _, model, _, _, _ = demo
    component = cue_points(model)[0]
    knee, ankle = np.zeros(len(LANDMARKS), bool), np.zeros(len(LANDMARKS), bool)
    knee[_index("left", LEGS)] = True
    ankle[_index("right", LEGS[1:])] = True
    names = np.array(model.names)
    assert set(names[hidden_parts(model, component, knee)]) == {"thigh_l", "shin_l", "foot_l"}
    assert set(names[hidden_parts(model, component, ankle)]) == {"shin_r", "foot_r"}
    assert not hidden_parts(model, component, np.zeros(len(LANDMARKS), bool)).any()


def test_the_tracker_gives_guessed_legs_no_landmark_edge_or_colour_weight(demo, perfect_detections):
    """A frame whose legs' landmarks are folded as behind a table: the legs' parts are hidden in that frame (their
    samples search nothing and read no colours) and their landmarks are dropped; the true landmarks, or the rule
    off, hide nothing."""
    cameras, model, images, poses, world = demo
    folded = perfect_detections(cameras, _folded(_folded(world, "left", 0.4, 0.4), "right", 0.4, 0.4))
    names = np.array(model.names)

    tracker = Tracker(model, cameras, poses)
    tracker.step(images, keypoints=folded)
    assert set(names[tracker.hidden]) == {"thigh_l", "shin_l", "foot_l", "thigh_r", "shin_r", "foot_r"}
    assert tracker.landmarks.frame is not None
    assert not tracker.landmarks.frame[1][:, _index("left", LEGS) + _index("right", LEGS)].any()
    assert (tracker.landmarks.frame[1][:, _index("left", ("hip", "shoulder", "wrist"))] == 1.0).all()
    work = tracker.work
    legs = tracker.hidden[work.samples.component[: work.samples.count]]
    assert legs.any() and (~legs).any()
    assert (work.lo[legs] > work.hi[legs]).all() and (work.outside[legs] == -2).all()
    assert (work.lo[~legs] <= work.hi[~legs]).all()

    for keypoints, settings in (
        (perfect_detections(cameras, world), Settings()),
        (folded, Settings().but(keypoints=dict(hide_guessed=False))),
    ):
        tracker = Tracker(model, cameras, poses, settings)
        tracker.step(images, keypoints=keypoints)
        assert not tracker.hidden.any()
        assert tracker.landmarks.frame is not None and (tracker.landmarks.frame[1] == keypoints[1]).all()


def test_a_leg_whose_knee_the_detector_is_unsure_of_is_not_judged(demo, perfect_detections):
    """The rule triangulates only the confident detections (those the check across the views uses): with the
    left knee below that confidence, neither of the left leg's bones is known, and only the right leg, folded
    too, is guessed."""
    cameras, model, _, poses, world = demo
    pixels, confidence = perfect_detections(cameras, _folded(_folded(world, "left", 0.4, 0.4), "right", 0.4, 0.4))
    confidence[:, _index("left", ("knee",))] = 0.4
    lengths = bone_lengths(poses, *cue_points(model))
    assert set(np.flatnonzero(guessed(cameras, pixels, confidence, lengths=lengths))) == set(_index("right", LEGS))


def test_every_landmark_below_a_hip_hides_both_legs_and_nothing_else(demo):
    _, model, _, _, _ = demo
    chosen = leg_landmarks()
    assert {LANDMARKS[j] for j in np.flatnonzero(chosen)} == {
        f"{side}_{name}" for side in ("left", "right") for name in LEGS
    }
    names = np.array(model.names)
    legs = {f"{part}_{side}" for part in ("thigh", "shin", "foot") for side in "lr"}
    assert set(names[hidden_parts(model, cue_points(model)[0], chosen)]) == legs


def test_axis_points_run_along_each_quadric(demo):
    """A cone's ends and middle; an ellipsoid's centre and 0.6 of its longest semi-axis either way along it."""
    _, model, _, _, _ = demo
    component, points = axis_points(model)
    assert len(component) == 3 * len(model.quadric_params)
    for q, spec in enumerate(model.quadric_params):
        assert (component[3 * q : 3 * q + 3] == model.quadric_component[q]).all()
        three = points[3 * q : 3 * q + 3]
        if spec["shape"] == "cone":
            np.testing.assert_allclose(three[[0, 2]], [spec["from"], spec["to"]])
            np.testing.assert_allclose(three[1], 0.5 * (three[0] + three[2]))
        else:
            radii = np.asarray(spec["radii"])
            np.testing.assert_allclose(three[1], spec.get("center", (0.0, 0.0, 0.0)))
            np.testing.assert_allclose(three[2] - three[1], 0.6 * radii.max() * np.eye(3)[np.argmax(radii)])
            np.testing.assert_allclose(three[0] + three[2], 2.0 * three[1])
