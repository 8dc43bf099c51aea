"""The automatic first pose (issue 16): landmarks triangulated across views that may read a pair swapped or
follow someone else, the model fitted to them, snapped to the edges; its errors; the anchors it rests on."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest

from tracker.chain import FREE, SLIDE
from tracker.cli import main
from tracker.commands.init import keypoint_pose
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.poses import load_poses
from tracker.io.recording import open_recording
from tracker.landmarks import detector
from tracker.landmarks.anchors import anchors, reach, rigid_distances
from tracker.landmarks.body_landmarks import LANDMARKS, left_right_pairs
from tracker.landmarks.detect_recording import detect_recording
from tracker.landmarks.store import Keypoints
from tracker.landmarks.triangulation import triangulated
from tracker.model import joint_centres, load_model, model_from_dict, rest_poses
from tracker.seeding import pose_fit
from tracker.seeding.first_pose import agreeing_views, first_pose, placed_in_depth
from tracker.seeding.pose_fit import Body, fit_pose, fit_to_views
from tracker.viewer.placement import in_view

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "recordings" / "demo"
PAIRS = left_right_pairs(LANDMARKS)


@pytest.fixture(scope="module")
def demo():
    recording = open_recording(DEMO)
    return recording, load_model(recording.model_path), load_poses(DEMO / "truth.npz")


def landmark_world(model, poses: np.ndarray) -> np.ndarray:
    """World points (33, 3) of the landmarks' model points at ``poses`` (NaN where the model has none)."""
    component, anchor = anchors(model)
    out = np.full((len(LANDMARKS), 3), np.nan)
    for j in np.flatnonzero(component >= 0):
        out[j] = poses[component[j], :3, :3] @ anchor[j] + poses[component[j], :3, 3]
    return out


def perfect(recording, model, truth, frames: int = 5, cameras=None) -> Keypoints:
    """Detections that are the exact images of the true landmark points, frames 0..frames-1, in every camera of
    the recording (or of ``cameras``)."""
    cameras = recording.cameras if cameras is None else cameras
    pixels = np.full((frames, len(cameras), len(LANDMARKS), 2), np.nan)
    for f in range(frames):
        points = landmark_world(model, truth["poses"][f])
        known = np.isfinite(points).all(axis=1)
        for k, camera in enumerate(cameras):
            pixels[f, k, known] = camera.project(points[known])
    confidence = np.isfinite(pixels).all(axis=3).astype(float)
    names = tuple(camera.name for camera in cameras)
    return Keypoints(np.arange(frames), names, pixels, confidence, np.full((*pixels.shape[:3], 3), np.nan))


def mean_error(poses: np.ndarray, truth: np.ndarray) -> float:
    """Mean joint-centre distance (metres) between two sets of poses."""
    return float(np.linalg.norm(joint_centres(poses) - joint_centres(truth), axis=1).mean())


def test_anchors_and_rigid_distances_of_the_human_model():
    """Worked by hand from models/human.toml: the shoulders sit 0.4 m apart on the torso, an elbow 0.29 m from
    its shoulder, the hips 0.18 m apart; a wrist can get no farther than 0.29 + 0.25 m from its shoulder; a
    shoulder and a knee share no component (NaN) but a chain joins them; the nose is the front of the head's
    ellipsoid (centre (0, -0.01, 0.14), radii (0.085, 0.1, 0.115))."""
    model = load_model(ROOT / "models" / "human.toml")
    component, anchor = anchors(model)
    distances, farthest = rigid_distances(model), reach(model)
    index = LANDMARKS.index
    assert distances[index("left_shoulder"), index("right_shoulder")] == pytest.approx(0.4)
    assert distances[index("left_shoulder"), index("left_elbow")] == pytest.approx(0.29)
    assert distances[index("left_hip"), index("right_hip")] == pytest.approx(0.18)
    assert np.isnan(distances[index("left_shoulder"), index("left_knee")])
    assert farthest[index("left_shoulder"), index("left_wrist")] == pytest.approx(0.54)
    assert np.isfinite(farthest[index("left_shoulder"), index("left_knee")])
    assert model.names[component[index("nose")]] == "head"
    np.testing.assert_allclose(anchor[index("nose")], [0.0, -0.11, 0.14])
    pose2sim = load_model(ROOT / "models" / "pose2sim_man.toml")
    assert (anchors(pose2sim)[0] >= 0).sum() == (component >= 0).sum() == 23


