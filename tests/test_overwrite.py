"""A command never writes over its own inputs (tracker/overwrite.py), and synth replaces a recording only with --force:
each refusal exits 2 with one line that names the file and the fix, before any work, and leaves every byte of the
user's files as it was."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from conftest import HUMAN, ROOT, TEST_DATA, file_hashes

from tracker.cli import main
from tracker.overwrite import keep_inputs, same_file


def refused(argv: list, capsys) -> str:
    """The one line of a command that exits 2, without its ``tracker: error:`` prefix."""
    assert main([str(word) for word in argv]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracker: error: ")
    return lines[0].removeprefix("tracker: error: ")


@pytest.fixture
def rec(tiny_recording, tmp_path) -> Path:
    """A copy of the tiny rendered recording (cameras cam0 and cam1), the user's own."""
    return Path(shutil.copytree(tiny_recording, tmp_path / "rec"))


def test_the_same_file_by_another_spelling_or_a_link(tmp_path):
    file = tmp_path / "poses.npz"
    file.write_bytes(b"arrays")
    (tmp_path / "sub").mkdir()
    (tmp_path / "link.npz").symlink_to(file)
    os.link(file, tmp_path / "hard.npz")
    for other in (tmp_path / "sub" / ".." / "poses.npz", tmp_path / "link.npz", tmp_path / "hard.npz"):
        assert same_file(other, file)
    (tmp_path / "copy.npz").write_bytes(b"arrays")
    assert not same_file(tmp_path / "copy.npz", file)
    assert not same_file(tmp_path / "new.npz", tmp_path / "new.npz")  # not there yet: nobody's input


def test_an_output_that_is_an_input_is_refused_with_its_fix(tmp_path, one_line_error):
    poses = tmp_path / "poses.npz"
    poses.write_bytes(b"arrays")
    read = [(None, "an option not given"), (poses, "the poses file being exported")]
    keep_inputs([None, tmp_path / "poses.csv"], read, "write the export to another file")
    message = one_line_error(lambda: keep_inputs([tmp_path / "poses.csv", poses], read, "write it elsewhere"))
    assert message == f"{poses}: is the poses file being exported; write it elsewhere"


@pytest.mark.parametrize("fmt", ["csv", "trc"])
def test_export_refuses_to_write_over_the_poses_it_exports(small_poses, fmt, capsys):
    before = file_hashes(small_poses.parent)
    for out in (small_poses, small_poses.parent / ".." / "run" / "poses.npz"):
        line = refused(["export", small_poses, "--to", fmt, "--out", out], capsys)
        assert line == f"{out}: is the poses file being exported; write the export to another file"
    assert file_hashes(small_poses.parent) == before


def test_export_refuses_to_write_over_the_model(small_poses, tmp_path, capsys):
    model = Path(shutil.copy(HUMAN, tmp_path / "model.toml"))
    before = file_hashes(model, small_poses)
    line = refused(["export", small_poses, "--to", "bvh", "--model", model, "--out", model], capsys)
    assert line == f"{model}: is the body model of the export; write the export to another file"
    assert file_hashes(model, small_poses) == before


def _synth(calib: Path, out: Path, *extra: str) -> list:
    return [
        "synth",
        "--model",
        HUMAN,
        "--calib",
        calib,
        "--motion",
        "procedural",
        "--frames",
        "1",
        "--out",
        out,
        *extra,
    ]


def test_synth_refuses_a_folder_that_holds_a_recording(rec, capsys):
    before = file_hashes(rec)
    line = refused(_synth(ROOT / "calib" / "demo3.toml", rec, "--quiet"), capsys)
    assert line == (
        f"{rec}: already holds a recording (calibration.toml, cam0.avi, cam1.avi); write the render to another "
        "folder, or add --force to replace it"
    )
    assert file_hashes(rec) == before


@pytest.mark.parametrize("force", [[], ["--force"]], ids=["", "force"])
def test_synth_never_writes_over_the_calibration_it_renders_from(rec, force, capsys):
    calib = rec / "calibration.toml"
    before = file_hashes(rec)
    line = refused(_synth(calib, rec, "--zoom", "2", "--quiet", *force), capsys)
    assert line == f"{calib}: is the calibration being rendered from (--calib); write the recording to another folder"
    assert file_hashes(rec) == before


