"""``tracker view``: review a poses.npz over its recording in the browser viewer."""

from __future__ import annotations

import argparse

from tracker.commands import options
from tracker.commands.viewing import scene, serve

HELP = "review poses.npz over its recording in the browser viewer"

ABOUT = (
    "Open a tracked run (poses.npz) over its recording in the web browser: the body drawn over every camera's "
    "images, the 3-D scene, and a timeline to play or step through the frames. With --record it writes the "
    "session to a .viser file, which plays in a browser without the tracker, and returns."
)
EXAMPLE = "tracker view recordings/demo --poses out/demo/poses.npz"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker view``."""
    inputs = parser.add_argument_group("inputs")
    viewer = parser.add_argument_group("viewer")
    options.add_recording_argument(inputs)
    inputs.add_argument("--poses", help="poses.npz to review (default: out/<recording name>/poses.npz)")
    inputs.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    options.add_recording_options(inputs)
    inputs.add_argument(
        "--background",
        metavar="DIR",
        help="the empty scene a run was tracked against (tracker track --background; a median one "
        "is saved in OUT/background): the panels then show and search the difference images",
    )
    options.add_viewer_options(viewer)
    viewer.add_argument("--quiet", action="store_true", help="no progress bar while recording")


def run(args: argparse.Namespace) -> int:
    """Serve the review until Ctrl-C, or with ``--record`` write the session and return."""
    from tracker.overwrite import keep_inputs
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.settings import Settings
    from tracker.viewer.review import Review

    rec, model = options.opened(args)
    poses_path, results = options.tracked(args.poses, rec, model)
    keep_inputs(
        [args.record],
        [(poses_path, "the poses file being reviewed"), (args.model, "the body model being read")]
        + options.recording_inputs(rec),
        "write the viewer session to another file",
    )
    settings = Settings()
    background = None
    if args.background:
        from tracker.tracking.foreground import load_background

        background = load_background(args.background, rec)
    truth = options.truth(rec)
    record = options.record_file(args)
    tracker = Tracker(model, rec.cameras, results["poses"][0], settings)
    shown = scene(args, rec, model, settings=settings, truth=truth, quiet=record is not None)
    review = Review(shown, rec, tracker, results, truth, background)
    review.show(0)
    if record is not None:  # a file, not a viewer to open: the server that drew it goes without a word
        review.record(record, progress=not args.quiet)
        review.close()
        shown.server.stop()
        print(f"wrote {args.record}")
        return 0
    return serve(f"reviewing {poses_path} ({len(results['frame'])} frames)", review)
