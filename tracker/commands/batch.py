"""``tracker batch``: track many recording folders, one Ray task each, locally or on a cluster (docs/batch.md).

The driver matches the folders, gives each a results folder under ``--out`` (its path from the folders' common
parent), and submits one task per folder that is not finished according to the manifest
(:mod:`tracker.io.batch_records`), at most ``--workers`` at a time. A task runs ``tracker track`` in the Ray worker,
its output going to the results folder's ``track.log``, and returns the recording's :class:`Row`. A one-line
input error (a missing calibration, say) fails the recording at once; a crash (an exception, a worker that
died) is tried again, up to :data:`RETRIES` times. Each finished recording is written to the manifest as it
comes, so a batch stopped by Ctrl-C, SIGTERM or SIGHUP (or a driver that died) resumes where it was: run the same
command again.  Stopped, it writes the recordings whose tasks had finished, ends the others with Ray, and removes the
temporary files their writes were cut off in.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import fnmatch
import glob
import logging
import os
import shutil
import signal
import socket
import sys
import time
from pathlib import Path

from tracker import stop_signals
from tracker.atomic import remove_temporaries
from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "track many recording folders, one Ray task each, locally or on a cluster"

ABOUT = (
    "Track many recording folders, several at a time, on this machine or on a Ray cluster, each as tracker track "
    "would, into its own folder under OUT, with a summary of all in OUT/summary.csv. Run it again after a stop "
    "and it goes on with the recordings not yet done."
)
EXAMPLE = "tracker batch 'data/*' --out results"

RETRIES = 2
"""Tries after the first for a recording whose task crashed."""

INSTALL = "pip install 'tracker[cluster]' (in a clone: pip install -e '.[cluster]'; make setup does it)"

PATHS = ("model", "init", "calib")
"""Tracking options that name files: made absolute, so that every worker reads the same ones."""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker batch``: its own, then those of ``tracker track`` that it passes on."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    cluster = parser.add_argument_group("where it runs")
    inputs.add_argument(
        "recordings",
        nargs="+",
        metavar="GLOB",
        help="recording folders, or glob patterns matching them (quote them to match on the driver: 'data/*/trial*')",
    )
    outputs.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output folder: one results folder a recording, the manifest and summary.csv",
    )
    cluster.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="address of a running Ray cluster (e.g. 10.0.0.5:6379, or auto); default: a local one started for "
        "the batch",
    )
    cluster.add_argument(
        "--workers",
        type=options.positive_int,
        help="recordings tracked at once (default: the machine's cores locally, the cluster's CPUs with --ray)",
    )
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")
    options.add_tracking_options(parser, inputs=inputs)


@dataclasses.dataclass(frozen=True)
class Job:
    """One recording of the batch and its results folder."""

    recording: Path
    name: str
    out: Path


def matched(patterns: list[str], out: Path) -> list[Path]:
    """The folders ``patterns`` (paths or glob patterns) match, absolute, in order, each once, leaving out the
    batch's own output folder ``out`` and what lies in it; a one-line error for a pattern that matches none."""
    found: dict[Path, None] = {}
    for pattern in patterns:
        folders = [Path(path).resolve() for path in sorted(glob.glob(pattern))]
        folders = [folder for folder in folders if folder.is_dir() and folder != out and out not in folder.parents]
        if not folders:
            raise TrackerInputError(
                f"{pattern}: matches no folder; give recording folders or a pattern that matches them"
            )
        found.update(dict.fromkeys(folders))
    return list(found)


