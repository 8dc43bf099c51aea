"""``tracker batch`` on a local two-worker Ray: the same results as ``tracker track`` alone, a bad folder reported
while the others finish, a killed worker's recording tried again, an interrupted batch resumed without redoing
anything (and, with Ray stood in for, a stop that keeps every row already in, the detections of the recordings it
tracks again and no temporary file, also when the terminal closed); and one-line errors without Ray, for other
options, and for a folder that is not the batch's."""

import csv
import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import HUMAN, closing_terminal, file_hashes

from tracker.camera import look_at_camera, save_calibration
from tracker.cli import main
from tracker.commands.batch import jobs, matched
from tracker.synthetic.synth import synthesize

pytest.importorskip("ray", reason="tracker batch needs Ray: pip install -e '.[cluster]'")


@pytest.fixture(scope="session")
def recordings(tmp_path_factory) -> list[Path]:
    """Four small two-camera renderings (8 frames each, the first 300) and a folder without a calibration."""
    folder = tmp_path_factory.mktemp("batch")
    rig = [
        look_at_camera("cam0", (0.5, -3.5, 1.3), (0.0, 0.0, 0.9), size=(320, 240), focal=280.0),
        look_at_camera("cam1", (3.3, 0.8, 1.6), (0.0, 0.0, 0.9), size=(320, 240), focal=280.0),
    ]
    save_calibration(rig, folder / "rig.toml")
    made = []
    for seed, frames in zip((11, 12, 13, 14), (300, 8, 8, 8)):
        made.append(folder / "trials" / f"trial{seed}")
        synthesize(HUMAN, folder / "rig.toml", made[-1], motion="procedural", frames=frames, seed=seed)
    return made


@pytest.fixture
def with_bad(recordings, tmp_path) -> list[Path]:
    """The three 8-frame renderings and, among them, a folder with a video but no calibration (the 300-frame one is
    for the tests that act while it is tracked, which compare it with ``tracker track`` alone too)."""
    bad = recordings[0].parent / "trial00-uncalibrated"
    bad.mkdir(exist_ok=True)
    (bad / "cam0.avi").write_bytes((recordings[1] / "cam0.avi").read_bytes())
    return [bad, *recordings[1:]]


def _tracked_alone(recording: Path, out: Path, *options: str) -> Path:
    assert main(["track", str(recording), "--out", str(out), "--quiet", *options]) == 0
    return out


def _same_results(alone: Path, batched: Path) -> None:
    """Every file ``tracker track`` wrote alone is in the batch's folder with the same bytes; in poses.npz, every
    array but ``elapsed`` (the seconds each frame took, which no two runs share)."""
    assert sorted(path.name for path in alone.iterdir()) == sorted(
        path.name for path in batched.iterdir() if path.name != "track.log"
    )
    for path in alone.iterdir():
        if path.name != "poses.npz":
            assert path.read_bytes() == (batched / path.name).read_bytes(), path.name
    with np.load(alone / "poses.npz") as one, np.load(batched / "poses.npz") as other:
        assert one.files == other.files
        for key in one.files:
            if key != "elapsed":
                assert one[key].tobytes() == other[key].tobytes(), key


def _states(out: Path) -> dict[str, str]:
    """Each recording's state in the batch's manifest, by its folder's name."""
    recordings = json.loads((out / "manifest.json").read_text())["recordings"]
    return {Path(path).name: entry["state"] for path, entry in recordings.items()}


def _summary(out: Path) -> dict[str, dict]:
    with open(out / "summary.csv", newline="") as file:
        return {row["name"]: row for row in csv.DictReader(file)}


