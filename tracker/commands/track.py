"""``tracker track``: track a recording folder, write DIR/poses.npz and print a summary (the run itself:
:func:`tracker.apps.track.track`)."""

from __future__ import annotations

import argparse
import functools

from tracker.commands import options
from tracker.commands.viewing import serve
from tracker.errors import TrackerInputError

HELP = "track a recording folder, write DIR/poses.npz and print a summary"

ABOUT = (
    "Follow the body through a recording folder (its calibration.toml and one video per camera) and write the "
    "pose of every frame to OUT/poses.npz. Without a model.toml in the folder it first fits the standard human "
    "model to the person; without an init.toml it finds the first pose with the keypoint detector. At the end it "
    "says how well the frames were followed, which files it wrote and, when the folder holds the true poses "
    "(truth.npz), how close the tracked joints came to them."
)
EXAMPLE = "tracker track recordings/demo --frames 40 --out out/demo"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker track``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    viewer = parser.add_argument_group("viewer")
    options.add_recording_argument(inputs)
    outputs.add_argument("--out", help="output folder (default: out/<recording name>)")
    options.add_tracking_options(parser, inputs=inputs)
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")
    outputs.add_argument(
        "--overlay",
        metavar="VIDEO",
        help="also write a video (.mp4/.avi) of every camera with the tracked outlines and edge searches",
    )
    options.add_live_view_options(viewer, "then review the result")
    options.add_viewer_options(viewer)


def run(args: argparse.Namespace) -> int:
    """Track, write poses.npz and print the summary (and the evaluation against the recording's truth);
    130 after Ctrl-C, SIGTERM or SIGHUP with the frames done written (the CLI reports the signal's own code)."""
    from tracker.apps.track import Viewing, print_summary, track
    from tracker.overwrite import keep_inputs

    if args.record and not args.view:
        raise TrackerInputError(f"{args.record}: --record writes the viewer session; add --view")
    rec, tracking = options.tracking(args)
    read = [(args.model, "the body model being read"), (args.init, "the first pose being read")]
    read += options.recording_inputs(rec)
    keep_inputs([args.overlay], read, "write the overlay video to another file")
    keep_inputs([args.record], read, "write the viewer session to another file")
    record = options.record_file(args)
    view = None
    if args.view:
        view = Viewing(args.host, args.port, args.view_rate, record)
    outcome = track(
        rec,
        tracking,
        out=options.output_folder(args.out, rec),
        overlay=args.overlay,
        view=view,
        bar=functools.partial(options.bar, args),
    )
    if outcome.interrupted:
        print(f"wrote {outcome.poses} ({outcome.frames} frames)")
        options.say_interrupted()
        return 130
    print_summary(outcome)
    if outcome.review is None:
        return 0
    return serve(f"tracking done; the viewer now reviews {outcome.poses}", outcome.review())
