"""The options several commands share (tracker.commands.options): the tuning options, built from the settings'
fields, one group per settings group, each flag's help ending with the field's default, and parsed back into the
settings; ``--cache``, the keypoints' folder of the commands whose ``--out`` is a file."""

import argparse
import dataclasses
from pathlib import Path

import pytest
from conftest import file_hashes

from tracker.cli import main
from tracker.commands import options
from tracker.errors import TrackerInputError
from tracker.landmarks import detect_recording
from tracker.tracking.settings import Settings

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"


def _parser(which=None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="t")
    options.add_tuning_options(parser, which)
    return parser


def test_every_flagged_field_is_an_option_in_its_groups_section_with_its_default():
    parser = _parser()
    fields = options.tuning_fields()
    assert {"--iterations", "--spacing", "--dynamics", "--region", "--work-side"} <= set(fields)
    titles = {group.title: group for group in parser._action_groups}
    for flag, (group, spec) in fields.items():
        section = titles[f"tuning: {type(getattr(Settings(), group)).__doc__.strip()}"]
        action = next(a for a in section._group_actions if flag in a.option_strings)
        default = getattr(getattr(Settings(), group), spec.name)
        assert action.help.startswith(spec.metadata["help"]), flag
        assert action.help.endswith(f"(default {options._shown(default)})"), flag


def test_given_options_change_their_fields_and_no_other():
    parser = _parser()
    given = options.settings_from(
        parser.parse_args(["--iterations", "3", "--region", "off", "--dynamics", "kalman", "--max-turn", "0.2"]), 30.0
    )
    expected = Settings().but(
        solve=dict(iterations=3, max_turn=0.2), region=dict(on=False), motion=dict(dynamics="kalman", frame_rate=30.0)
    )
    assert given == expected
    assert options.settings_from(parser.parse_args([])) == Settings()


def test_a_command_offers_the_flags_it_names_and_refuses_bad_values(capsys):
    parser = _parser(("--spacing", "--damping"))
    assert options.settings_from(parser.parse_args(["--spacing", "6"])).outline.spacing == 6.0
    for bad, said in (
        (["--iterations", "3"], "unrecognized"),
        (["--damping", "2"], "between 0 and 1"),
        (["--spacing", "-1"], "positive number"),
    ):
        with pytest.raises(SystemExit):
            parser.parse_args(bad)
        assert said in capsys.readouterr().err


def test_the_old_motion_flag_still_sets_the_dynamics_with_a_warning(capsys):
    args = _parser().parse_args(["--motion", "none"])
    assert options.settings_from(args).motion.dynamics == "none"
    assert "--motion is now --dynamics" in capsys.readouterr().err


def test_the_shown_defaults_read_as_a_user_would_type_them():
    assert [options._shown(value) for value in (True, False, float("inf"), 0.6, 1e3, 480, "kalman")] == [
        "on",
        "off",
        "none",
        "0.6",
        "1000",
        "480",
        "kalman",
    ]
    assert all(dataclasses.is_dataclass(group) for group in vars(Settings()).values())


def test_the_table_of_tuning_options_in_the_docs_shows_the_settings_defaults():
    """docs/commands.md's table of `tracker track`'s tuning options: each flag the settings give is a row, and its
    default cell is the settings' default as the help shows it."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "commands.md").read_text()
    rows = {}
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.replace("\\|", "/").strip().strip("|").split("|")]
        if line.startswith("| `--") and len(cells) >= 3:
            rows[cells[0].strip("`").split()[0]] = cells[1].strip("`")
    for flag, (group, spec) in options.tuning_fields().items():
        assert flag in rows, flag
        assert rows[flag] == options._shown(getattr(getattr(Settings(), group), spec.name)), flag


@pytest.mark.parametrize("command", ["fit-model", "init"])
def test_the_cache_option_chooses_where_the_keypoints_are_kept(command, tmp_path, monkeypatch, capsys):
    """fit-model and init, whose --out is a file, keep the detector's keypoints in --cache DIR, by default
    out/<recording name>, where a pick of the cameras has a file of its own: `fit-model REC --cameras cam1,cam2`
    then `fit-model REC` keep both.  Each run here stops at the file it chose, before detecting."""
    rec = tmp_path / "demo"  # the demo without its init.toml, so that init fits the first pose to the keypoints
    rec.mkdir()
    for file in DEMO.iterdir():
        if file.name != "init.toml":
            (rec / file.name).symlink_to(file)
    chosen = []
    cache_file = detect_recording.cache_file

    def stop(folder, recording):
        chosen.append(cache_file(folder, recording))
        raise TrackerInputError("stopped where the keypoints would be kept")

    monkeypatch.setattr(detect_recording, "cache_file", stop)
    monkeypatch.chdir(tmp_path)
    given = file_hashes(DEMO)
    for extra in (["--cameras", "cam1,cam2"], [], ["--cache", str(tmp_path / "kp")]):
        assert main([command, str(rec), "--out", str(tmp_path / "out.toml"), *extra]) == 2
        assert capsys.readouterr().err == "tracker: error: stopped where the keypoints would be kept\n"
    kept = [Path("out/demo/keypoints-cam1,cam2.npz"), Path("out/demo/keypoints.npz"), tmp_path / "kp" / "keypoints.npz"]
    assert chosen == kept and (tmp_path / "kp").is_dir()
    assert file_hashes(DEMO) == given


def test_a_list_of_names_that_names_none_is_empty_not_absent():
    """``--cameras ""`` and ``--cameras ","`` name no camera (open_recording refuses that), where leaving the option
    out means every camera."""
    assert options.camera_names(None) is None
    assert options.camera_names("") == options.camera_names(",") == options.camera_names(" , ,") == []
    assert options.camera_names("cam0, cam2,") == ["cam0", "cam2"]