def test_batch_gives_what_track_gives_alone_and_reports_a_bad_folder(with_bad, tmp_path, capsys):
    out = tmp_path / "batch"
    assert main(["batch", *map(str, with_bad), "--out", str(out), "--workers", "2", "--quiet"]) == 1
    printed = capsys.readouterr()
    summary = _summary(out)
    assert list(summary) == [path.name for path in with_bad]
    bad = summary["trial00-uncalibrated"]
    assert bad["state"] == "failed" and bad["attempts"] == "1"
    assert "calibration.toml" in bad["error"] and "\n" not in bad["error"]
    assert bad["error"] in printed.out
    assert "1 of 4 recordings failed" in printed.err
    for recording in with_bad[1:]:
        row = summary[recording.name]
        assert row["state"] == "done" and row["error"] == ""
        alone = _tracked_alone(recording, tmp_path / "alone" / recording.name)
        with np.load(alone / "poses.npz") as poses:
            assert int(row["frames"]) == len(poses["frame"])
            assert int(row["lost"]) == int((poses["status"] == 2).sum())
            assert float(row["residual_px"]) == pytest.approx(np.nanmean(poses["residual"]), rel=1e-9)
        assert np.isfinite(float(row["mpjpe_mm"]))  # each rendering has its truth.npz
        _same_results(alone, out / recording.name)


# Edges only, and many iterations: the 300-frame recording then takes seconds to track, so that it is still being
# tracked when an 8-frame one finishes, however slow the machine is to pass that news on (the tests below act then);
# frame by frame, which spares them the time of a backward pass.
SLOW = ("--keypoints", "off", "--iterations", "40", "--smooth", "none")


def _batch(recordings: list[Path], out: Path) -> subprocess.Popen:
    """``tracker batch`` in a process of its own, on two local workers, with :data:`SLOW`; its output read line by
    line."""
    command = [sys.executable, "-m", "tracker.cli", "batch", *map(str, recordings), "--out", str(out)]
    command += ["--workers", "2", "--quiet", *SLOW]
    env = {key: value for key, value in os.environ.items() if key != "PYTHONUNBUFFERED"}  # lines must come as made
    env["OPENBLAS_NUM_THREADS"] = "1"
    return subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=_interruptible,  # noqa: PLW1509 (one signal call, before exec)
    )


def _interruptible() -> None:
    """In the batch's process before it starts: Ctrl-C at its default, so that Python raises KeyboardInterrupt on
    it.  An ignored SIGINT is inherited across exec, and Python then leaves it ignored; in a full test run something
    before these tests leaves the test process ignoring it, and the batch then ran to its end through the SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _first_finished(batch: subprocess.Popen) -> str:
    """Read the batch's output up to the first recording it finishes; that line."""
    assert batch.stdout is not None
    for line in batch.stdout:
        if line.startswith("done "):
            return line
    raise AssertionError(f"the batch finished nothing: {batch.communicate()}")


