"""The ``tracker`` command line (formats.md): parse, call, report; no algorithm here.

Bad input raises :class:`TrackerInputError` and exits with code 2 and one line;
an interrupted run (Ctrl-C, SIGTERM or SIGHUP: :mod:`tracker.stop_signals`) keeps the work already done and exits
with 128 plus the signal's number (130, 143, 129), quietly when the terminal it wrote to has closed (SIGHUP, after
which writing there fails); output whose reader
stopped early (``| head``) ends the command quietly with 141, as a shell reports a broken pipe.
Each subcommand's options, help and body are in its module under :mod:`tracker.commands`; every help opens with
what the command does and an example.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import io
import os
import signal
import sys
import warnings
from typing import NoReturn

from tracker import __version__, stop_signals
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

COMMANDS = {  # in the order a newcomer meets them: track, look, score, export; then their own rig; then the rest
    "track": track,
    "view": view,
    "eval": evaluate,
    "export": export,
    "init": init,
    "fit-model": fit_model,
    "calibrate": calibrate,
    "sync": sync,
    "live": live,
    "batch": batch,
    "background": background,
    "refine": refine,
    "keypoints": keypoints,
    "synth": synth,
    "suite": suite,
    "bench": bench,
    "points": points,
    "experiment": experiment,
}


PATHS = frozenset({"init", "model", "calib", "poses", "background", "out", "record", "overlay", "cache"})
"""The options that name a file or a folder: given empty (``--init ''``), one names none, which would otherwise
read as the current folder."""


class _Parser(argparse.ArgumentParser):
    """A parser whose usage error is one line, the error and the help to read (``tracker track: error: argument
    --port: invalid port value: 'abc'; see tracker track --help``), exit code 2; a command's unknown arguments are
    that command's error, not the main parser's, and so is an option of :data:`PATHS` given empty."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}; see {self.prog} --help\n")

    def parse_known_args(self, args=None, namespace=None):
        parsed, extra = super().parse_known_args(args, namespace)
        if extra:
            self.error(f"unrecognized arguments: {' '.join(extra)}")
        for action in self._actions:
            if action.dest in PATHS and action.option_strings and getattr(parsed, action.dest, None) == "":
                self.error(f"argument {action.option_strings[0]}: '' names no file or folder; name one or leave it out")
        return parsed, extra


class _Paragraphs(argparse.HelpFormatter):
    """Help text as paragraphs split by blank lines: each filled to the terminal's width, except one with an indented
    line (an example command), which is kept as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        fill = super()._fill_text
        return "\n\n".join(
            paragraph if "\n " in paragraph else fill(paragraph, width, indent) for paragraph in text.split("\n\n")
        )


def _opening(about: str, example: str) -> str:
    """A help's opening: what the command does, then an example of it."""
    return f"{about}\n\nexample:\n  {example}"


def _short_usage(parser: argparse.ArgumentParser) -> str:
    """The usage line with only what must be given (the arguments and required options): the full one lists every
    option and fills a screen before the help says what the command does."""
    needed = [action for action in parser._actions if action.required or not action.option_strings]
    formatter = parser._get_formatter()
    formatter.add_usage(None, needed, [], prefix="")
    return f"%(prog)s [options] {formatter.format_help().strip().removeprefix(parser.prog).strip()}"


def build_parser() -> argparse.ArgumentParser:
    """The ``tracker`` parser: one subparser per command, whose ``run`` default is the command's body."""
    parser = _Parser(
        prog="tracker",
        description=_opening(
            "Follow the 3-D pose of a person or other articulated body in calibrated multi-camera video: calibrate "
            "the cameras, track a recording or live cameras, review it in the browser, export the poses. Start with "
            "the demo recording that comes with the tracker; your own cameras: docs/own-rig.md.",
            "tracker track recordings/demo --frames 40 --out out/demo",
        ),
        epilog="What each command does, with an example and its options: tracker COMMAND --help.",
        formatter_class=_Paragraphs,
    )
    parser.add_argument(
        "--version", action="version", version=f"%(prog)s {__version__}", help="print the tracker's version and exit"
    )
    sub = parser.add_subparsers(dest="command", required=True, title="commands", metavar="COMMAND")
    for name, command in COMMANDS.items():
        subparser = sub.add_parser(
            name, help=command.HELP, description=_opening(command.ABOUT, command.EXAMPLE), formatter_class=_Paragraphs
        )
        command.add_options(subparser)
        subparser.usage = _short_usage(subparser)
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
    with stop_signals.like_ctrl_c() as received:  # SIGTERM and SIGHUP stop the run as Ctrl-C does
        return received.exit_code(_run(args, received))


def _run(args: argparse.Namespace, received: stop_signals.Received) -> int:
    """The command's exit code (:func:`_reported`); that of an interruption (130, reported as SIGHUP's 129) for a
    run stopped by SIGHUP (``received``) whose output then failed with EIO, as writing to a terminal that has closed
    does: its output goes nowhere from then on, what the command had still to say is lost, and no traceback ends a
    run whose work is saved."""
    try:
        return _reported(args)
    except OSError as error:
        if error.errno != errno.EIO or received.number != signal.SIGHUP:
            raise
        _to_nowhere(sys.stdout, sys.stderr)
        return stop_signals.INTERRUPTED


def _reported(args: argparse.Namespace) -> int:
    """The command's exit code: its own, 2 after bad input, 130 after an interruption that reached here."""
    try:
        return args.run(args)
    except TrackerInputError as exc:
        print(f"tracker: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError) as error:  # SystemError: a stop inside a numba kernel, as it reports it
        if not stop_signals.stopped_within(error):
            raise
        print("tracker: interrupted", file=sys.stderr)
        return stop_signals.INTERRUPTED
    except BrokenPipeError:  # whatever read the output stopped early (tracker ... | head): no traceback
        _to_nowhere(sys.stdout)  # nor one when Python flushes it at exit
        return 141


def _to_nowhere(*streams) -> None:
    """Point the file descriptors of ``streams`` (standard output or error) at /dev/null, so that what they still hold
    is flushed there at exit without an error; a stream without one (captured) is left as it is."""
    nowhere = os.open(os.devnull, os.O_WRONLY)
    try:
        for stream in streams:
            with contextlib.suppress(OSError, ValueError, io.UnsupportedOperation):
                os.dup2(nowhere, stream.fileno())
    finally:
        os.close(nowhere)


if __name__ == "__main__":
    sys.exit(main())
