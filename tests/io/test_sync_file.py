"""sync.toml (tracker.io.sync_file): the cameras' capture-time offsets written and read back, and the one-line errors
for bad files."""

import pytest

from tracker.errors import TrackerInputError
from tracker.io.sync_file import load_offsets, save_offsets

CAMERAS = ["cam0", "cam1", "cam2"]


def test_offsets_are_written_and_read_back(tmp_path):
    path = save_offsets(tmp_path / "sync.toml", {"cam0": 0.0, "cam1": 0.0210264}, {"cam0": 0.0, "cam1": 0.0008})
    assert load_offsets(path, CAMERAS, 4.0) == {"cam0": 0.0, "cam1": 0.021026, "cam2": 0.0}  # unnamed: no offset
    assert path.read_text().startswith("# Capture-time offsets")


@pytest.mark.parametrize(
    "text, message",
    [
        ("cam1 = 0.02\n", r"needs an \[offsets\] table"),
        ("[offsets]\ncam9 = 0.02\n", "names camera 'cam9', which the recording does not have"),
        ('[offsets]\ncam1 = "0.02"\n', r"the offset of cam1 is not a number of seconds \('0.02'\)"),
        ("[offsets]\ncam1 = true\n", "the offset of cam1 is not a number"),
        ("[offsets]\ncam1 = nan\n", "the offset of cam1 is not a number"),
        ("[offsets]\ncam1 = 12\n", r"as long as the recording \(4 s\) or longer; fix it \(seconds, not frames\)"),
        ("[offsets\n", "not valid TOML"),
    ],
)
def test_a_bad_sync_file_is_a_one_line_error(tmp_path, text, message):
    path = tmp_path / "sync.toml"
    path.write_text(text)
    with pytest.raises(TrackerInputError, match=message) as raised:
        load_offsets(path, CAMERAS, 4.0)
    assert str(path) in str(raised.value) and "\n" not in str(raised.value)


def test_a_missing_sync_file_names_the_command(tmp_path):
    with pytest.raises(TrackerInputError, match="run tracker sync"):
        load_offsets(tmp_path / "sync.toml", CAMERAS, 4.0)