def _descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (Linux: from /proc)."""
    parent = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parent[int(entry.name)] = int(stat[stat.rindex(")") + 2 :].split()[1])
    found, frontier = [], [pid]
    while frontier:
        children = [child for child, up in parent.items() if up in frontier]
        found += children
        frontier = children
    return found


def _worker_tracking(pid: int, log: Path) -> int:
    """The Ray worker below ``pid`` that has the ``track.log`` of a recording open: the one tracking it."""
    for child in _descendants(pid):
        try:
            opened = [os.readlink(link) for link in Path(f"/proc/{child}/fd").iterdir()]
        except OSError:
            continue
        if str(log) in opened:
            return child
    raise AssertionError(f"no process is writing {log}")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds Ray's worker processes in /proc (Linux)")
def test_a_killed_worker_is_tried_again_and_nothing_is_lost(recordings, tmp_path):
    out = tmp_path / "batch"
    batch = _batch(recordings, out)
    _first_finished(batch)  # an 8-frame one: the 300-frame recording is still being tracked
    os.kill(_worker_tracking(batch.pid, out / recordings[0].name / "track.log"), signal.SIGKILL)
    printed, errors = batch.communicate(timeout=600)
    assert batch.returncode == 0, errors
    assert "crashed" in errors and "trying again" in errors
    summary = _summary(out)
    assert all(row["state"] == "done" for row in summary.values())
    assert [row["attempts"] for row in summary.values()] == ["2", "1", "1", "1"]
    _same_results(_tracked_alone(recordings[0], tmp_path / "alone", *SLOW), out / recordings[0].name)
    kept = {path.name: (out / path.name / "poses.npz").stat().st_mtime_ns for path in recordings}

    again = _batch(recordings, out)  # resumed: everything is finished, nothing is tracked again
    printed, errors = again.communicate(timeout=600)
    assert again.returncode == 0, errors
    assert "resuming: 4 of 4 recordings finished before" in errors
    assert not [line for line in printed.splitlines() if line.startswith("done ")]
    assert {path.name: (out / path.name / "poses.npz").stat().st_mtime_ns for path in recordings} == kept
    assert _summary(out) == summary


def test_an_interrupted_batch_resumes_without_redoing_what_was_finished(recordings, tmp_path):
    """SIGTERM (``timeout``, a job scheduler) to the batch as it tracks: exit 143, no temporary file left behind (Ray
    ends the tasks still running, perhaps amid a write), and run again it tracks only what had not finished."""
    out = tmp_path / "batch"
    batch = _batch(recordings, out)
    _first_finished(batch)
    batch.send_signal(signal.SIGTERM)
    printed, errors = batch.communicate(timeout=600)
    assert batch.returncode == 143, errors
    assert "run the same command again to resume" in errors
    assert not [path for path in out.rglob("*") if ".tmp" in path.name]
    states = _states(out)
    finished = sorted(name for name, state in states.items() if state == "done")
    assert finished and len(finished) < len(recordings)
    kept = {name: (out / name / "poses.npz").stat().st_mtime_ns for name in finished}

    again = _batch(recordings, out)
    printed, errors = again.communicate(timeout=600)
    assert again.returncode == 0, errors
    assert f"resuming: {len(finished)} of {len(recordings)} recordings finished before" in errors
    tracked_now = sorted(line.split()[1].rstrip(":") for line in printed.splitlines() if line.startswith("done "))
    assert tracked_now == sorted(set(states) - set(finished))  # each recording tracked once in all
    assert {name: (out / name / "poses.npz").stat().st_mtime_ns for name in finished} == kept
    summary = _summary(out)
    assert sorted(summary) == sorted(path.name for path in recordings)
    assert all(row["state"] == "done" for row in summary.values())
    for recording in recordings:
        with np.load(out / recording.name / "poses.npz") as poses, np.load(recording / "truth.npz") as truth:
            assert len(poses["frame"]) == len(truth["frame"])


class _Ray:
    """Ray as ``tracker batch`` uses it, without Ray: each task of a recording named in ``finishing`` returns its row,
    but the first try of one in ``crashing``, which crashes, and the others never finish; a task that does not finish
    leaves in its folder what a stopped ``tracker track`` leaves (its log, the detections it saved, and the temporary
    file of a poses.npz it was writing, as Ray ending it mid-write would).  ``ray.wait`` hands out the replies one by
    one.  The ``stop_at``-th call of ``stop_in`` (its ``wait`` or its
    ``get``) sends this process the signal ``stop`` first, and ``hung_up``, if given, is called then (the terminal
    closed).  ``init`` sets a SIGTERM handler that exits at once, as ray.init does.  ``found`` holds what each task
    found in its folder when it was submitted."""

    class exceptions:
        RayError = RuntimeError

    def __init__(
        self,
        finishing: set[str],
        *,
        crashing: frozenset[str] = frozenset(),
        stop: int = 0,
        stop_in: str = "wait",
        stop_at: int = 0,
        hung_up=None,
    ):
        self.finishing, self.crashing = finishing, crashing
        self.stop, self.stop_in, self.stop_at, self.hung_up = stop, stop_in, stop_at, hung_up
        self.submitted: list[str] = []
        self.found: dict[str, list[str]] = {}
        self.calls = {"wait": 0, "get": 0}

    def init(self, **options) -> None:
        signal.signal(signal.SIGTERM, lambda number, frame: sys.exit(number))

    def shutdown(self) -> None:
        pass

    def remote(self, **options):
        return lambda function: SimpleNamespace(remote=self.submit)

    def _called(self, name: str) -> None:
        self.calls[name] += 1
        if name == self.stop_in and self.calls[name] == self.stop_at:
            if self.hung_up is not None:
                self.hung_up()
            os.kill(os.getpid(), self.stop)

    def get(self, ref):
        from tracker.io.batch_records import DONE, Row

        self._called("get")
        recording, name = ref
        if name in self.crashing and self.submitted.count(name) == 1:
            raise RuntimeError("the worker died")
        return Row(recording, name, DONE, frames=8, fps=30.0, residual_px=0.5, lost=0, mpjpe_mm=9.0, seconds=1.0)

    def wait(self, refs, num_returns=1, timeout=None):
        ready = [ref for ref in refs if ref[1] in self.finishing]
        if timeout == 0:  # the replies in already
            return ready, [ref for ref in refs if ref not in ready]
        self._called("wait")
        return ready[:1], [ref for ref in refs if ref not in ready[:1]]

    def submit(self, recording: str, name: str, out: str, *, chosen: dict):
        """``task.remote(...)``: the task of one recording, which writes in its folder ``out``."""
        self.submitted.append(name)
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
        first = name not in self.found
        self.found[name] = sorted(path.name for path in folder.iterdir())
        if name not in self.finishing or (name in self.crashing and first):
            for file in ("track.log", "keypoints.npz", f".poses.{os.getpid()}.0123abcd.tmp.npz"):
                (folder / file).write_text(name)
        return (recording, name)


def _three(tmp_path: Path) -> tuple[list[str], Path]:
    """``tracker batch`` of three recording folders r1, r2 and r3 on two workers, and its output folder."""
    for name in ("r1", "r2", "r3"):
        (tmp_path / name).mkdir()
    out = tmp_path / "out"
    return ["batch", *(str(tmp_path / name) for name in ("r1", "r2", "r3")), "--out", str(out), "--workers", "2"], out


@pytest.mark.parametrize(("stop", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_stopped_batch_keeps_what_finished_and_no_temporary_file(stop, code, tmp_path, monkeypatch, capsys):
    """Three recordings on two workers: r1 finishes, r3 is submitted, and the stop comes while the batch waits, r2's
    row already in: r1 and r2 are done in the manifest, r3's temporary file is gone, the exit code is the signal's and
    the handler the process had is back; run again, the batch tracks r3 alone, in its folder emptied but for the
    detections the stopped task saved."""
    command, out = _three(tmp_path)
    ray = _Ray({"r1", "r2"}, stop=stop, stop_at=2)
    monkeypatch.setitem(sys.modules, "ray", ray)
    recordings = [tmp_path / name for name in ("r1", "r2", "r3")]
    given = file_hashes(*recordings)
    before = signal.getsignal(signal.SIGTERM)
    assert main([*command, "--quiet"]) == code
    assert signal.getsignal(signal.SIGTERM) is before
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "tracker: interrupted: 2 of 3 recordings finished; run the same command again to resume"
    )
    assert _states(out) == {"r1": "done", "r2": "done", "r3": "started"} and ray.submitted == ["r1", "r2", "r3"]
    assert sorted(path.name for path in (out / "r3").iterdir()) == ["keypoints.npz", "track.log"]
    assert file_hashes(*recordings) == given and all(not any(folder.iterdir()) for folder in recordings)

    again = _Ray({"r1", "r2", "r3"})
    monkeypatch.setitem(sys.modules, "ray", again)
    assert main([*command, "--quiet"]) == 0
    assert again.submitted == ["r3"] and again.found["r3"] == ["keypoints.npz"]
    assert (out / "r3" / "keypoints.npz").read_text() == "r3"


def test_a_crashed_try_is_tried_again_with_the_detections_it_saved(tmp_path, monkeypatch, capsys):
    """r1's first try crashes (its worker died) after saving detections: the second try starts in r1's folder emptied
    but for them, and finishes."""
    command, out = _three(tmp_path)
    ray = _Ray({"r1", "r2", "r3"}, crashing=frozenset({"r1"}))
    monkeypatch.setitem(sys.modules, "ray", ray)
    assert main([*command, "--quiet"]) == 0
    assert "r1: try 1 crashed (the worker died); trying again" in capsys.readouterr().err
    assert ray.submitted == ["r1", "r2", "r1", "r3"] and ray.found["r1"] == ["keypoints.npz"]
    assert _summary(out)["r1"]["attempts"] == "2"


def test_a_stop_while_a_reply_is_taken_keeps_that_reply(tmp_path, monkeypatch):
    """SIGTERM while the batch takes r1's row from Ray (``ray.get``): r1 is done in the manifest all the same, as is
    r2, whose reply had come too."""
    command, out = _three(tmp_path)
    monkeypatch.setitem(sys.modules, "ray", _Ray({"r1", "r2"}, stop=signal.SIGTERM, stop_in="get", stop_at=1))
    assert main([*command, "--quiet"]) == 143
    assert _states(out) == {"r1": "done", "r2": "done", "r3": "started"}


def test_a_batch_whose_terminal_closed_keeps_its_rows_and_its_summary(tmp_path, monkeypatch):
    """SIGHUP from a terminal that closed while the batch waits, r2's reply in, writing to the terminal failing from
    then on: r1 and r2 are done in the manifest and in summary.csv, r3's temporary file is gone, and the batch exits 129
    without an error of its own."""
    command, out = _three(tmp_path)
    ray = _Ray({"r1", "r2"}, stop=signal.SIGHUP, stop_at=2, hung_up=closing_terminal(monkeypatch))
    monkeypatch.setitem(sys.modules, "ray", ray)
    assert main([*command, "--quiet"]) == 129
    assert _states(out) == {"r1": "done", "r2": "done", "r3": "started"}
    assert sorted(_summary(out)) == ["r1", "r2"]
    assert sorted(path.name for path in (out / "r3").iterdir()) == ["keypoints.npz", "track.log"]


def test_without_ray_it_says_how_to_install_it(recordings, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)
    assert main(["batch", str(recordings[1]), "--out", str(tmp_path / "out")]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert "Ray" in line and "pip install" in line and "[cluster]" in line


def test_other_options_on_the_same_output_folder_are_refused(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "manifest.json").write_text(
        json.dumps({"format": "tracker batch manifest", "version": 1, "options": {"iterations": 9}, "recordings": {}})
    )
    assert main(["batch", str(recordings[1]), "--out", str(out), "--iterations", "4"]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert "manifest.json" in line and "iterations" in line


def test_a_folder_the_batch_did_not_make_is_left_alone(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    (out / recordings[1].name).mkdir(parents=True)
    (out / recordings[1].name / "notes.txt").write_text("mine")
    assert main(["batch", str(recordings[1]), "--out", str(out)]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert recordings[1].name in line and "not from this batch" in line
    assert (out / recordings[1].name / "notes.txt").read_text() == "mine"


def test_a_pattern_that_matches_nothing_is_one_line(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nothing-*"), "--out", str(tmp_path / "out")]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert "nothing-*" in line and "matches no folder" in line


@pytest.mark.parametrize("cameras", ["", ","])
def test_a_camera_list_that_names_none_is_one_line_before_any_job(tmp_path, cameras, capsys):
    assert main(["batch", str(tmp_path / "nothing-*"), "--out", str(tmp_path / "out"), "--cameras", cameras]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"tracker: error: --cameras {cameras!r} names no camera; name the cameras to track, or leave --cameras out to "
        "track them all"
    ]
    assert not (tmp_path / "out").exists()


def test_an_address_where_no_ray_answers_is_one_line(recordings, tmp_path, capsys):
    with socket.socket() as closed:  # a port bound but not listening: connections to it are refused
        closed.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{closed.getsockname()[1]}"
        assert main(["batch", str(recordings[1]), "--out", str(tmp_path / "out"), "--ray", address]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert address in line and "ray start --head" in line


def test_a_recording_keeps_its_results_folder_and_folders_never_overlap(tmp_path, one_line_error):
    data, out = tmp_path / "data", tmp_path / "out"
    first = jobs([data / "s1" / "t1", data / "s2" / "t1"], out, {})
    assert [job.name for job in first] == ["s1/t1", "s2/t1"]
    known = {str(job.recording): job.name for job in first}
    [again] = jobs([data / "s1" / "t1"], out, known)  # alone now, it would be called t1
    assert again.name == "s1/t1" and again.out == out / "s1" / "t1"
    [added] = jobs([data / "t1"], out, known)
    assert added.name == "t1"
    message = one_line_error(lambda: jobs([data / "s1"], out, known))  # s1/t1 would lie inside its folder
    assert "share a folder" in message and str(data / "s1") in message
    message = one_line_error(lambda: jobs([data / "a", data / "a" / "b"], out, {}))
    assert "share a folder" in message


def test_the_output_folder_is_not_a_recording(tmp_path):
    for name in ("t1", "t2", "results", "results/t1"):
        (tmp_path / name).mkdir(parents=True)
    assert matched([str(tmp_path / "*")], tmp_path / "results") == [tmp_path / "t1", tmp_path / "t2"]