@pytest.mark.parametrize("name", ["human", "pose2sim_man"])
def test_joint_space_round_trip(name):
    """parameters_of inverts posed: random joint parameters within limits, posed, read back."""
    model = load_model(ROOT / "models" / f"{name}.toml")
    body = Body.of(model)
    rng = np.random.default_rng(3)
    parameters = np.clip(rng.normal(0.0, 0.4, body.offsets[-1]), body.lower, body.upper)
    root = np.eye(4)
    root[:3, 3] = [0.3, -0.2, 0.9]
    poses = body.posed(root, parameters)
    np.testing.assert_allclose(body.parameters_of(root, poses), parameters, atol=1e-9)
    np.testing.assert_allclose(model.coerce(poses), poses, atol=1e-9)


def _every_joint_kind():
    """models/human.toml with the head on a free joint and the left forearm on a slide: every kind of joint."""
    data = tomllib.loads((ROOT / "models" / "human.toml").read_text())
    for component in data["component"]:
        if component["name"] == "head":
            component["joint"] = "free"
            component.pop("max_angle", None)
        if component["name"] == "forearm_l":
            component["joint"], component["limits"] = "slide", [-0.1, 0.2]
    model = model_from_dict(data)
    assert {FREE, SLIDE} <= set(model.joint_type[1:].tolist())
    return model


@pytest.mark.parametrize("model", [load_model(ROOT / "models" / "pose2sim_man.toml"), _every_joint_kind()])
def test_fit_jacobians_match_finite_differences(model):
    """The landmarks' and the penalties' analytic Jacobians (Body.landmark_jacobian, penalty_jacobian) against
    central differences of posed, at random parameters with balls turned and twisted past their limits."""
    body = Body.of(model)
    rng = np.random.default_rng(5)
    parameters = np.clip(rng.normal(0.0, 1.0, body.offsets[-1]), body.lower, body.upper)
    for i, limit in zip(body.twisted, body.twist_limits):  # each twisted beyond its limit
        parameters[body.offsets[i] : body.offsets[i] + 3] = [0.2, -0.3, limit + 0.5]
    root = se3.from_rotvec([0.2, -0.4, 1.1], [0.3, -0.2, 0.9])
    landmarks = body.landmark_jacobian(parameters, body.posed(root, parameters))
    penalties = body.penalty_jacobian(parameters)
    limits = penalties[len(parameters) - 6 :]
    assert (np.abs(limits[: len(body.balls)]).sum(axis=1) > 0).any()  # some ball beyond its limit
    if len(body.twisted):
        assert (np.abs(limits[len(body.balls) :]).sum(axis=1) > 0).any()  # and some twisted beyond its own
    h = 1e-6
    for q in range(len(parameters)):
        step = np.eye(len(parameters))[q] * h
        ahead, back = body.posed(root, parameters + step), body.posed(root, parameters - step)
        difference = (body.landmark_points(ahead) - body.landmark_points(back)) / (2 * h)
        np.testing.assert_allclose(landmarks[:, :, q], np.nan_to_num(difference), atol=1e-7)
        difference = (body.penalties(parameters + step) - body.penalties(parameters - step)) / (2 * h)
        np.testing.assert_allclose(penalties[:, q], difference, atol=1e-7)


def test_perfect_keypoints_give_the_true_joint_centres(demo):
    """The exact images of the true landmark points in the demo's three cameras: triangulated, they are the
    true points; the model fitted to them, and then to the pixels, has the true joint centres."""
    recording, model, truth = demo
    keypoints = perfect(recording, model, truth)
    found = triangulated(keypoints, recording.cameras, model, frames=1)
    true_points = landmark_world(model, truth["poses"][0])
    known = np.isfinite(true_points).all(axis=1)
    np.testing.assert_allclose(found.points[known], true_points[known], atol=1e-6)
    assert (found.views[known] == 3).all() and found.agree[0][:, known].all()
    fitted = fit_pose(model, found.points)
    assert mean_error(fitted, truth["poses"][0]) < 0.001
    refined = fit_to_views(
        model, fitted, recording.cameras, pixels=keypoints.pixels[:1], confidence=keypoints.confidence[:1]
    )
    assert mean_error(refined, truth["poses"][0]) < 0.001


