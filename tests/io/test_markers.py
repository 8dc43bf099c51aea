"""tracker.io.markers: real C3D and TRC marker files read into metres with gaps, and their errors.

The files are the committed cuts in tests/data/markers (the first frames of ../shared/data/markers'
files, C3D rewritten by ezc3d without the analog channels); the full originals are read too when
../shared/data is beside the repository."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from conftest import SHARED_DATA, TEST_DATA, needs_shared

from tracker.io.export.c3d import write_c3d
from tracker.io.markers import read_markers

MARKERS = TEST_DATA / "markers"
FULL = SHARED_DATA / "markers"


def _vicon_in_metres_with_its_gaps(path: Path, frames: int, gaps_expected: int) -> None:
    markers = read_markers(path)
    raw = ezc3d.c3d(str(path))
    points = raw["data"]["points"]
    residuals = raw["data"]["meta_points"]["residuals"][0]
    assert markers.positions.shape == (frames, 51, 3)
    assert markers.rate == 100.0 and markers.first_frame == 0
    assert markers.labels[8] == "Daphnee:ASISr"
    gaps = ~np.isfinite(markers.positions).all(axis=2)
    assert gaps.sum() == (residuals < 0).sum() == gaps_expected
    seen = ~gaps
    assert np.allclose(markers.positions[seen], np.transpose(points[:3], (2, 1, 0))[seen] / 1000.0)
    # an adult's sternum sits 0.3-0.6 m from the front of the pelvis: the units became metres
    # (measured 0.446 m over the committed 160 frames, 0.454 m over all 580)
    pelvis, sternum = np.nanmedian(markers.select(["ASISr", "STER"]), axis=0)
    assert 0.3 < np.linalg.norm(sternum - pelvis) < 0.6


def test_vicon_c3d_in_metres_with_its_gaps() -> None:
    """The committed first 160 frames: 64 gaps, in 4 markers (LARMl, STYLu, LASTC, MEDH) from frame 118."""
    _vicon_in_metres_with_its_gaps(MARKERS / "Vicon.c3d", 160, 64)
    markers = read_markers(MARKERS / "Vicon.c3d")
    gappy = ~np.isfinite(markers.positions).all(axis=2)
    assert [markers.labels[i] for i in np.nonzero(gappy.any(axis=0))[0]] == [
        "Daphnee:LARMl",
        "Daphnee:STYLu",
        "Daphnee:LASTC",
        "Daphnee:MEDH",
    ]
    assert not gappy[:118].any() and gappy[118].any()


@needs_shared("markers", "Vicon.c3d")
def test_full_vicon_c3d_in_metres_with_its_gaps() -> None:
    _vicon_in_metres_with_its_gaps(FULL / "Vicon.c3d", 580, 305)


def test_qualisys_c3d_and_opensim_trc() -> None:
    qualisys = read_markers(MARKERS / "Qualisys.c3d")
    assert qualisys.positions.shape == (40, 55, 3) and qualisys.rate == 200.0 and qualisys.first_frame == 704
    assert np.isfinite(qualisys.positions).all()
    trc = read_markers(MARKERS / "subject01_walk1.trc")
    assert trc.positions.shape == (60, 41, 3) and trc.rate == 60.0 and trc.first_frame == 1
    assert trc.positions[0, trc.index("R.ASIS")] == pytest.approx([0.61724762, 1.05527502, 0.17078198])


@needs_shared("markers")
def test_full_qualisys_c3d_and_opensim_trc_and_the_committed_cuts_are_their_first_frames() -> None:
    qualisys = read_markers(FULL / "Qualisys.c3d")
    assert qualisys.positions.shape == (340, 55, 3) and qualisys.rate == 200.0
    assert np.isfinite(qualisys.positions).all()
    trc = read_markers(FULL / "subject01_walk1.trc")
    assert trc.positions.shape == (151, 41, 3) and trc.rate == 60.0 and trc.first_frame == 1
    assert trc.positions[0, trc.index("R.ASIS")] == pytest.approx([0.61724762, 1.05527502, 0.17078198])
    for name in ("Vicon.c3d", "Qualisys.c3d", "subject01_walk1.trc", "arm26_elbow_flex.trc"):
        full, cut = read_markers(FULL / name), read_markers(MARKERS / name)
        assert cut.labels == full.labels and cut.rate == full.rate and cut.first_frame == full.first_frame
        np.testing.assert_array_equal(cut.positions, full.positions[: len(cut.positions)])


def test_c3d_round_trip_keeps_gaps_and_first_frame(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    joints = rng.normal(size=(6, 2, 3))
    joints[2, 1] = np.nan
    write_c3d(tmp_path / "two.c3d", ["a", "b"], first_frame=7, rate=30.0, joints=joints)
    markers = read_markers(tmp_path / "two.c3d")
    assert markers.labels == ("a", "b") and markers.first_frame == 7 and markers.rate == 30.0
    assert np.isnan(markers.positions[2, 1]).all()
    assert np.allclose(markers.positions[np.isfinite(joints)], joints[np.isfinite(joints)], atol=1e-6)


def test_names_match_after_a_subject_prefix_and_errors_name_the_file(one_line_error) -> None:
    markers = read_markers(MARKERS / "Vicon.c3d")
    assert markers.index("EPICl") == markers.labels.index("Daphnee:EPICl")
    assert markers.index("Daphnee:EPICl") == markers.index("EPICl")
    message = one_line_error(lambda: markers.index("ELBOW"))
    assert "Vicon.c3d" in message and "'ELBOW'" in message and "fix the name" in message


@pytest.mark.parametrize(
    "content, fix",
    [
        (b"not a c3d file at all" * 20, "not a readable C3D file"),
        (b"", "not a readable C3D file"),
    ],
)
def test_corrupt_c3d_is_one_line(tmp_path: Path, content: bytes, fix: str, one_line_error) -> None:
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(content)
    message = one_line_error(lambda: read_markers(bad))
    assert str(bad) in message and fix in message


def test_missing_file_wrong_suffix_and_unknown_units(tmp_path: Path, one_line_error) -> None:
    assert "not found" in one_line_error(lambda: read_markers(tmp_path / "none.c3d"))
    assert "give a .c3d or .trc file" in one_line_error(lambda: read_markers(tmp_path / "walk.csv"))
    source = (MARKERS / "subject01_walk1.trc").read_text().splitlines()
    source[2] = source[2].replace("mm", "in", 1)
    inches = tmp_path / "inches.trc"
    inches.write_text("\n".join(source) + "\n")
    message = one_line_error(lambda: read_markers(inches))
    assert str(inches) in message and "'in'" in message and "mm, cm or m" in message
