"""A write that fails says the fix that matches its cause (tracker/atomic.py): a full disk, a folder where a file
goes, a file where a folder goes, a folder the user may not write to; the file being written stays as it was."""

from __future__ import annotations

import errno
import os

import pytest
from conftest import file_hashes

from tracker import atomic
from tracker.atomic import atomic_write
from tracker.cli import main


def _error_line(argv: list, capsys) -> str:
    assert main([str(word) for word in argv]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1
    return lines[0].removeprefix("tracker: error: ")


def test_a_folder_where_the_file_goes(small_poses, tmp_path, capsys):
    folder = tmp_path / "exports"
    folder.mkdir()
    before = file_hashes(tmp_path)
    line = _error_line(["export", small_poses, "--to", "csv", "--out", folder], capsys)
    assert line == f"{folder}: cannot write (Is a directory); it is a folder; give the name of a file to write"
    assert file_hashes(tmp_path) == before  # nor a temporary file left beside it


@pytest.mark.parametrize("below", [["poses.csv"], ["more", "poses.csv"]], ids=["parent", "grandparent"])
def test_a_file_where_a_folder_goes(small_poses, below, capsys):
    before = file_hashes(small_poses.parent)
    out = small_poses.joinpath(*below)
    line = _error_line(["export", small_poses, "--to", "csv", "--out", out], capsys)
    assert line.startswith(f"{out.parent}: cannot write there (")
    assert line.endswith(f"); {small_poses} is a file, not a folder; choose another output path")
    assert file_hashes(small_poses.parent) == before


@pytest.mark.parametrize(
    "code, fix",
    [
        (errno.ENOSPC, "free disk space or choose an output folder on another disk"),
        (errno.EACCES, "choose a writable output folder"),
        (errno.EROFS, "choose a writable output folder"),
    ],
)
def test_the_fix_follows_the_cause(tmp_path, monkeypatch, one_line_error, code, fix):
    path = tmp_path / "poses.csv"
    path.write_bytes(b"before")

    def fails(*args):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(atomic.os, "replace", fails)
    message = one_line_error(lambda: atomic_write(path, lambda file: file.write(b"after")))
    assert message == f"{path}: cannot write ({os.strerror(code)}); {fix}"
    assert path.read_bytes() == b"before" and [p.name for p in tmp_path.iterdir()] == ["poses.csv"]


def test_an_output_file_is_checked_before_the_work(tmp_path, one_line_error):
    """A command whose output comes at the end of long work (fit-model, calibrate, init, --record) checks first that
    the file can be written there: its folder made, no folder in its place, no file in the folder's place."""
    assert atomic.writable_file(tmp_path / "new" / "model.toml") == tmp_path / "new" / "model.toml"
    assert (tmp_path / "new").is_dir() and not (tmp_path / "new" / "model.toml").exists()
    (tmp_path / "taken").mkdir()
    message = one_line_error(lambda: atomic.writable_file(tmp_path / "taken"))
    assert message == f"{tmp_path / 'taken'}: is a folder; give the name of a file to write"
    (tmp_path / "file").write_text("mine")
    message = one_line_error(lambda: atomic.writable_file(tmp_path / "file" / "model.toml"))
    assert message.startswith(f"{tmp_path / 'file'}: cannot write there") and (tmp_path / "file").read_text() == "mine"


def test_fit_model_checks_its_output_before_any_detection(tiny_recording, tmp_path, monkeypatch, capsys):
    def detect(*args, **kwargs):
        raise AssertionError("detected")

    monkeypatch.setattr("tracker.landmarks.detect_recording.detect_recording", detect)
    (tmp_path / "taken").mkdir()
    argv = ["fit-model", str(tiny_recording), "--out", str(tmp_path / "taken"), "--cache", str(tmp_path / "kp")]
    assert main(argv) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"tracker: error: {tmp_path / 'taken'}: is a folder; give the name of a file to write"
    ]
