"""tracker export: TRC, C3D, BVH and CSV written from poses.npz, read back by our readers and by independent ones."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import c3d
import ezc3d
import numpy as np
import pandas
import pytest
from conftest import SHARED_DATA, TEST_DATA, needs_shared
from scipy.spatial.transform import Rotation

from tracker.cli import build_parser
from tracker.commands.export import run
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.bvh_clip import bvh_global, load_bvh
from tracker.io.export import export
from tracker.io.export.bvh import Z_UP_TO_Y_UP, depth_first, euler_zxy, hold_lost, motion, write_bvh
from tracker.io.export.trc import read_trc, write_trc
from tracker.io.poses import PosesWriter
from tracker.model import load_model, model_from_dict, rest_poses

with warnings.catch_warnings():
    warnings.simplefilter("ignore", PendingDeprecationWarning)  # bvhio imports PyGLM by its old name
    import bvhio

ROOT = Path(__file__).resolve().parents[2]
HUMAN = ROOT / "models" / "human.toml"
TRUTH = ROOT / "recordings" / "demo" / "truth.npz"
MARKERS = TEST_DATA / "markers"  # subject01_walk1.trc: its first 60 frames; arm26_elbow_flex.trc whole
FULL_MARKERS = SHARED_DATA / "markers"

FPS = 50.0
FRAMES = 40
LOST, MISSING, NAN_FRAME, NAN_JOINT = 5, 20, 10, 3  # frame 20 is left out of the poses file


@pytest.fixture(scope="module")
def truth() -> dict[str, np.ndarray]:
    with np.load(TRUTH) as data:
        return {key: data[key] for key in data.files}


@pytest.fixture
def tracked(tmp_path: Path, truth: dict[str, np.ndarray]) -> Path:
    """A poses.npz of the demo's true motion at 50 fps: frame 5 lost, 6 uncertain, 20 missing, one NaN joint."""
    path = tmp_path / "run" / "poses.npz"
    with PosesWriter(path, list(truth["component_names"]), list(truth["joint_names"]), FPS) as writer:
        for frame in range(FRAMES):
            if frame == MISSING:
                continue
            joints = truth["joints"][frame].copy()
            if frame == NAN_FRAME:
                joints[NAN_JOINT] = np.nan
            status = 2 if frame == LOST else 1 if frame == LOST + 1 else 0
            writer.append(frame, truth["poses"][frame], joints, status=status, residual=0.25 * frame)
    return path


def expected_joints(truth: dict[str, np.ndarray]) -> np.ndarray:
    """The joints of ``tracked`` as every export should hold them: NaN gaps for lost, missing and NaN joints."""
    joints = truth["joints"][:FRAMES].copy()
    joints[[LOST, MISSING]] = np.nan
    joints[NAN_FRAME, NAN_JOINT] = np.nan
    return joints