def jobs(recordings: list[Path], out: Path, known: dict[str, str]) -> list[Job]:
    """Each recording with its results folder under ``out``: the name it had in the batch before (``known``,
    recording -> name, from the manifest), else its path below the recordings' common parent (its own name when
    alone); a one-line error when two recordings' folders would be one or lie one inside the other."""
    if len(recordings) == 1:
        fresh = {str(recordings[0]): recordings[0].name}
    else:
        parent = Path(os.path.commonpath([recording.parent for recording in recordings]))
        fresh = {str(recording): recording.relative_to(parent).as_posix() for recording in recordings}
    names = {**known, **{recording: name for recording, name in fresh.items() if recording not in known}}
    holders: dict[str, str] = {}  # a results folder, or a folder above one -> a recording whose it is
    for recording, name in names.items():
        parts = name.split("/")
        for above in ("/".join(parts[:end]) for end in range(1, len(parts) + 1)):
            other = holders.setdefault(above, recording)
            if other != recording and (above == name or names[other] == above):
                raise TrackerInputError(
                    f"{out / name}: the results of {recording} would share a folder with those of {other}; "
                    "track recordings that do not lie inside one another, or use another --out"
                )
    return [Job(recording, names[str(recording)], out / names[str(recording)]) for recording in recordings]


def tracking_options(args: argparse.Namespace) -> dict:
    """The ``tracker track`` options of ``args`` (the ones :func:`tracker.commands.options.add_tracking_options`
    makes), file names made absolute."""
    parser = argparse.ArgumentParser()
    options.add_tracking_options(parser, inputs=parser)
    chosen = {key: getattr(args, key) for key in vars(parser.parse_args([]))}
    for key in PATHS:
        if chosen[key] is not None:
            chosen[key] = str(Path(chosen[key]).resolve())
    if chosen["background"] not in ("none", "median"):
        chosen["background"] = str(Path(chosen["background"]).resolve())
    return chosen


def track_recording(recording: str, name: str, out: str, *, chosen: dict):
    """The Ray task: ``tracker track recording --out out`` with the ``chosen`` tracking options, its output in
    OUT/track.log; the recording's row, failed with the error's line for bad input. Any other exception is the
    driver's to retry."""
    import cv2

    from tracker.apps.track import print_summary, track
    from tracker.atomic import ensure_writable_folder
    from tracker.io.batch_records import DONE, FAILED, Row
    from tracker.status import LOST

    cv2.setNumThreads(1)  # as tracker.cli.main: the reader threads run in parallel already
    args = argparse.Namespace(recording=recording, **chosen)
    started = time.perf_counter()
    try:
        log = ensure_writable_folder(out) / "track.log"
    except TrackerInputError as error:
        return Row(recording, name, FAILED, seconds=time.perf_counter() - started, error=str(error))
    with open(log, "w") as stream, contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
        try:
            rec, tracking = options.tracking(args)
            outcome = track(rec, tracking, out=Path(out))
        except TrackerInputError as error:
            print(f"tracker: error: {error}", file=sys.stderr)
            return Row(recording, name, FAILED, seconds=time.perf_counter() - started, error=str(error))
        if outcome.interrupted:  # a stop reached the worker too: not a finished recording
            raise RuntimeError(f"{recording}: interrupted after {outcome.frames} frames")
        print_summary(outcome)
    return Row(
        recording,
        name,
        DONE,
        frames=outcome.frames,
        fps=outcome.fps,
        residual_px=outcome.residual,
        lost=outcome.counts[LOST],
        mpjpe_mm=outcome.report.mpjpe_mm if outcome.report is not None else float("nan"),
        seconds=time.perf_counter() - started,
    )


