"""A batch's records: the manifest survives a reopen with what each recording's state is, refuses other tracking
options and unreadable files with one line, and the summary lists every row."""

import csv
import math

import pytest

from tracker.io.batch_records import COLUMNS, DONE, FAILED, Manifest, Row, format_summary, write_summary

OPTIONS = {"model": None, "iterations": 6, "keypoints": None, "background": "none"}


def _rows() -> list[Row]:
    return [
        Row("/data/a", "a", DONE, frames=20, fps=31.5, residual_px=0.5, lost=1, mpjpe_mm=12.5, seconds=4.0),
        Row("/data/b", "b", DONE, frames=30, fps=40.0, residual_px=0.75, lost=0),
        Row("/data/c", "c", FAILED, attempts=3, error="/data/c/calibration.toml: not found; add it"),
    ]


def test_manifest_reopens_with_started_and_finished_recordings(tmp_path):
    manifest = Manifest.open(tmp_path / "manifest.json", OPTIONS)
    assert manifest.names == {}
    manifest.start({"/data/a": "a", "/data/b": "b", "/data/c": "c"})
    done, _, failed = _rows()
    manifest.finish(failed)
    manifest.finish(done)

    again = Manifest.open(tmp_path / "manifest.json", dict(OPTIONS))
    assert repr(again.row("/data/a")) == repr(done)  # NaN fields: equal as written, not as floats
    assert repr(again.row("/data/c")) == repr(failed)
    assert again.row("/data/b") is None and again.names == {"/data/a": "a", "/data/b": "b", "/data/c": "c"}
    assert [row.name for row in again.finished()] == ["a", "c"]  # in the order taken on, not finished
    again.start({"/data/c": "c"})  # a failed recording tried again is no longer finished
    assert [row.name for row in again.finished()] == ["a"]
    assert [path.name for path in tmp_path.iterdir()] == ["manifest.json"]  # no temporary file left


def test_manifest_of_other_options_is_refused_naming_them(tmp_path, one_line_error):
    Manifest.open(tmp_path / "manifest.json", OPTIONS).start({"/data/a": "a"})
    other = {**OPTIONS, "iterations": 4, "keypoints": 0}
    message = one_line_error(lambda: Manifest.open(tmp_path / "manifest.json", other))
    assert "iterations, keypoints" in message and "--out" in message


@pytest.mark.parametrize("text", ["{not json", '{"format": "something else", "version": 1}', '{"format": 3}'])
def test_unreadable_manifest_is_one_line(tmp_path, one_line_error, text):
    (tmp_path / "manifest.json").write_text(text)
    message = one_line_error(lambda: Manifest.open(tmp_path / "manifest.json", OPTIONS))
    assert str(tmp_path / "manifest.json") in message and "remove it" in message


def test_summary_csv_has_a_row_per_recording(tmp_path):
    rows = _rows()
    write_summary(rows, tmp_path / "summary.csv")
    with open(tmp_path / "summary.csv", newline="") as file:
        table = list(csv.DictReader(file))
    assert tuple(table[0]) == COLUMNS
    assert [entry["name"] for entry in table] == ["a", "b", "c"]
    assert float(table[0]["mpjpe_mm"]) == 12.5 and math.isnan(float(table[1]["mpjpe_mm"]))
    assert table[2]["state"] == FAILED and table[2]["error"] == rows[2].error and table[2]["attempts"] == "3"


def test_terminal_summary_shows_each_recording_and_the_error_of_a_failed_one():
    lines = format_summary(_rows()).splitlines()
    assert lines[0].split()[:3] == ["recording", "state", "frames"]
    assert lines[1].split()[:6] == ["a", "done", "20", "31.5", "0.50", "px"]
    assert "12.5 mm" in lines[1]
    assert lines[3].split()[:2] == ["c", "failed"]
    assert lines[4].strip() == _rows()[2].error
