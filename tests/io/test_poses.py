"""poses.npz writer (atomic, interrupt-safe) and the poses/truth loader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracker.errors import TrackerInputError
from tracker.io.poses import PosesWriter, load_poses

COMPONENTS = ["pelvis", "thigh_l", "shin_l"]
JOINTS = ["pelvis", "thigh_l", "shin_l", "foot_l"]


def row(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    poses = np.tile(np.eye(4), (len(COMPONENTS), 1, 1))
    poses[:, :3, 3] = rng.normal(size=(len(COMPONENTS), 3))
    return poses, rng.normal(size=(len(JOINTS), 3))


def write_frames(writer: PosesWriter, frames: range, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    rows = []
    for frame in frames:
        poses, joints = row(rng)
        writer.append(frame, poses, joints, status=frame % 3, residual=0.5 * frame, elapsed=0.001 * frame)
        rows.append((poses, joints))
    return rows


def test_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "new" / "folder" / "poses.npz"  # missing folders are created
    with PosesWriter(path, COMPONENTS, JOINTS, fps=25.0) as writer:
        rows = write_frames(writer, range(10, 110))
    arrays = load_poses(path)
    np.testing.assert_array_equal(arrays["frame"], np.arange(10, 110))
    np.testing.assert_allclose(arrays["time"], np.arange(100) / 25.0)
    assert list(arrays["component_names"]) == COMPONENTS and list(arrays["joint_names"]) == JOINTS
    np.testing.assert_array_equal(arrays["poses"], np.stack([p for p, _ in rows]))
    np.testing.assert_array_equal(arrays["joints"], np.stack([j for _, j in rows]))
    np.testing.assert_array_equal(arrays["status"], np.arange(10, 110) % 3)
    np.testing.assert_allclose(arrays["residual"], 0.5 * np.arange(10, 110))
    np.testing.assert_allclose(arrays["elapsed"], 0.001 * np.arange(10, 110))
    dtypes = {
        key: arrays[key].dtype.kind + str(arrays[key].dtype.itemsize) for key in ("frame", "time", "poses", "status")
    }
    assert dtypes == {"frame": "i8", "time": "f8", "poses": "f8", "status": "i1"}
    assert arrays["joint_names"].dtype.kind == "U"
    with np.load(path, allow_pickle=False) as raw:
        keys = ["frame", "time", "component_names", "poses", "joint_names", "joints", "status", "residual", "elapsed"]
        assert sorted(raw.files) == sorted(keys)


def test_flush_writes_a_loadable_file_and_no_temporaries(tmp_path: Path) -> None:
    path = tmp_path / "poses.npz"
    writer = PosesWriter(path, COMPONENTS, JOINTS, fps=30.0, flush_every=1000)
    write_frames(writer, range(3))
    assert not path.exists()
    writer.flush()
    assert len(load_poses(path)["frame"]) == 3
    assert [p.name for p in tmp_path.iterdir()] == ["poses.npz"]
    write_frames(writer, range(3, 5))
    assert len(load_poses(path)["frame"]) == 3  # not flushed yet
    writer.close()
    assert len(load_poses(path)["frame"]) == 5


def test_flush_every(tmp_path: Path) -> None:
    path = tmp_path / "poses.npz"
    writer = PosesWriter(path, COMPONENTS, JOINTS, fps=30.0, flush_every=2)
    write_frames(writer, range(3))
    assert len(load_poses(path)["frame"]) == 2


@pytest.mark.parametrize("interruption", [RuntimeError, KeyboardInterrupt])
def test_interrupted_run_leaves_the_frames_done(tmp_path: Path, interruption: type[BaseException]) -> None:
    path = tmp_path / "poses.npz"
    with pytest.raises(interruption):
        with PosesWriter(path, COMPONENTS, JOINTS, fps=30.0) as writer:
            write_frames(writer, range(3))
            raise interruption()
    np.testing.assert_array_equal(load_poses(path)["frame"], [0, 1, 2])


def test_unwritable_folder(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("not a folder")
    with pytest.raises(TrackerInputError, match="file"):
        PosesWriter(tmp_path / "file" / "out" / "poses.npz", COMPONENTS, JOINTS, fps=30.0)


def test_bad_rows_are_rejected(tmp_path: Path) -> None:
    writer = PosesWriter(tmp_path / "poses.npz", COMPONENTS, JOINTS, fps=30.0)
    with pytest.raises(ValueError, match="joints"):
        writer.append(0, np.tile(np.eye(4), (3, 1, 1)), np.zeros((2, 3)), status=0, residual=0.0)
    with pytest.raises(ValueError, match="status"):
        writer.append(0, np.tile(np.eye(4), (3, 1, 1)), np.zeros((4, 3)), status=5, residual=0.0)


def test_truth_with_only_joints_loads(tmp_path: Path) -> None:
    path = tmp_path / "truth.npz"
    np.savez(path, joint_names=np.array([b"a", b"b"]), joints=np.zeros((4, 2, 3), np.float32))
    arrays = load_poses(path)
    assert list(arrays["joint_names"]) == ["a", "b"] and arrays["joints"].dtype == np.float64


@pytest.mark.parametrize(
    "arrays, expected",
    [
        ({"joints": np.zeros((2, 1, 3))}, "joint_names"),
        ({"joint_names": np.array(["a"]), "joints": np.zeros((2, 2, 3))}, "joints"),
        ({"joint_names": np.array(["a", "a"]), "joints": np.zeros((2, 2, 3))}, "repeats"),
        ({"joint_names": np.array(["a"]), "joints": np.zeros((2, 1, 3)), "frame": np.array([0.5, 1.5])}, "frame"),
        ({"joint_names": np.array(["a"]), "joints": np.zeros((2, 1, 3)), "status": np.array([0, 7])}, "status"),
        (
            {"joint_names": np.array(["a"]), "joints": np.zeros((2, 1, 3)), "poses": np.zeros((2, 1, 4, 4))},
            "component_names",
        ),
        ({"joint_names": np.array(["a"], dtype=object), "joints": np.zeros((2, 1, 3))}, "npz"),
    ],
)
def test_bad_npz_names_file(tmp_path: Path, arrays: dict, expected: str) -> None:
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(TrackerInputError, match=expected) as error:
        load_poses(path)
    assert "bad.npz" in str(error.value)


@pytest.mark.parametrize("content", [b"", b"not a zip file at all"])
def test_not_an_npz(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "poses.npz"
    path.write_bytes(content)
    with pytest.raises(TrackerInputError, match="poses.npz"):
        load_poses(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TrackerInputError, match="gone.npz"):
        load_poses(tmp_path / "gone.npz")


def test_long_runs_flush_geometrically(tmp_path: Path, monkeypatch) -> None:
    """Flushes come after 25 frames or a quarter more than the file holds: O(F) bytes over a run."""
    writer = PosesWriter(tmp_path / "poses.npz", COMPONENTS, JOINTS, fps=30.0, flush_every=25)
    flushed_at = []
    monkeypatch.setattr(writer, "flush", lambda: (flushed_at.append(len(writer)), setattr(writer, "_unflushed", 0)))
    for index in range(2000):
        writer.append(
            index, np.tile(np.eye(4), (len(COMPONENTS), 1, 1)), np.zeros((len(JOINTS), 3)), status=0, residual=0.5
        )
    assert flushed_at[:4] == [25, 50, 75, 100]
    assert sum(flushed_at) < 6 * 2000 and len(flushed_at) < 30


def test_rows_with_their_own_times_keep_them(tmp_path: Path) -> None:
    """Live capture: rows numbered as tracked, timed as captured (stale frames dropped between them)."""
    path = tmp_path / "poses.npz"
    rng = np.random.default_rng(7)
    with PosesWriter(path, COMPONENTS, JOINTS, fps=60.0) as writer:
        for frame, at in enumerate((0.05, 0.1, 0.3)):
            poses, joints = row(rng)
            writer.append(frame, poses, joints, status=0, residual=0.5, elapsed=0.01, time=at)
        with pytest.raises(ValueError, match="every frame a time or none"):
            writer.append(3, poses, joints, status=0, residual=0.5)
    np.testing.assert_array_equal(load_poses(path)["time"], [0.05, 0.1, 0.3])


def test_a_long_run_keeps_its_rows_on_disk_and_cleans_up(tmp_path: Path) -> None:
    """1000 frames with capture times, flushed as they come: the file holds every row in order, the writer's
    memory holds a fixed number of rows however many are written, and closing removes its raw files."""
    import tracker.io.poses as poses_module

    path = tmp_path / "poses.npz"
    writer = PosesWriter(path, COMPONENTS, JOINTS, fps=30.0, flush_every=7)
    held = sum(column.nbytes for column in writer._buffer.values())
    rng = np.random.default_rng(3)
    rows = []
    for frame in range(1000):
        poses, joints = row(rng)
        writer.append(
            frame, poses, joints, status=frame % 4, residual=0.1 * frame, elapsed=0.002, time=0.5 + frame / 29.97
        )
        rows.append((poses, joints))
        if frame == 600:
            assert len(load_poses(path)["frame"]) >= 480  # flushed along the way, a valid file
    assert sum(column.nbytes for column in writer._buffer.values()) == held
    assert 1000 > poses_module._BUFFER
    raw = writer._rows
    assert raw.is_dir()
    writer.close()
    assert not raw.exists()
    arrays = load_poses(path)
    np.testing.assert_array_equal(arrays["frame"], np.arange(1000))
    np.testing.assert_allclose(arrays["time"], 0.5 + np.arange(1000) / 29.97)
    np.testing.assert_array_equal(arrays["poses"], np.stack([p for p, _ in rows]))
    np.testing.assert_array_equal(arrays["joints"], np.stack([j for _, j in rows]))
    np.testing.assert_array_equal(arrays["status"], np.arange(1000) % 4)


def test_a_writer_with_no_frames_writes_an_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "poses.npz"
    with PosesWriter(path, COMPONENTS, JOINTS, fps=30.0):
        pass
    arrays = load_poses(path)
    assert arrays["joints"].shape == (0, len(JOINTS), 3) and arrays["poses"].shape == (0, len(COMPONENTS), 4, 4)
    assert arrays["time"].shape == (0,)


def test_a_spill_broken_off_is_done_again(tmp_path: Path, monkeypatch) -> None:
    """Ctrl-C while the rows go to disk (after the first array, before the second; the frame that caused it
    is not taken), then two frames more: closing writes a valid file with every frame once, in order."""
    import tracker.io.poses as poses_module

    monkeypatch.setattr(poses_module, "_BUFFER", 4)
    path = tmp_path / "poses.npz"
    writer = PosesWriter(path, COMPONENTS, JOINTS, fps=30.0, flush_every=1000)
    write_frames(writer, range(4))  # the buffer is full: the next frame spills it first
    real_open, opened = open, []

    def interrupted_open(file, mode="r", *args, **kwargs):
        opened.append(file)
        if len(opened) == 2:
            raise KeyboardInterrupt
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr("builtins.open", interrupted_open)
    with pytest.raises(KeyboardInterrupt):
        write_frames(writer, range(4, 5), seed=1)
    monkeypatch.setattr("builtins.open", real_open)
    write_frames(writer, range(4, 6), seed=2)
    writer.close()
    arrays = load_poses(path)
    np.testing.assert_array_equal(arrays["frame"], np.arange(6))
    assert arrays["poses"].shape == (6, len(COMPONENTS), 4, 4)


def test_rows_that_cannot_be_kept_are_a_one_line_error(tmp_path: Path, monkeypatch) -> None:
    import tracker.io.poses as poses_module

    monkeypatch.setattr(poses_module, "_BUFFER", 2)
    writer = PosesWriter(tmp_path / "poses.npz", COMPONENTS, JOINTS, fps=30.0, flush_every=1000)
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")
    writer._rows = blocked  # as if the temporary folder's disk had gone
    write_frames(writer, range(2))
    with pytest.raises(TrackerInputError, match="not-a-folder: cannot keep the tracked frames there.*TMPDIR"):
        write_frames(writer, range(2, 3))


def test_which_parts_are_held_is_written_for_every_frame_or_none(tmp_path: Path) -> None:
    """``held`` (F, N) int8 round-trips; a writer given it for some frames and not others refuses; a file without
    it (written before it, or by tracker points) loads without it; one with a code other than 0-2 is refused."""
    rng = np.random.default_rng(1)
    path = tmp_path / "poses.npz"
    codes = np.array([[0, 1, 2], [0, 0, 0], [2, 2, 1]], np.int8)
    with PosesWriter(path, COMPONENTS, JOINTS, fps=30.0) as writer:
        for frame, held in enumerate(codes):
            writer.append(frame, *row(rng), status=0, residual=0.0, held=held)
        with pytest.raises(ValueError, match="every frame or in none"):
            writer.append(3, *row(rng), status=0, residual=0.0)
        with pytest.raises(ValueError, match="held must hold 0, 1 or 2"):
            writer.append(3, *row(rng), status=0, residual=0.0, held=np.array([0, 3, 0]))
    arrays = load_poses(path)
    np.testing.assert_array_equal(arrays["held"], codes)
    assert arrays["held"].dtype == np.int8
    old = tmp_path / "old.npz"
    with PosesWriter(old, COMPONENTS, JOINTS, fps=30.0) as writer:
        write_frames(writer, range(2))
    assert "held" not in load_poses(old) and "held" not in np.load(old).files
    bad = tmp_path / "bad.npz"
    np.savez(bad, **dict(arrays, held=np.full((3, 3), 5, np.int8)))
    with pytest.raises(TrackerInputError, match="'held' holds values other than 0, 1, 2"):
        load_poses(bad)
    np.savez(bad, **dict(arrays, held=np.zeros((3, 2), np.int8)))
    with pytest.raises(TrackerInputError, match="'held' must be integer of shape"):
        load_poses(bad)
