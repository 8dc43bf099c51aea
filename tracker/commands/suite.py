"""``tracker suite``: make the hard suite of renders, track it, and score it (docs/suite.md)."""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "make, track and score the hard suite of renders unlike the model"

ABOUT = (
    "The hard test suite: render recordings whose body, clothing, room and cameras differ from the tracking model"
    " (make), then track and score them all (run), score results tracked otherwise (score), or score the keypoint"
    " detector's landmarks on them (landmarks)."
)
EXAMPLE = "tracker suite make out/suite"

TRACK = (sys.executable, "-m", "tracker.cli", "track")
"""The command that tracks each render, in a child process (:func:`_track`)."""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The actions of ``tracker suite``: make, score, run and landmarks."""
    actions = parser.add_subparsers(dest="action", required=True)
    make = actions.add_parser("make", help="render every render of the suite into OUT/<name>/")
    make.add_argument("out", help="folder for the renders")
    _only(make)
    make.add_argument("--clips", metavar="DIR", help="folder holding the CMU clips 131_01.bvh and 131_02.bvh")
    make.add_argument("--frames", type=options.positive_int, help="render only the first N frames of each")
    make.add_argument("--quiet", action="store_true", help="no progress bar")
    score = actions.add_parser("score", help="score RESULTS/<name>/poses.npz against OUT/<name>/truth.npz")
    score.add_argument("out", help="folder of the renders")
    score.add_argument("results", help="folder of the tracked results, RESULTS/<name>/poses.npz")
    _only(score)
    _landmark_model(score, "whose detections beside the results are scored too")
    score.add_argument("--json", action="store_true", help="print the scores as JSON")
    run = actions.add_parser(
        "run",
        help="track every render (tracker track OUT/<name> --out RESULTS/<name> TRACK OPTIONS), then score",
        usage="tracker suite run [--only NAMES] [--landmark-model M] [--json] [--quiet] OUT RESULTS [-- TRACK OPTIONS]",
    )
    _only(run)
    _landmark_model(run, "that tracker track runs, and whose detections are scored")
    run.add_argument("--json", action="store_true", help="print the scores as JSON")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("out", help="folder of the renders")
    run.add_argument("results", help="folder for the tracked results")
    run.add_argument(
        "track",
        nargs=argparse.REMAINDER,
        help="after --: options for tracker track; {rec} is replaced by OUT/<name> "
        "(e.g. -- --init {rec}/truth_init.toml)",
    )
    landmarks = actions.add_parser(
        "landmarks", help="score the detector's landmarks KP/<name>/keypoints.npz against OUT/<name>/truth.npz"
    )
    landmarks.add_argument("out", help="folder of the renders")
    landmarks.add_argument("keypoints", help="folder of the detections, KP/<name>/keypoints.npz (tracker keypoints)")
    _only(landmarks)
    _landmark_model(landmarks, "whose detections are scored (KP/<name>/keypoints-<model>.npz but for the default)")
    landmarks.add_argument("--json", action="store_true", help="print the scores as JSON")


def _only(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", metavar="NAMES", help="comma-separated renders of the suite (default: all)")


def _landmark_model(parser: argparse.ArgumentParser, what: str) -> None:
    """``--landmark-model``, the detector's model ``what`` says."""
    group = parser.add_argument_group(f"the landmark model {what}")
    options.add_landmark_model_option(group)


def run(args: argparse.Namespace) -> int:
    """Do the action."""
    return {"make": _make, "score": _score, "run": _run, "landmarks": _landmarks}[args.action](args)


def _make(args: argparse.Namespace) -> int:
    from tracker.synthetic.suite import make, select

    renders = select(options.camera_names(args.only))
    started = time.perf_counter()
    summaries = make(args.out, renders, clips=args.clips, frames=args.frames, progress=not args.quiet)
    for render, done in zip(renders, summaries):
        print(
            f"{render.name}: {render.rig}, {done['frames']} frames at {done['fps']:g} fps, "
            f"{done['seconds']['total']:.0f} s; {render.hard}"
        )
    print(f"wrote {len(renders)} renders into {args.out} in {time.perf_counter() - started:.0f} s")
    return 0