def run(args: argparse.Namespace) -> int:
    """Track the recordings not yet finished in ``--out`` and print and write the summary of all it finished; 1
    when a recording failed, 128 plus the signal's number after a stop signal (130 after Ctrl-C, 143 after SIGTERM,
    129 after SIGHUP: the finished ones kept, the batch resumable)."""
    if options.camera_names(args.cameras) == []:  # else each recording's job would fail with it, one by one
        raise TrackerInputError(
            f"--cameras {args.cameras!r} names no camera; name the cameras to track, or leave --cameras out to track "
            "them all"
        )
    ray = _ray()
    from tracker.atomic import ensure_writable_folder
    from tracker.io.batch_records import FAILED, Manifest, format_summary, write_summary

    recordings = matched(args.recordings, Path(args.out).resolve())
    out = ensure_writable_folder(args.out).resolve()
    manifest = Manifest.open(out / "manifest.json", tracking_options(args))
    everything = jobs(recordings, out, manifest.names)
    todo = [job for job in everything if (row := manifest.row(str(job.recording))) is None or row.state == FAILED]
    for job in todo:  # what an unfinished try left goes, but never a folder the batch did not make
        if job.out.exists():
            if str(job.recording) not in manifest.names:
                raise TrackerInputError(
                    f"{job.out}: already exists and is not from this batch; pick another --out or move it away"
                )
            _cleared(job.out)
    if len(todo) < len(everything):
        before = len(everything) - len(todo)
        print(f"resuming: {before} of {len(everything)} recordings finished before", file=sys.stderr)
    manifest.start({str(job.recording): job.name for job in todo})
    try:
        stopped = _track_all(ray, args, todo, manifest) if todo else 0
    finally:  # written before anything is printed: a terminal that hung up (SIGHUP) fails the printing
        rows = manifest.finished()
        write_summary(rows, out / "summary.csv")
    print(format_summary(rows))
    print(f"wrote {out / 'summary.csv'}")
    if stopped:
        done = sum(manifest.row(str(job.recording)) is not None for job in everything)
        print(
            f"tracker: interrupted: {done} of {len(everything)} recordings finished; run the same command again to "
            "resume",
            file=sys.stderr,
        )
        return stop_signals.exit_code(stopped)
    failed = sum(row.state == FAILED for row in rows)
    if failed:
        print(f"{failed} of {len(rows)} recordings failed: their errors are in the summary", file=sys.stderr)
        return 1
    return 0


def _cleared(folder: Path) -> None:
    """Empty the results ``folder`` (if there is one) of a recording's unfinished try but for the keypoint detector's
    files (keypoints*.npz): the frames it detected before it stopped are not detected again (a file names the
    recording it holds, :func:`tracker.landmarks.detect_recording.cached`)."""
    for path in folder.iterdir() if folder.is_dir() else ():
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif not fnmatch.fnmatch(path.name, "keypoints*.npz"):
            path.unlink()


def _ray():
    """The ray module, or a one-line error saying how to install it."""
    try:
        import ray
    except ImportError:
        raise TrackerInputError(f"tracker batch runs on Ray, which is not installed here: {INSTALL}") from None
    return ray


