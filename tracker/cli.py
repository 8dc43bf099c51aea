"""The ``tracker`` command line (formats.md): parse, call, report; no algorithm here.

Bad input raises :class:`TrackerInputError` and exits with code 2 and one line;
an interrupted run (Ctrl-C) keeps the frames already written and exits 130; output whose reader
stopped early (``| head``) ends the command quietly with 141, as a shell reports a broken pipe.
Each subcommand's options and body are in its module under :mod:`tracker.commands`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import warnings

from tracker import __version__
from tracker.commands import (
    background,
    batch,
    bench,
    calibrate,
    evaluate,
    experiment,
    export,
    fit_model,
    init,
    keypoints,
    live,
    points,
    refine,
    suite,
    sync,
    synth,
    track,
    view,
)
from tracker.errors import TrackerInputError

COMMANDS = {
    "track": track,
    "background": background,
    "refine": refine,
    "view": view,
    "init": init,
    "fit-model": fit_model,
    "eval": evaluate,
    "synth": synth,
    "sync": sync,
    "suite": suite,
    "live": live,
    "calibrate": calibrate,
    "export": export,
    "keypoints": keypoints,
    "points": points,
    "experiment": experiment,
    "bench": bench,
    "batch": batch,
}


def build_parser() -> argparse.ArgumentParser:
    """The ``tracker`` parser: one subparser per command, whose ``run`` default is the command's body."""
    parser = argparse.ArgumentParser(
        prog="tracker",
        description="Follow the 3-D pose of a person or other articulated body in calibrated multi-camera video: "
        "calibrate the cameras, track a recording or live cameras, review it in the browser, export the poses.",
        epilog="Start with: tracker track RECORDING (docs/own-rig.md); options: tracker COMMAND --help.",
    )
    parser.add_argument(
        "--version", action="version", version=f"%(prog)s {__version__}", help="print the tracker's version and exit"
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name, command in COMMANDS.items():
        subparser = sub.add_parser(name, help=command.HELP)
        command.add_options(subparser)
        subparser.set_defaults(run=command.run)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"tracker: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default: the process's arguments) and return its exit code."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices only: no BLAS thread storms
    import cv2

    cv2.setNumThreads(1)  # the reader threads already run in parallel; OpenCV's own pool only contends
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else argv
    if not argv:  # `tracker` alone: what it can do, not a usage error
        parser.print_help()
        return 0
    args = parser.parse_args(argv)
    warnings.showwarning = _show_warning
    try:
        return args.run(args)
    except TrackerInputError as exc:
        print(f"tracker: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("tracker: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # whatever read the output stopped early (tracker ... | head): no traceback
        with contextlib.suppress(OSError, ValueError, io.UnsupportedOperation):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nor one when Python flushes it at exit
        return 141


if __name__ == "__main__":
    sys.exit(main())
