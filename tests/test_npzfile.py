""".npz archives read with one-line errors (tracker/npzfile.py): a file that is no archive is called what it is, never
pickled data, and the message names the fix."""

from __future__ import annotations

import io

import numpy as np
import pytest
from conftest import file_hashes

from tracker.cli import main
from tracker.npzfile import read_npz


def _npy() -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(3))
    return buffer.getvalue()


@pytest.mark.parametrize(
    "content, kind",
    [
        (b"frame,a_x,a_y,a_z\n0,0.1,0.2,0.3\n", "text"),
        (b"", "an empty file"),
        (_npy(), "a single .npy array"),
        (b"\x00\x01\x02binary", "a file of another kind"),
    ],
    ids=["text", "empty", "npy", "binary"],
)
def test_a_file_that_is_no_archive_is_called_what_it_is(tmp_path, one_line_error, content, kind):
    path = tmp_path / "poses.npz"
    path.write_bytes(content)
    message = one_line_error(lambda: read_npz(path, "a poses file", "give a poses.npz"))
    assert message == f"{path}: not a poses file (an .npz archive) but {kind}; give a poses.npz"


def test_archives_that_cannot_be_read(tmp_path, one_line_error):
    good = tmp_path / "good.npz"
    np.savez(good, joints=np.zeros((2, 1, 3)))
    assert read_npz(good, "a poses file", "fix")["joints"].shape == (2, 1, 3)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:100])
    assert one_line_error(lambda: read_npz(cut, "a poses file", "fix")).startswith(f"{cut}: not a readable .npz")
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, names=np.array(["a"], dtype=object))
    message = one_line_error(lambda: read_npz(pickled, "a poses file", "fix"))
    assert message.startswith(f"{pickled}: holds object arrays") and "np.array(names, dtype=str)" in message
    assert message.endswith("); fix")
    assert (
        one_line_error(lambda: read_npz(tmp_path, "a poses file", "fix"))
        == f"{tmp_path}: is a folder, not a poses file; fix"
    )
    gone = tmp_path / "gone.npz"
    assert one_line_error(lambda: read_npz(gone, "a poses file", "fix")) == f"{gone}: file not found; check the path"


def test_eval_of_a_text_file_says_it_is_not_a_poses_file(small_poses, capsys):
    text = small_poses.parent / "poses.csv"
    text.write_text("frame,a_x,a_y,a_z\n0,0.1,0.2,0.3\n")
    before = file_hashes(small_poses.parent)
    assert main(["eval", str(text), str(small_poses)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        f"tracker: error: {text}: not a poses or truth file (an .npz archive) but text; give the poses.npz that "
        "tracker track wrote, or a truth.npz"
    ]
    assert file_hashes(small_poses.parent) == before
