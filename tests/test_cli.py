"""The command line: a tracked run end to end, one-line errors with exit code 2 for bad input, and a run stopped
by a signal."""

import argparse
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from conftest import file_hashes, stopping_after

from tracker.cli import COMMANDS, build_parser, main
from tracker.evaluate import evaluate
from tracker.io.poses import load_poses


def _copy(recording: Path, tmp_path: Path) -> Path:
    target = tmp_path / "rec"
    shutil.copytree(recording, target)
    return target


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert err, "no error message"
    assert "Traceback" not in "\n".join(err)
    return err[-1]


def test_track_writes_poses_and_summary(tiny_recording, tmp_path, capsys):
    assert main(["track", str(tiny_recording), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    poses = load_poses(tmp_path / "out" / "poses.npz")
    assert poses["poses"].shape[0] == 6
    assert np.all(np.isfinite(poses["joints"]))
    out = capsys.readouterr().out
    report = evaluate(poses, load_poses(tiny_recording / "truth.npz"))
    assert float(_number(r"frames per second: ([\d.]+)", out)) > 0
    counts = [int(_number(rf"(\d+) {name}", out)) for name in ("tracked", "uncertain", "lost")]
    assert sum(counts) == 6 and counts[0] == (poses["status"] == 0).sum()
    assert _number(r"(?m)^MPJPE ([\d.]+) mm", out) == f"{report.mpjpe_mm:.1f}"
    assert _number(r"PCK@50mm ([\d.]+)%", out) == f"{100 * report.pck:.1f}"
    assert "truth.npz over frames 0..5:" in out and "not tracked" not in out
    assert sorted(_files_listed(out)) == [str(path) for path in sorted((tmp_path / "out").iterdir())]  # every one


def test_track_summary_scores_the_frames_asked_for_and_says_what_it_left_out(tiny_recording, tmp_path, capsys):
    """With --start/--frames the summary's accuracy is over those frames, as eval scores the same poses against
    the same frames of the truth, and it names the truth's frames it leaves out; the files it lists are there."""
    from tracker.io.posefile import save_pose_file
    from tracker.model import load_model

    out, first = tmp_path / "out", tmp_path / "first.toml"
    model = load_model(tiny_recording / "model.toml")
    save_pose_file(first, model, load_poses(tiny_recording / "truth.npz")["poses"][1], frame=1)
    args = ["track", str(tiny_recording), "--init", str(first), "--out", str(out), "--start", "1", "--frames", "3"]
    assert main([*args, "--quiet"]) == 0
    printed = capsys.readouterr().out
    truth = load_poses(tiny_recording / "truth.npz")
    asked = {key: truth[key][1:4] for key in ("joints", "frame")} | {"joint_names": truth["joint_names"]}
    report = evaluate(load_poses(out / "poses.npz"), asked)
    assert "over frames 1..3, the ones asked for; its other 3 frames were not tracked" in printed
    assert "tracker eval counts them as lost" in printed
    assert _number(r"frames (\d+), lost (\d+)", printed) == ("3", str(report.lost_frames))
    assert _number(r"(?m)^MPJPE ([\d.]+) mm", printed) == f"{report.mpjpe_mm:.1f}"
    assert str(out / "poses.npz") in _files_listed(printed)
    assert all(Path(path).exists() for path in _files_listed(printed))


def _files_listed(printed: str) -> list[str]:
    """The paths the summary lists under "files of this run:", in its order."""
    listed = printed.split("files of this run:\n", 1)[1]
    return [line.split()[0] for line in listed.splitlines() if line.startswith("  ")]


def test_eval_prints_report(tiny_recording, capsys):
    truth = str(tiny_recording / "truth.npz")
    assert main(["eval", truth, truth]) == 0
    out = capsys.readouterr().out
    assert _number(r"(?m)^MPJPE ([\d.]+) mm", out) == "0.0" and _number(r"PCK@50mm ([\d.]+)%", out) == "100.0"
    assert _number(r"frames (\d+), lost 0", out) == str(len(load_poses(truth)["joints"]))


def test_help_says_what_the_tracker_does(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert "3-D pose" in out and "no algorithm here" not in out


def test_tracker_alone_prints_its_help(capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["tracker"])
    assert main() == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: tracker") and "3-D pose" in out and "track" in out and "eval" in out


def test_version_is_the_installed_packages(capsys):
    from importlib.metadata import version

    import tracker

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out == f"tracker {version('tracker')}\n" == f"tracker {tracker.__version__}\n"


@pytest.mark.parametrize("name", list(COMMANDS))
def test_each_commands_help_opens_with_what_it_does_and_an_example(name, capsys):
    """After a short usage line (no list of every option), the help says what the command does in the module's
    words, then shows an example that the parser takes, before any option."""
    command = COMMANDS[name]
    with pytest.raises(SystemExit) as stop:
        main([name, "--help"])
    assert stop.value.code == 0
    usage, opening, example, options = capsys.readouterr().out.split("\n\n", 3)
    assert usage.startswith(f"usage: tracker {name} [options]") and len(usage.splitlines()) <= 2
    assert " ".join(opening.split()) == " ".join(command.ABOUT.split())
    assert example == f"example:\n  {command.EXAMPLE}" and shlex.split(command.EXAMPLE)[:2] == ["tracker", name]
    assert "--" in options
    build_parser().parse_args(shlex.split(command.EXAMPLE)[1:])


def test_track_help_groups_what_it_reads_writes_and_shows(capsys):
    with pytest.raises(SystemExit):
        main(["track", "--help"])
    sections = {}
    for block in capsys.readouterr().out.split("\n\n"):
        title, _, body = block.partition("\n")
        sections[title] = re.findall(r"(?m)^  (-[-\w]+|[A-Z]+)", body)
    assert sections["inputs:"] == ["RECORDING", "--model", "--init", "--cameras", "--calib", "--start", "--frames"]
    assert sections["outputs:"] == ["--out", "--quiet", "--overlay"]
    assert sections["viewer:"] == ["--view", "--view-rate", "--host", "--port", "--record"]


def _number(pattern: str, text: str) -> str:
    """The first group of ``pattern``'s one match in ``text`` (the test fails when it matches none or several)."""
    found = re.findall(pattern, text)
    assert len(found) == 1, (pattern, found)
    return found[0]


def _bad_case(name: str, rec: Path) -> tuple[list[str], str]:
    """Break a copy of the recording one way; return the extra CLI args and the file the error must name."""
    if name == "missing calibration":
        (rec / "calibration.toml").unlink()
        return [], "calibration.toml"
    if name == "missing video":
        (rec / "cam1.avi").unlink()
        return ["--cameras", "cam0,cam1"], "cam1"
    if name == "different frame counts":
        import cv2

        src = cv2.VideoCapture(str(rec / "cam1.avi"))
        frames = []
        while True:
            ok, frame = src.read()
            if not ok:
                break
            frames.append(frame)
        src.release()
        h, w = frames[0].shape[:2]
        writer = cv2.VideoWriter(str(rec / "cam1.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (w, h))
        for frame in frames[:-2]:
            writer.write(frame)
        writer.release()
        return [], "cam1.avi"
    if name == "model with a cycle":
        text = (
            (rec / "model.toml")
            .read_text()
            .replace('name = "torso"\nparent = "pelvis"', 'name = "torso"\nparent = "head"')
        )
        (rec / "model.toml").write_text(text)
        return [], "model.toml"
    if name == "unknown parent":
        text = (rec / "model.toml").read_text().replace('parent = "torso"', 'parent = "chest"', 1)
        (rec / "model.toml").write_text(text)
        return [], "model.toml"
    if name == "init names an unknown component":
        with open(rec / "init.toml", "a") as f:
            f.write("\n[pose.tail]\nrotation = [0.0, 0.0, 0.0]\n")
        return [], "init.toml"
    if name == "lens model with six coefficients":
        document = tomllib.loads((rec / "calibration.toml").read_text())
        document["cam_0"]["distortions"] = [0.0] * 6  # OpenCV has no such model
        (rec / "calibration.toml").write_text(tomli_w.dumps(document))
        return [], "calibration.toml"
    if name == "sync offset not a number":
        (rec / "sync.toml").write_text('[offsets]\ncam1 = "late"\n')
        return [], "sync.toml"
    if name == "sync offset longer than the recording":
        (rec / "sync.toml").write_text("[offsets]\ncam1 = 60.0\n")
        return [], "sync.toml"
    if name == "timestamps of an unknown camera":
        (rec / "timestamps.csv").write_text("frame,cam0,cam7\n" + "".join(f"{k},{k / 30},{k / 30}\n" for k in range(6)))
        return [], "timestamps.csv"
    if name == "timestamps going backwards":
        rows = "".join(f"{k},{k / 30},{(5 - k) / 30}\n" for k in range(6))
        (rec / "timestamps.csv").write_text("frame,cam0,cam1\n" + rows)
        return [], "timestamps.csv"
    if name == "corrupt video":
        (rec / "cam0.avi").write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
        return [], "cam0.avi"
    raise AssertionError(name)


@pytest.mark.parametrize(
    "case",
    [
        "missing calibration",
        "missing video",
        "different frame counts",
        "model with a cycle",
        "unknown parent",
        "init names an unknown component",
        "corrupt video",
        "lens model with six coefficients",
        "sync offset not a number",
        "sync offset longer than the recording",
        "timestamps of an unknown camera",
        "timestamps going backwards",
    ],
)
def test_bad_input_is_one_line_exit_2(case, tiny_recording, tmp_path, capsys):
    rec = _copy(tiny_recording, tmp_path)
    extra, named = _bad_case(case, rec)
    code = main(["track", str(rec), "--out", str(tmp_path / "out"), "--quiet", *extra])
    line = _error_line(capsys)
    assert code == 2
    assert line.startswith("tracker: error:") and named in line


def test_missing_recording_folder(tmp_path, capsys):
    assert main(["track", str(tmp_path / "nowhere"), "--quiet"]) == 2
    assert "nowhere" in _error_line(capsys)


def _negative_focal(rec: Path) -> None:
    document = tomllib.loads((rec / "calibration.toml").read_text())
    document["cam_0"]["matrix"][0][0] = -280.0
    (rec / "calibration.toml").write_text(tomli_w.dumps(document))


def _init_of_frame_3(rec: Path) -> None:
    text = (rec / "init.toml").read_text()
    assert text.startswith("frame = 0\n")  # tracker synth writes the frame
    (rec / "init.toml").write_text(text.replace("frame = 0\n", "frame = 3\n", 1))


EDGES = {  # a user's mistake at the edges: how to make it, the arguments after RECORDING, the line it gets
    "negative focal length": (
        _negative_focal,
        [],
        "{rec}/calibration.toml: [cam_0] 'matrix' has focal lengths fx = -280, fy = 280, not both positive; use the "
        "calibration in OpenCV's convention (x right, y down, z forward: fx, fy > 0 in pixels)",
    ),
    "camera list empty": (
        None,
        ["--cameras", ""],
        "{rec}: the list of cameras names none; pick cameras with a video from: cam0, cam1, or leave --cameras out "
        "to track them all",
    ),
    "camera list of commas": (
        None,
        ["--cameras", ","],
        "{rec}: the list of cameras names none; pick cameras with a video from: cam0, cam1, or leave --cameras out "
        "to track them all",
    ),
    "--init of another frame": (
        None,
        ["--start", "3", "--init", "{rec}/init.toml"],
        "{rec}/init.toml: is the pose at frame 0, but the run starts at frame 3; pass --start 0, or --init with a "
        "pose at frame 3, or no --init to find the first pose by itself",
    ),
    "--init of another frame, without --start": (
        _init_of_frame_3,
        ["--init", "{rec}/init.toml"],
        "{rec}/init.toml: is the pose at frame 3, but the run starts at frame 0; pass --start 3, or --init with a "
        "pose at frame 0, or no --init to find the first pose by itself",
    ),
    "the recording's init.toml of another frame, and no keypoints": (
        None,
        ["--start", "3", "--keypoints", "off"],
        "{rec}/init.toml: is the pose at frame 0, but the run starts at frame 3, where it cannot find the first pose "
        "by itself; pass --start 0, or --init with a pose at frame 3",
    ),
}


@pytest.mark.parametrize("case", list(EDGES))
def test_a_mistake_at_the_edges_is_one_line_before_anything_runs(case, tiny_recording, tmp_path, capsys):
    """Exit 2 and the one line that names the file and the fix, before any tracking: nothing written, the user's
    files as they were."""
    rec = _copy(tiny_recording, tmp_path)
    make, extra, line = EDGES[case]
    if make is not None:
        make(rec)
    before = file_hashes(rec)
    args = ["track", str(rec), "--out", str(tmp_path / "out"), "--quiet", *(arg.format(rec=rec) for arg in extra)]
    assert main(args) == 2
    assert capsys.readouterr().err.splitlines() == [f"tracker: error: {line.format(rec=rec)}"]
    assert file_hashes(rec) == before and not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", ["a camera without a video", "the recording's init.toml of another frame"])
def test_what_a_run_leaves_out_it_names_in_a_warning_and_goes_on(case, tiny_recording, tmp_path, capsys):
    """A camera of the calibration without a video, and the recording's init.toml when the run starts at another
    frame, are left out with a warning naming them; the run goes on to its next step (here a --model that is not
    there, which stops it before any tracking)."""
    rec = _copy(tiny_recording, tmp_path)
    if case == "a camera without a video":
        shutil.move(rec / "cam1.avi", tmp_path / "cam1.avi")
        extra = []
        warning = (
            f"{rec}: camera cam1 has no video, leaving cam0 of calibration.toml; add <name>.mp4|.avi|.mkv or a folder "
            "<name>/ of numbered images, or pick the cameras with --cameras to say so"
        )
    else:
        extra = ["--start", "3"]
        warning = (
            f"ignoring {rec / 'init.toml'}, the pose at frame 0: the run starts at frame 3, where it finds the first "
            "pose by itself"
        )
    before = file_hashes(rec)
    nowhere = tmp_path / "nowhere.toml"
    args = ["track", str(rec), "--model", str(nowhere), "--out", str(tmp_path / "out"), "--quiet", *extra]
    assert main(args) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"tracker: warning: {warning}",
        f"tracker: error: {nowhere}: model file not found; pass --model with an existing models/*.toml",
    ]
    assert file_hashes(rec) == before and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "option", [["--iterations", "0"], ["--spacing", "-1"], ["--damping", "2"], ["--frames", "0"], ["--work-side", "-1"]]
)
def test_bad_options_are_usage_errors(tiny_recording, option, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["track", str(tiny_recording), *option])
    assert exit_info.value.code == 2
    assert option[0] in capsys.readouterr().err


def test_unwritable_output_folder_fails_before_tracking(tiny_recording, tmp_path, capsys, monkeypatch):
    import tempfile

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "TemporaryFile", denied)
    assert main(["track", str(tiny_recording), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    line = _error_line(capsys)
    assert "cannot write there (Permission denied)" in line and "out" in line


def test_disk_full_mid_run_keeps_the_frames_already_saved(tmp_path, capsys, monkeypatch):
    import errno
    import os

    from tracker import atomic
    from tracker.io.poses import load_poses

    demo = Path(__file__).resolve().parents[1] / "recordings" / "demo"
    calls = {"n": 0}
    real_fsync = os.fsync

    def fsync(fd):
        calls["n"] += 1
        if calls["n"] > 1:  # the first save (25 frames) lands, then the disk is full
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    assert main(["track", str(demo), "--out", str(tmp_path), "--frames", "60", "--quiet"]) == 2
    assert "No space left on device" in _error_line(capsys)
    assert list(load_poses(tmp_path / "poses.npz")["frame"]) == list(range(25))
    assert [p.name for p in tmp_path.iterdir()] == ["poses.npz"]  # no temporary file left behind


def test_a_start_beyond_the_recording_leaves_earlier_results_alone(tiny_recording, tmp_path, capsys):
    assert main(["track", str(tiny_recording), "--out", str(tmp_path), "--quiet"]) == 0
    before = (tmp_path / "poses.npz").read_bytes()
    assert main(["track", str(tiny_recording), "--out", str(tmp_path), "--start", "6", "--quiet"]) == 2
    assert "--start 6 is outside its frames 0..5" in _error_line(capsys)
    assert (tmp_path / "poses.npz").read_bytes() == before


def test_a_port_out_of_range_is_a_usage_error(tiny_recording, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["view", str(tiny_recording), "--port", "70000"])
    assert exit_info.value.code == 2 and "0-65535" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, prog, said",
    [
        (["track", "rec", "--port", "abc"], "tracker track", "argument --port: invalid port value: 'abc'"),
        (["track"], "tracker track", "the following arguments are required: RECORDING"),
        (["track", "rec", "--bogus"], "tracker track", "unrecognized arguments: --bogus"),
        (["--bogus", "eval", "a", "b"], "tracker", "unrecognized arguments: --bogus"),
        (["bogus"], "tracker", "argument COMMAND: invalid choice: 'bogus'"),
        (["suite", "run", "renders"], "tracker suite run", "the following arguments are required: results"),
        (["track", "rec", "--init", ""], "tracker track", "argument --init: '' names no file or folder"),
        (["sync", "rec", "--refine", "--init", ""], "tracker sync", "argument --init: '' names no file or folder"),
        (["export", "p.npz", "--to", "csv", "--out", ""], "tracker export", "argument --out: '' names no file"),
        (["view", "rec", "--poses", ""], "tracker view", "argument --poses: '' names no file or folder"),
    ],
)
def test_a_usage_error_is_one_line_that_points_to_the_help(argv, prog, said, capsys):
    """The parser of the command (or of the tracker) that the mistake is in says it in one line, without the usage
    that --help shows, and exits with 2."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    printed = capsys.readouterr()
    assert printed.out == "" and len(printed.err.splitlines()) == 1
    assert printed.err.startswith(f"{prog}: error: {said}") and printed.err.endswith(f"; see {prog} --help\n")


@pytest.mark.parametrize("option", [["--dynamics", "kalman"], ["--motion", "none"]])
def test_motion_models_from_the_command_line(tiny_recording, tmp_path, option, capsys):
    """--dynamics picks the motion model; the old name --motion (which names the clip in synth) still works,
    with a warning, and is not in --help."""
    from tracker.io.poses import load_poses

    assert main(["track", str(tiny_recording), "--out", str(tmp_path), "--quiet", *option]) == 0
    assert len(load_poses(tmp_path / "poses.npz")["frame"]) == 6
    warned = "--motion is now --dynamics" in capsys.readouterr().err
    assert warned == (option[0] == "--motion")
    with pytest.raises(SystemExit):
        main(["track", "--help"])
    shown = capsys.readouterr().out
    assert "--dynamics" in shown and "--motion" not in shown


def test_work_side_sets_the_search_reduction():
    """--work-side reaches the tracker's settings (0: full size); without it the default stands."""
    from tracker.commands import options
    from tracker.tracking.settings import Settings

    parser = argparse.ArgumentParser()
    options.add_tuning_options(parser)
    assert options.settings_from(parser.parse_args(["--work-side", "0"])).images.work_side == 0
    assert options.settings_from(parser.parse_args([])).images.work_side == Settings().images.work_side == 480


def test_output_cut_short_ends_quietly(tiny_recording):
    """``tracker ... | head``: the reader goes away mid-output; exit 141 as a shell reports it, no traceback."""
    code = (
        "import sys; from tracker.cli import COMMANDS, build_parser, main\n"
        "import tracker.commands.evaluate as e\n"
        "def run(args):\n"
        "    while True: print('row ' * 100)\n"
        "e.run = run\n"
        f"sys.exit(main(['eval', {str(tiny_recording / 'truth.npz')!r}, {str(tiny_recording / 'truth.npz')!r}]))\n"
    )
    process = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert process.stdout is not None and process.stdout.readline().startswith(b"row")
    process.stdout.close()  # as head does after its lines
    _, err = process.communicate(timeout=60)
    assert process.returncode == 141 and b"Traceback" not in err and b"Exception ignored" not in err, err


def test_sigterm_mid_run_keeps_every_frame_done(tmp_path, capsys, monkeypatch):
    """``timeout``, systemd and Docker stop a run with SIGTERM: the demo's frames 0-3 done (and the detections the
    tracker took, frames 0 and 4), exit 143 as a shell reports SIGTERM, one line saying so, and the handler the
    process had before is back."""
    from tracker.landmarks.store import load_keypoints

    demo = Path(__file__).resolve().parents[1] / "recordings" / "demo"
    monkeypatch.setattr("tracker.commands.options.bar", stopping_after(3, signal.SIGTERM))
    before, given = signal.getsignal(signal.SIGTERM), file_hashes(demo)
    assert main(["track", str(demo), "--out", str(tmp_path), "--frames", "8", "--quiet"]) == 143
    assert file_hashes(demo) == given
    assert signal.getsignal(signal.SIGTERM) is before
    printed = capsys.readouterr()
    assert f"wrote {tmp_path / 'poses.npz'} (4 frames)" in printed.out
    lines = printed.err.strip().splitlines()
    assert lines[-1] == "tracker: interrupted: the frames done so far are saved"
    assert sum("interrupted" in line or "warning" in line or "Traceback" in line for line in lines) == 1
    assert list(load_poses(tmp_path / "poses.npz")["frame"]) == [0, 1, 2, 3]
    assert {0, 4} <= set(load_keypoints(tmp_path / "keypoints.npz").frame)


@pytest.mark.parametrize(("number", "code"), [(signal.SIGHUP, 129), (signal.SIGTERM, 143)])
def test_a_stop_signal_reaching_the_command_line_is_one_line(number, code, tiny_recording, capsys, monkeypatch):
    """A stop signal that no command catches (here while ``tracker eval`` runs) ends the run as Ctrl-C would."""
    import tracker.commands.evaluate as command

    def stopped(args):
        os.kill(os.getpid(), number)
        raise AssertionError("the signal did not stop the run")

    monkeypatch.setattr(command, "run", stopped)
    truth, before = str(tiny_recording / "truth.npz"), signal.getsignal(number)
    assert main(["eval", truth, truth]) == code
    assert capsys.readouterr().err == "tracker: interrupted\n"
    assert signal.getsignal(number) is before