def test_synth_never_writes_over_the_model_it_renders(rec, capsys):
    before = file_hashes(rec)
    argv = _synth(ROOT / "calib" / "demo3.toml", rec, "--force", "--quiet")
    argv[argv.index(HUMAN)] = rec / "model.toml"
    line = refused(argv, capsys)
    assert (
        line
        == f"{rec / 'model.toml'}: is the body model being rendered (--model); write the recording to another folder"
    )
    assert file_hashes(rec) == before


def test_synth_force_leaves_nothing_of_the_recording_it_replaces(rec, capsys):
    (rec / "cam9.avi").write_bytes(b"a camera the new rig lacks")
    (rec / "timestamps.csv").write_text("frame,cam0,cam1\n")
    (rec / "notes.txt").write_text("the user's own")
    assert (rec / "init.toml").is_file()
    assert (
        main([str(word) for word in _synth(ROOT / "calib" / "demo3.toml", rec, "--force", "--no-init", "--quiet")]) == 0
    )
    names = {path.name for path in rec.iterdir()}
    assert {"truth_init.toml", "cam0.avi", "cam1.avi", "cam2.avi", "notes.txt"} <= names
    assert not names & {"init.toml", "cam9.avi", "timestamps.csv", "body.toml"}


CASES = {
    "track --overlay": (
        ["track", "{rec}", "--out", "{tmp}/out", "--overlay", "{rec}/cam0.avi", "--quiet"],
        "{rec}/cam0.avi: is the footage of camera cam0 being read; write the overlay video to another file",
    ),
    "track --record": (
        ["track", "{rec}", "--out", "{tmp}/out", "--view", "--record", "{rec}/truth.npz", "--quiet"],
        "{rec}/truth.npz: is the recording's true poses; write the viewer session to another file",
    ),
    "view --record": (
        ["view", "{rec}", "--poses", "{rec}/truth.npz", "--record", "{rec}/truth.npz", "--quiet"],
        "{rec}/truth.npz: is the poses file being reviewed; write the viewer session to another file",
    ),
    "init --out": (
        ["init", "{rec}", "--out", "{rec}/init.toml"],
        "{rec}/init.toml: is the pose the placement starts from; save the placed pose to another file (and track "
        "with --init FILE)",
    ),
    "fit-model --out": (
        ["fit-model", "{rec}", "--out", "{rec}/model.toml", "--quiet"],
        "{rec}/model.toml: is the model the fit starts from; write the fitted model to another file",
    ),
    "refine --out": (
        ["refine", "{rec}", "--poses", "{rec}/truth.npz", "--out", "{rec}/truth.npz", "--quiet"],
        "{rec}/truth.npz: is the poses file the rig is refined to; write the refined rig to another file",
    ),
}


@pytest.mark.parametrize("argv, expected", CASES.values(), ids=CASES)
def test_a_command_on_a_recording_never_writes_over_its_files(rec, tmp_path, argv, expected, capsys):
    before = file_hashes(rec)
    line = refused([word.format(rec=rec, tmp=tmp_path) for word in argv], capsys)
    assert line == expected.format(rec=rec)
    assert file_hashes(rec) == before and not (tmp_path / "out").exists()


def test_calibrate_never_writes_over_the_intrinsics_it_keeps(tmp_path, capsys):
    rig = Path(shutil.copy(ROOT / "calib" / "demo3.toml", tmp_path / "rig.toml"))
    before = file_hashes(rig)
    argv = ["calibrate", tmp_path / "boards", "--board", "chessboard:9x6:0.025", "--fix-intrinsics", rig, "--out", rig]
    line = refused(argv, capsys)
    assert line == (
        f"{rig}: is the calibration the intrinsics are taken from (--fix-intrinsics); write the new calibration to "
        "another file"
    )
    assert file_hashes(rig) == before


def test_points_never_writes_over_its_marker_file(tmp_path, capsys):
    markers = Path(shutil.copy(TEST_DATA / "markers" / "Vicon.c3d", tmp_path / "Vicon.c3d"))
    before = file_hashes(markers)
    argv = ["points", markers, "--model", ROOT / "models" / "vicon_arm.points.toml", "--out", tmp_path / "out"]
    line = refused([*argv, "--record", markers, "--quiet"], capsys)
    assert line == f"{markers}: is the marker file being fitted; write the results elsewhere (--out, --record)"
    assert file_hashes(markers) == before and not (tmp_path / "out").exists()
