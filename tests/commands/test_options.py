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

    def stop(folder, recording, landmark_model):
        chosen.append(cache_file(folder, recording, landmark_model))
        raise TrackerInputError("stopped where the keypoints would be kept")

    monkeypatch.setattr(detect_recording, "cache_file", stop)
    monkeypatch.chdir(tmp_path)
    given = file_hashes(DEMO)
    for extra in (["--cameras", "cam1,cam2"], [], ["--cache", str(tmp_path / "kp")]):
        assert main([command, str(rec), "--out", str(tmp_path / "out.toml"), *extra]) == 2
        said = capsys.readouterr().err.splitlines()
        assert said[-1] == "tracker: error: stopped where the keypoints would be kept"
    kept = [Path("out/demo/keypoints-cam1,cam2.npz"), Path("out/demo/keypoints.npz"), tmp_path / "kp" / "keypoints.npz"]
    assert chosen == kept and (tmp_path / "kp").is_dir()
    assert file_hashes(DEMO) == given


def test_a_list_of_names_that_names_none_is_empty_not_absent():
    """``--cameras ""`` and ``--cameras ","`` name no camera (open_recording refuses that), where leaving the option
    out means every camera."""
    assert options.camera_names(None) is None
    assert options.camera_names("") == options.camera_names(",") == options.camera_names(" , ,") == []
    assert options.camera_names("cam0, cam2,") == ["cam0", "cam2"]


def _subparser(command: str) -> argparse.ArgumentParser:
    from tracker.cli import build_parser

    parser = build_parser()
    commands = next(action for action in parser._actions if isinstance(action, argparse._SubParsersAction))
    return commands.choices[command]


@pytest.mark.parametrize("command", ["track", "batch", "keypoints", "fit-model", "sync", "init", "bench", "live"])
def test_every_command_that_detects_takes_the_landmark_model_with_its_default(command):
    """One option, the same choices and help everywhere; the most accurate model for recorded folders, the live one
    for cameras."""
    from tracker.landmarks.landmark_models import LIVE, MODELS, RECORDED

    action = next(a for a in _subparser(command)._actions if "--landmark-model" in a.option_strings)
    assert tuple(action.choices) == MODELS
    assert action.default == (LIVE if command == "live" else RECORDED)
    assert action.help.endswith(f"(default {action.default})")


def _named(folder: Path, source: Path) -> Path:
    """A recording folder ``folder`` whose files are links to those of ``source``."""
    folder.mkdir(parents=True)
    for file in source.iterdir():
        (folder / file.name).symlink_to(file)
    return folder


def test_two_recordings_of_the_same_name_get_their_own_default_output_folder(tmp_path, monkeypatch, capsys):
    """a/rec, then b/rec: the first gets out/rec, which remembers it (out/rec/recording.txt), the second
    out/rec-<the first 8 hex digits of the SHA-1 of its resolved path>; each again gets its own, and a command that
    only reads finds the same folder without writing one."""
    import hashlib
    from types import SimpleNamespace

    monkeypatch.chdir(tmp_path)
    first, second = SimpleNamespace(path=tmp_path / "a" / "rec"), SimpleNamespace(path=Path("b/rec"))
    assert options.output_folder("given", first) == Path("given")  # --out: taken as it is, nothing written
    assert not Path("out").exists() and capsys.readouterr().err == ""
    assert options.output_folder(None, first, claim=False) == Path("out/rec") and not Path("out").exists()
    assert options.output_folder(None, first) == Path("out/rec")
    assert Path("out/rec/recording.txt").read_text() == f"{tmp_path / 'a' / 'rec'}\n"
    assert capsys.readouterr().err == "output folder: out/rec\n"
    digest = hashlib.sha1(str(tmp_path / "b" / "rec").encode()).hexdigest()[:8]
    assert options.output_folder(None, second, claim=False) == Path(f"out/rec-{digest}")
    assert not Path(f"out/rec-{digest}").exists()
    assert options.output_folder(None, second) == Path(f"out/rec-{digest}")
    assert capsys.readouterr().err == f"output folder: out/rec-{digest} (out/rec holds {tmp_path / 'a' / 'rec'})\n"
    assert Path(f"out/rec-{digest}/recording.txt").read_text() == f"{tmp_path / 'b' / 'rec'}\n"
    for rec, folder in ((first, "out/rec"), (second, f"out/rec-{digest}"), (first, "out/rec")):
        assert options.output_folder(None, rec) == Path(folder)
    assert sorted(path.name for path in Path("out").iterdir()) == ["rec", f"rec-{digest}"]


def test_keypoints_of_two_recordings_of_the_same_name_keep_apart(tiny_recording, tmp_path, monkeypatch):
    """`tracker keypoints a/rec` then `tracker keypoints b/rec` (another recording in a folder of the same name): the
    second detects into its own folder, where it stopped at the first's cache before."""
    monkeypatch.chdir(tmp_path)
    a, b = _named(tmp_path / "a" / "rec", DEMO), _named(tmp_path / "b" / "rec", tiny_recording)
    for rec in (a, b, a):
        assert main(["keypoints", str(rec), "--frames", "1", "--quiet", "--landmark-model", "full"]) == 0
    folders = {path.name: path.joinpath("recording.txt").read_text().strip() for path in Path("out").iterdir()}
    assert len(folders) == 2 and folders["rec"] == str(a) and str(b) in folders.values()
    for folder in Path("out").iterdir():
        assert [path.name for path in folder.glob("keypoints*.npz")] == ["keypoints-full.npz"]