def _score(args: argparse.Namespace) -> int:
    from tracker.synthetic.suite import format_summary, made, score, summary

    renders = made(args.out, options.camera_names(args.only))
    data = summary(score(args.out, args.results, renders, landmark_model=args.landmark_model))
    print(json.dumps(data, indent=2) if args.json else format_summary(data))
    return 0


def _run(args: argparse.Namespace) -> int:
    from tracker.synthetic.suite import format_summary, made, score, summary

    extra = list(args.track)  # argparse drops the "--" right after RESULTS; one further on follows misplaced options
    if "--" in extra:
        misplaced = " ".join(extra[: extra.index("--")])
        raise TrackerInputError(f"{misplaced}: give the suite's options before OUT, and tracker track's after --")
    if any(word.split("=")[0] == "--landmark-model" for word in extra):
        raise TrackerInputError(
            "--landmark-model: give it before OUT, where it names the detections scored too, not after --"
        )
    extra += ["--landmark-model", args.landmark_model]
    renders = made(args.out, options.camera_names(args.only))
    for render in options.bar(args, "suite run", "render", leave=True)(renders):
        _track(Path(args.out) / render.name, Path(args.results) / render.name, extra)
    data = summary(score(args.out, args.results, renders, landmark_model=args.landmark_model))
    print(json.dumps(data, indent=2) if args.json else format_summary(data))
    return 0


def _landmarks(args: argparse.Namespace) -> int:
    from tracker.synthetic.keypoint_accuracy import accuracy_rows, format_accuracy, suite_accuracy
    from tracker.synthetic.suite import made

    renders = made(args.out, options.camera_names(args.only))
    scores = suite_accuracy(args.out, args.keypoints, renders, landmark_model=args.landmark_model)
    print(json.dumps(accuracy_rows(scores), indent=2) if args.json else format_accuracy(scores))
    return 0


def _track(recording: Path, results: Path, extra: list[str]) -> None:
    """Run ``tracker track recording --out results --quiet extra`` ({rec} in ``extra`` -> ``recording``) in a
    child process, its output kept in results/track.log; a failure is a one-line error naming the log.  A stop
    (Ctrl-C, SIGTERM, SIGHUP) is passed on to the child (:func:`_finished`), which saves what it tracked; its log is
    written, and then the stop goes on, stopping the suite."""
    from tracker.atomic import atomic_write

    results.mkdir(parents=True, exist_ok=True)
    command = [*TRACK, str(recording), "--out", str(results), "--quiet"]
    command += [word.replace("{rec}", str(recording)) for word in extra]
    texts = []
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        code, stop = _finished(subprocess.Popen(command, stdout=out, stderr=err, process_group=0))
        for stream in (out, err):
            stream.seek(0)
            texts.append(stream.read().decode(errors="replace"))
    said, errors = texts
    log = results / "track.log"
    text = f"$ {' '.join(command)}\n{said}{errors}".encode()
    atomic_write(log, lambda file: file.write(text))
    if stop is not None:
        raise stop
    if code != 0:
        last = (errors.strip().splitlines() or ["no message"])[-1]
        raise TrackerInputError(f"{recording.name}: tracker track exited with {code} ({last}); see {log}")


def _finished(child: subprocess.Popen) -> tuple[int, KeyboardInterrupt | None]:
    """The exit code of the ``child`` process, once it has ended, and the stop that came meanwhile (None if none
    did).  A stop is passed on to the child as its signal (SIGINT for Ctrl-C), once: the child runs in a process group
    of its own, which a terminal's Ctrl-C or hang-up does not reach."""
    stop = None
    while True:
        try:
            return child.wait(), stop
        except KeyboardInterrupt as error:
            stop = error
            child.send_signal(getattr(error, "number", signal.SIGINT))