def test_trc_round_trip(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    out = export(tracked, "trc")
    assert out == tracked.with_suffix(".trc")
    trc = read_trc(out)
    assert trc.header["NumFrames"] == str(FRAMES) and trc.header["NumMarkers"] == "15"
    assert trc.rate == FPS and float(trc.header["CameraRate"]) == FPS and trc.units == "mm"
    assert trc.names == tuple(truth["joint_names"])
    np.testing.assert_array_equal(trc.frame, np.arange(FRAMES) + 1)
    np.testing.assert_allclose(trc.time, np.arange(FRAMES) / FPS, atol=1e-9)
    np.testing.assert_allclose(trc.markers / 1000.0, expected_joints(truth), rtol=0, atol=1e-9)


def test_trc_read_by_pandas(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    out = export(tracked, "trc", tracked.parent / "markers.trc")
    header = pandas.read_csv(out, sep="\t", skiprows=1, nrows=1)
    assert header["DataRate"][0] == FPS and header["NumFrames"][0] == FRAMES and header["Units"][0] == "mm"
    table = pandas.read_csv(out, sep="\t", skiprows=5, header=None)
    assert list(table[0]) == list(range(1, FRAMES + 1))
    values = table.iloc[:, 2 : 2 + 45].to_numpy(dtype=float).reshape(FRAMES, 15, 3) / 1000.0
    np.testing.assert_allclose(values, expected_joints(truth), rtol=0, atol=1e-9)
    with open(out) as file:
        names = file.read().splitlines()[3].split("\t")[2::3][:15]
    assert names == list(truth["joint_names"])


@pytest.mark.parametrize(
    "folder, name, markers, frames, rate, first",
    [
        (MARKERS, "subject01_walk1.trc", 41, 60, 60.0, ("R.ASIS", [617.247620, 1055.275020, 170.781980])),
        (MARKERS, "arm26_elbow_flex.trc", 3, 121, 120.0, ("r_acromion", [-13.05452443, 839.50547557, 169.5054756])),
        pytest.param(
            FULL_MARKERS,
            "subject01_walk1.trc",
            41,
            151,
            60.0,
            ("R.ASIS", [617.247620, 1055.275020, 170.781980]),
            marks=needs_shared("markers"),
            id="full-walk",
        ),
    ],
)
def test_trc_reader_on_real_files_and_rewrite(
    tmp_path: Path, folder: Path, name: str, markers: int, frames: int, rate: float, first: tuple[str, list[float]]
) -> None:
    trc = read_trc(folder / name)
    assert trc.markers.shape == (frames, markers, 3) and len(trc.names) == markers
    assert int(trc.header["NumFrames"]) == frames and trc.rate == rate and trc.units == "mm"
    assert trc.names[0] == first[0]
    np.testing.assert_allclose(trc.markers[0, 0], first[1])
    np.testing.assert_array_equal(trc.frame, np.arange(1, frames + 1))
    np.testing.assert_allclose(np.diff(trc.time), 1.0 / rate, atol=1e-3)
    assert np.isfinite(trc.markers).all()
    # our writer keeps real marker names (with dots) and values
    write_trc(tmp_path / name, trc.names, frame=trc.frame - 1, rate=trc.rate, joints=trc.markers / 1000.0)
    again = read_trc(tmp_path / name)
    assert again.names == trc.names and again.rate == rate
    np.testing.assert_allclose(again.markers, trc.markers, rtol=0, atol=1e-6)


def test_c3d_round_trip_with_ezc3d(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    out = export(tracked, "c3d")
    data = ezc3d.c3d(str(out))
    point = data["parameters"]["POINT"]
    assert list(point["LABELS"]["value"]) == list(truth["joint_names"])
    assert point["RATE"]["value"][0] == FPS and point["UNITS"]["value"] == ["mm"]
    assert point["Y_SCREEN"]["value"] == ["+Z"]
    assert data["header"]["points"]["first_frame"] == 0 and data["header"]["points"]["last_frame"] == FRAMES - 1
    points = np.transpose(data["data"]["points"][:3], (2, 1, 0)) / 1000.0
    np.testing.assert_allclose(points, expected_joints(truth), rtol=0, atol=1e-6)  # 32-bit floats
    residuals = data["data"]["meta_points"]["residuals"][0].T
    np.testing.assert_array_equal(residuals == -1, np.isnan(expected_joints(truth)).any(axis=2))
    assert set(np.unique(residuals)) == {-1.0, 0.0}


def test_c3d_to_a_name_without_its_suffix(tracked: Path, tmp_path: Path) -> None:
    """ezc3d adds .c3d to a file name that does not end in it: the export still lands at the name given."""
    names = ["poses", "poses.C3D"]
    for name in names:
        out = export(tracked, "c3d", tmp_path / "out" / name)
        assert ezc3d.c3d(str(out))["header"]["points"]["last_frame"] == FRAMES - 1
    assert sorted(path.name for path in (tmp_path / "out").iterdir()) == names  # no temporary file left


def test_c3d_read_by_the_c3d_package(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    out = export(tracked, "c3d")
    expected = expected_joints(truth)
    with open(out, "rb") as file, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file."
        reader = c3d.Reader(file)
        assert [label.strip() for label in reader.point_labels] == list(truth["joint_names"])
        assert reader.point_rate == FPS and reader.first_frame == 1 and reader.last_frame == FRAMES
        frames = [(index, points.copy()) for index, points, _ in reader.read_frames()]
    assert [index for index, _ in frames] == list(range(1, FRAMES + 1))
    for (_, points), joints in zip(frames, expected):
        gap = np.isnan(joints).any(axis=1)
        np.testing.assert_array_equal(points[:, 3] == -1, gap)
        np.testing.assert_allclose(points[~gap, :3] / 1000.0, joints[~gap], rtol=0, atol=1e-6)


def test_csv_read_by_the_csv_module(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    out = export(tracked, "csv")
    with open(out, newline="") as file:
        rows = list(csv.reader(file))
    names = list(truth["joint_names"])
    assert rows[0] == ["frame", "time", "status", "residual"] + [f"{n}_{a}" for n in names for a in "xyz"]
    table = np.array(rows[1:], dtype=float)
    assert table.shape == (FRAMES, 4 + 45)
    np.testing.assert_array_equal(table[:, 0], np.arange(FRAMES))
    np.testing.assert_allclose(table[:, 1], np.arange(FRAMES) / FPS, atol=1e-9)
    status = np.zeros(FRAMES)
    status[[LOST, MISSING]] = 2
    status[LOST + 1] = 1
    np.testing.assert_array_equal(table[:, 2], status)
    residual = 0.25 * np.arange(FRAMES)
    residual[MISSING] = np.nan
    np.testing.assert_allclose(table[:, 3], residual)
    np.testing.assert_allclose(table[:, 4:].reshape(FRAMES, 15, 3), expected_joints(truth), rtol=0, atol=1e-9)
    assert rows[1 + LOST][4] == "NaN"


def bvh_joint_centres(path: Path, names: list[str]) -> np.ndarray:
    """Joint centres (F, J, 3) in the tracker's z-up world, by forward kinematics of a BVH with our reader."""
    bvh = load_bvh(path)
    world = bvh_global(bvh)[:, [bvh.index(name) for name in names]][..., :3, 3]
    return world @ Z_UP_TO_Y_UP  # y up -> z up: C^T p


def test_bvh_forward_kinematics_reproduces_the_joints(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    model = load_model(HUMAN)
    out = export(tracked, "bvh", model=HUMAN)
    bvh = load_bvh(out)
    assert bvh.frames == FRAMES and bvh.frame_time == pytest.approx(1.0 / FPS, abs=1e-10)
    assert bvh.names == tuple(model.names[i] for i in depth_first(model))
    assert all(
        model.parent[model.index(n)] == (model.index(bvh.names[p]) if p >= 0 else -1)
        for n, p in zip(bvh.names, bvh.parents)
    )
    assert bvh.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert set(bvh.channels[1:]) == {("Zrotation", "Xrotation", "Yrotation")}
    centres = bvh_joint_centres(out, list(truth["joint_names"]))
    true = truth["joints"][:FRAMES]
    good = np.setdiff1d(np.arange(FRAMES), [LOST, MISSING])
    np.testing.assert_allclose(centres[good], true[good], rtol=0, atol=1e-6)
    # a lost or missing frame holds the last pose that was not lost
    np.testing.assert_allclose(centres[[LOST, MISSING]], true[[LOST - 1, MISSING - 1]], rtol=0, atol=1e-6)
    # the OFFSETs are the rest pose in metres, y up: the torso sits 0.08 m above the pelvis
    assert bvh.offsets[bvh.index("torso")] == pytest.approx([0.0, 0.08, 0.0])


def test_bvh_read_by_bvhio(tracked: Path, truth: dict[str, np.ndarray]) -> None:
    out = export(tracked, "bvh", model=HUMAN)
    root = bvhio.readAsHierarchy(str(out))
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    assert set(joints) == set(truth["joint_names"])
    for frame in (0, 17, FRAMES - 1):
        root.loadPose(frame)
        centres = np.array([joints[name].PositionWorld for name in truth["joint_names"]]) @ Z_UP_TO_Y_UP
        np.testing.assert_allclose(centres, truth["joints"][frame], rtol=0, atol=1e-5)  # bvhio computes in float32


TOY = {
    "name": "toy",
    "component": [
        {"name": "base", "parent": "", "joint": "free", "quadric": [{"shape": "sphere", "radius": 0.1}]},
        {
            "name": "arm",
            "parent": "base",
            "joint": "ball",
            "at": [0.1, 0.2, 0.3],
            "rest": [0.3, -0.2, 0.5],
            "quadric": [{"shape": "cone", "from": [0, 0, 0], "to": [0, 0, -0.3], "radii": [0.05, 0.04]}],
        },
        {
            "name": "elbow",
            "parent": "arm",
            "joint": "hinge",
            "axis": [0, 1, 1],
            "at": [0, 0, -0.3],
            "rest": [0, 0.4, 0],
        },
        {
            "name": "tip",
            "parent": "elbow",
            "joint": "slide",
            "axis": [1, 0, 0],
            "at": [0, 0, -0.2],
            "rest": [0.2, 0.1, -0.3],
        },
        {"name": "side", "parent": "base", "joint": "fixed", "at": [-0.1, 0, 0], "rest": [0, 0, 1.0]},
    ],
}


def toy_poses(model, frames: int, seed: int) -> np.ndarray:
    """Random exact poses of the toy model; frame 0 is the rest pose with the root at the origin."""
    rng = np.random.default_rng(seed)
    kinds = {spec["name"]: spec.get("joint", "ball") for spec in TOY["component"]}
    out = np.empty((frames, model.size, 4, 4))
    out[0] = rest_poses(model, np.eye(4))
    for f in range(1, frames):
        out[f, 0] = se3.from_rotvec(rng.normal(size=3), rng.normal(size=3))
        for i in range(1, model.size):
            axis = model.axis[i]
            local = {
                "ball": se3.from_rotvec(rng.normal(size=3)),
                "hinge": se3.from_rotvec(rng.uniform(-3, 3) * axis),
                "slide": se3.from_rotvec(np.zeros(3), rng.uniform(-0.2, 0.2) * axis),
                "fixed": np.eye(4),
            }[kinds[model.names[i]]]
            out[f, i] = out[f, model.parent[i]] @ model.rest[i] @ local
    return out


def test_bvh_of_rest_rotations_hinges_and_slides(tmp_path: Path) -> None:
    model = model_from_dict(TOY)
    poses = toy_poses(model, 30, seed=4)
    channels = motion(model, poses)
    np.testing.assert_allclose(channels[0], 0.0, atol=1e-9)  # rest pose = zero channels
    write_bvh(tmp_path / "toy.bvh", model, poses, status=np.zeros(30, np.int8), rate=30.0)
    bvh = load_bvh(tmp_path / "toy.bvh")
    assert bvh.channels[bvh.index("tip")][:3] == ("Xposition", "Yposition", "Zposition")
    assert len(bvh.channels[bvh.index("elbow")]) == 3
    np.testing.assert_allclose(
        bvh_joint_centres(tmp_path / "toy.bvh", list(model.names)), poses[:, :, :3, 3], rtol=0, atol=1e-6
    )


def test_euler_zxy_reproduces_rotations_also_at_gimbal_lock() -> None:
    rng = np.random.default_rng(7)
    angles = rng.uniform(-180, 180, size=(200, 3))
    angles[:50, 1] = rng.choice([-90.0, 90.0], size=50) + rng.choice([0.0, 1e-9, -1e-5, 1e-3], size=(50,))
    matrices = Rotation.from_euler("ZXY", angles, degrees=True).as_matrix()
    again = Rotation.from_euler("ZXY", euler_zxy(matrices), degrees=True).as_matrix()
    np.testing.assert_allclose(again, matrices, rtol=0, atol=1e-12)
    mild = angles[50:].copy()
    mild[:, 1] = rng.uniform(-80, 80, size=len(mild))
    np.testing.assert_allclose(euler_zxy(Rotation.from_euler("ZXY", mild, degrees=True).as_matrix()), mild, atol=1e-9)


def test_hold_lost_takes_the_last_good_frame() -> None:
    poses = np.arange(5, dtype=float)[:, None, None, None] * np.ones((5, 1, 4, 4))
    poses[3] = np.nan
    held = hold_lost(poses, np.array([2, 0, 1, 0, 2]))
    np.testing.assert_array_equal(held[:, 0, 0, 0], [1, 1, 2, 2, 2])


def test_run_prints_wrote_and_takes_the_format_case_insensitively(tracked: Path, capsys) -> None:
    out = tracked.parent / "sub" / "joints.csv"
    assert (
        run(build_parser().parse_args(["export", str(tracked), "--to", "CSV", "--out", str(out), "--fps", "25"])) == 0
    )
    assert capsys.readouterr().out == f"wrote {out}\n"
    with open(out) as file:
        assert file.read().splitlines()[2].split(",")[1] == "0.040000000"  # --fps sets the time step


def test_truth_file_exports_with_fps(tmp_path: Path, truth: dict[str, np.ndarray]) -> None:
    with pytest.raises(TrackerInputError, match="pass --fps"):
        export(TRUTH, "trc", tmp_path / "truth.trc")
    trc = read_trc(export(TRUTH, "trc", tmp_path / "truth.trc", fps=60.0))
    assert trc.rate == 60.0 and len(trc.frame) == len(truth["frame"])
    np.testing.assert_allclose(trc.markers / 1000.0, truth["joints"], rtol=0, atol=1e-9)


def test_bad_input(tmp_path: Path, tracked: Path, truth: dict[str, np.ndarray], one_line_error) -> None:
    message = one_line_error(lambda: export(tracked, "fbx"))
    assert str(tracked) in message and "--to trc, c3d, bvh, csv" in message
    missing = tmp_path / "nowhere" / "poses.npz"
    assert str(missing) in one_line_error(lambda: export(missing, "trc")) and not missing.parent.exists()
    joints_only = tmp_path / "joints.npz"
    np.savez(
        joints_only,
        joint_names=truth["joint_names"],
        joints=truth["joints"],
        frame=truth["frame"],
        time=truth["frame"] / 60.0,
    )
    message = one_line_error(lambda: export(joints_only, "bvh", model=HUMAN))
    assert str(joints_only) in message and "'poses'" in message and "--to trc" in message
    message = one_line_error(lambda: export(tracked, "bvh"))
    assert str(tracked) in message and "--model" in message
    toy = tmp_path / "toy.toml"
    toy.write_text('[[component]]\nname = "base"\nparent = ""\n[[component.quadric]]\nshape = "sphere"\nradius = 0.1\n')
    message = one_line_error(lambda: export(tracked, "bvh", model=toy))
    assert str(tracked) in message and str(toy) in message and "--model" in message
    assert not list(tmp_path.glob("*.bvh")) and not list(tracked.parent.glob("*.bvh"))
    bad_trc = tmp_path / "bad.trc"
    bad_trc.write_text("PathFileType\t4\n")
    assert str(bad_trc) in one_line_error(lambda: read_trc(bad_trc))


def test_c3d_refuses_frame_numbers_its_16_bit_header_cannot_hold(tmp_path: Path) -> None:
    from tracker.io.export.c3d import write_c3d

    joints = np.zeros((3, 2, 3))
    with pytest.raises(TrackerInputError, match="export to TRC or CSV"):
        write_c3d(tmp_path / "late.c3d", ["a", "b"], first_frame=70_000, rate=60.0, joints=joints)
    assert not (tmp_path / "late.c3d").exists()


def test_frames_spread_over_a_huge_range_are_refused(tmp_path: Path) -> None:
    from tracker.io.export import regular_rows

    data = {"frame": np.array([0, 2_000_000_000]), "time": np.array([0.0, 1.0]), "joints": np.zeros((2, 3, 3))}
    with pytest.raises(TrackerInputError, match="split the file or renumber"):
        regular_rows(data, tmp_path / "poses.npz", fps=60.0)