def test_first_pose_from_perfect_keypoints(demo):
    """End to end on the demo's frames 0-4: points triangulated over five frames of a moving body, fitted,
    refined and snapped to frame 0's edges: within a few millimetres of the true first pose."""
    recording, model, truth = demo
    poses = first_pose(recording, model, perfect(recording, model, truth))
    assert mean_error(poses, truth["poses"][0]) < 0.005


def turned_about_the_body(camera, centre: np.ndarray, angle: float):
    """``camera`` carried round the vertical line through ``centre`` by ``angle`` (radians), still facing it."""
    turn = se3.exp_so3(np.array([0.0, 0.0, angle]))
    world_from_turned = se3.from_rotation(turn, centre - turn @ centre)
    return camera.with_camera_from_world(camera.camera_from_world @ np.linalg.inv(world_from_turned))


@pytest.mark.parametrize(
    "degrees, placed", [(180, False), (165, False), (10, False), (90, True), (120, True), (45, True)]
)
def test_two_views_that_face_each_other_or_stand_together_do_not_place_the_body(demo, degrees, placed):
    """cam0 and a copy of it carried round the body: facing it (180 or 165 degrees) or beside it (10) they leave
    the body free along their common line of sight, and the first pose waits for views that place it in depth
    (30 to 150 degrees apart); perfect detections either way."""
    recording, model, truth = demo
    centre = truth["poses"][0][0, :3, 3]
    cameras = [recording.cameras[0], turned_about_the_body(recording.cameras[0], centre, np.radians(degrees))]
    keypoints = perfect(recording, model, truth, cameras=cameras)
    found = triangulated(keypoints, cameras, model, frames=5)
    assert placed_in_depth(found, cameras, agreeing_views(found)) == placed
    if not placed:
        with pytest.raises(TrackerInputError, match="face each other or stand together"):
            first_pose(dataclasses.replace(recording, cameras=cameras), model, keypoints)


def test_a_view_that_reads_left_and_right_swapped(demo):
    """cam0 reads every left/right pair the other way round: the views still agree (cam0 read swapped) and the
    fit finds the true pose."""
    recording, model, truth = demo
    keypoints = perfect(recording, model, truth, frames=1)
    keypoints.pixels[:, 0, PAIRS] = keypoints.pixels[:, 0, PAIRS[:, ::-1]].copy()
    found = triangulated(keypoints, recording.cameras, model, frames=1)
    assert (found.views[anchors(model)[0] >= 0] == 3).all()
    assert mean_error(fit_pose(model, found.points), truth["poses"][0]) < 0.001


def test_every_view_swapped_is_a_person_seen_from_behind(demo):
    """All three views swap left and right (the detector takes the back for the front): the points come out
    mirrored, and the fit tells the facing from the knees and elbows, which bend one way."""
    recording, model, truth = demo
    mirrored = landmark_world(model, truth["poses"][0])
    mirrored[PAIRS] = mirrored[PAIRS[:, ::-1]].copy()
    assert mean_error(fit_pose(model, mirrored), truth["poses"][0]) < 0.001


def test_a_view_following_someone_else_is_dropped(demo):
    """cam1's detector follows another person (the body of frame 100, a metre away): none of its detections
    agrees with the other views, and the pose comes from cam0 and cam2."""
    recording, model, truth = demo
    keypoints = perfect(recording, model, truth, frames=1)
    elsewhere = landmark_world(model, truth["poses"][100]) + np.array([1.0, 0.5, 0.0])
    known = np.isfinite(elsewhere).all(axis=1)
    keypoints.pixels[0, 1, known] = recording.cameras[1].project(elsewhere[known])
    found = triangulated(keypoints, recording.cameras, model, frames=1)
    assert not found.agree[0, 1].any() and found.agree[0][[0, 2]][:, known].all()
    assert mean_error(fit_pose(model, found.points), truth["poses"][0]) < 0.001


def test_a_model_of_other_lengths_lands_at_the_least_misfit(demo):
    """The person 10 % larger than the model (the true points scaled about the hips): the fit stays a pose of
    the model within its joint limits, near the true one, and misfits the points less than the true pose."""
    recording, model, truth = demo
    true_points = landmark_world(model, truth["poses"][0])
    hips = true_points[[LANDMARKS.index("left_hip"), LANDMARKS.index("right_hip")]].mean(axis=0)
    larger = hips + 1.1 * (true_points - hips)
    fitted = fit_pose(model, larger)
    np.testing.assert_allclose(model.coerce(fitted), fitted, atol=1e-9)

    def misfit(poses):
        return float(np.nanmean(np.linalg.norm(landmark_world(model, poses) - larger, axis=1)))

    assert misfit(fitted) < misfit(truth["poses"][0])
    assert mean_error(fitted, truth["poses"][0]) < 0.06