def _start(ray, args: argparse.Namespace) -> int:
    """Connect to ``--ray``, or start a local Ray with ``--workers`` CPUs; the recordings to track at once."""
    runtime = {"env_vars": {"OPENBLAS_NUM_THREADS": "1"}}  # as tracker.cli.main: small matrices only
    quiet = {"logging_level": logging.ERROR, "log_to_driver": False, "runtime_env": runtime}
    if args.ray is None:
        workers = args.workers or os.cpu_count() or 1
        ray.init(address="local", num_cpus=workers, include_dashboard=False, **quiet)  # a new one, never another's
        return workers
    _answers(args.ray)
    try:
        ray.init(address=args.ray, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as error:
        raise TrackerInputError(
            f"--ray {args.ray}: cannot join a Ray cluster there ({_line(error)}); start one with 'ray start --head' "
            "and pass the address it prints, or leave out --ray to run locally"
        ) from None
    return args.workers or max(1, int(ray.cluster_resources().get("CPU", 1)))


def _answers(address: str) -> None:
    """A one-line error when nothing listens at a HOST:PORT ``address`` (Ray itself would retry for minutes)."""
    host, _, port = address.rpartition(":")
    if not host or "/" in host or not port.isdigit():
        return  # "auto", ray://..., or an address Ray reads its own way
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as error:
        raise TrackerInputError(
            f"--ray {address}: nothing answers there ({error.strerror or error}); start the head with "
            "'ray start --head' and pass the address it prints, or leave out --ray to run locally"
        ) from None


def _line(error: BaseException) -> str:
    """The last non-empty line of an error's text (a Ray error's is a traceback ending in what went wrong)."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return lines[-1] if lines else type(error).__name__


def _track_all(ray, args: argparse.Namespace, todo: list[Job], manifest) -> int:
    """Track ``todo`` on Ray, at most the workers' number at a time, each finished row written to ``manifest``
    as it comes; a crashed try tried again up to :data:`RETRIES` times.  The number of the stop signal that stopped
    it (:mod:`tracker.stop_signals`; 0 when none did): the tasks whose rows had come by then are written too, the
    others end with Ray, and the temporary files their writes were cut off in are removed.  A task stays pending
    until its row is written, so that a stop in between writes it all the same."""
    from tracker.io.batch_records import FAILED, Row

    stopped = 0
    pending: dict = {}  # task -> (job, its try)
    try:
        # Ray's own processes start with SIGINT and SIGHUP held, so that a terminal's Ctrl-C or hang-up stops the
        # batch alone, which then ends them; not SIGTERM, with which Ray's shutdown ends them (before SIGKILL a second
        # later).  ray.init sets a SIGTERM handler of its own, which would exit at once
        with stop_signals.held((signal.SIGINT, signal.SIGHUP)), stop_signals.kept():
            workers = _start(ray, args)
        task = ray.remote(num_cpus=1, max_retries=0)(track_recording)
        chosen = manifest.options
        waiting = list(todo)

        def submit(job: Job, attempt: int) -> None:
            pending[task.remote(str(job.recording), job.name, str(job.out), chosen=chosen)] = (job, attempt)

        def kept(ready, row: Row) -> Row:
            """``row``, the reply of the task ``ready``, written to the manifest, the task no longer pending."""
            manifest.finish(row)
            del pending[ready]
            return row

        def say(row: Row) -> None:
            progress.update(1)
            progress.write(_finished(row), sys.stdout)
            sys.stdout.flush()  # a line as each finishes, also through a pipe

        progress = options.bar(args, "recordings", "recording", leave=True)(total=len(todo))
        try:
            while waiting or pending:
                while waiting and len(pending) < workers:
                    submit(waiting.pop(0), 1)
                [ready], _ = ray.wait(list(pending), num_returns=1)
                job, attempt = pending[ready]
                try:
                    row = dataclasses.replace(ray.get(ready), attempts=attempt)
                except ray.exceptions.RayError as error:
                    if attempt <= RETRIES:
                        progress.write(f"{job.name}: try {attempt} crashed ({_line(error)}); trying again", sys.stderr)
                        _cleared(job.out)
                        del pending[ready]
                        submit(job, attempt + 1)
                        continue
                    row = Row(str(job.recording), job.name, FAILED, attempts=attempt, error=f"crashed: {_line(error)}")
                say(kept(ready, row))
        except KeyboardInterrupt as stop:
            # ray.shutdown() below ends the job, and with it the tasks it owns: cancelling them first races their
            # replies and can abort the driver (Ray 2.60: 'not pending'); the rows that came before the stop are kept,
            # every one before any is said
            stopped = getattr(stop, "number", signal.SIGINT)
            arrived = ray.wait(list(pending), num_returns=len(pending), timeout=0)[0] if pending else []
            rows = []
            for ready in arrived:
                with contextlib.suppress(ray.exceptions.RayError):  # a crash is tried again on resuming
                    rows.append(kept(ready, dataclasses.replace(ray.get(ready), attempts=pending[ready][1])))
            for row in rows:
                say(row)
        finally:
            progress.close()
    finally:
        ray.shutdown()
        for job, _ in pending.values():  # their tasks ended with Ray (locally, by the time it is shut down)
            remove_temporaries(job.out)
    return stopped


def _finished(row) -> str:
    """The line printed when a recording finishes."""
    if row.error:
        return f"{row.state} {row.name}: {row.error}"
    return f"{row.state} {row.name}: {row.frames} frames at {row.fps:.1f} fps, {row.lost} lost"