@pytest.mark.parametrize("frame", [0, 40, 80])
def test_hips_read_high_do_not_fold_the_trunk(demo, monkeypatch, frame):
    """The true points with both hips 12 cm higher (a table hides them, the detector draws them up): the fit keeps
    the torso's joint within 25 degrees of rest (the truth's 13-18) and every joint within 2 cm on average; with
    only the torso's largest rotation (75 degrees), the trunk folds past 40 degrees to bring the hips up."""
    recording, model, truth = demo
    points = landmark_world(model, truth["poses"][frame])
    points[[LANDMARKS.index("left_hip"), LANDMARKS.index("right_hip")], 2] += 0.12
    torso = model.index("torso")

    def bend(poses: np.ndarray) -> float:
        return float(np.degrees(np.linalg.norm(se3.log_so3(poses[0, :3, :3].T @ poses[torso, :3, :3]))))

    fitted = fit_pose(model, points)
    assert bend(fitted) < 25.0 and mean_error(fitted, truth["poses"][frame]) < 0.02
    monkeypatch.setattr(pose_fit, "TRUNK_TURN", np.inf)
    assert bend(fit_pose(model, points)) > 40.0


def test_one_camera_is_an_error(demo, one_line_error):
    recording, model, truth = demo
    single = open_recording(DEMO, ["cam0"])
    keypoints = perfect(single, model, truth, frames=2)
    message = one_line_error(lambda: first_pose(single, model, keypoints))
    assert "two cameras or more" in message and "--init" in message


def test_no_person_is_a_one_line_error(demo, one_line_error):
    recording, model, truth = demo
    keypoints = perfect(recording, model, truth)
    keypoints.confidence[:] = 0.0
    message = one_line_error(lambda: first_pose(recording, model, keypoints))
    assert "frames 0..4" in message and str(DEMO) in message and "--start" in message


def test_no_hips_is_a_one_line_error(demo, one_line_error):
    """The detector sees the person but never the hips, which place the body."""
    recording, model, truth = demo
    keypoints = perfect(recording, model, truth)
    keypoints.confidence[..., [LANDMARKS.index("left_hip"), LANDMARKS.index("right_hip")]] = 0.0
    message = one_line_error(lambda: first_pose(recording, model, keypoints))
    assert "frames 0..4" in message and "both hips" in message and "--init" in message


def test_tracker_init_starts_from_the_fit_to_the_detector(demo, tmp_path, monkeypatch, capsys):
    """``tracker init`` without an init file: the detector's landmarks in the demo's frames 0-4 (cam1 follows a
    basketball player in the background photo, cam0 reads the shoulders and wrists swapped in frame 0),
    cached in out/demo/keypoints-full.npz (the full model's file); the snapped pose is within a centimetre of the true
    first pose (measured: docs/keypoints.md, "Automatic first pose").  The cache serves any frames it holds."""
    recording, model, truth = demo
    monkeypatch.chdir(tmp_path)
    poses = keypoint_pose(recording, model, 0, landmark_model="full")
    assert mean_error(poses, truth["poses"][0]) < 0.01
    assert "frames 0..4" in capsys.readouterr().out
    some, detected = detect_recording(
        recording, 1, 3, cache=tmp_path / "out" / "demo" / "keypoints-full.npz", landmark_model="full"
    )
    assert detected == 0 and list(some.frame) == [1, 2]


def test_tracker_init_without_the_detector_starts_at_rest(demo, monkeypatch, capsys):
    """Without the detector's package ``tracker init`` starts from the rest pose where the cameras look, and
    says why."""
    recording, model, truth = demo
    monkeypatch.setattr(detector, "missing", lambda: "the keypoint detector is not installed (test)")
    poses = keypoint_pose(recording, model, 0, landmark_model="full")
    np.testing.assert_allclose(poses, rest_poses(model, in_view(recording.cameras)))
    assert "not installed (test)" in capsys.readouterr().out


def test_tracker_init_start_outside_the_recording_is_a_one_line_error(tmp_path, capsys):
    assert main(["init", str(DEMO), "--out", str(tmp_path / "init.toml"), "--start", "500"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--start 500 is outside its frames 0..159" in lines[0]
