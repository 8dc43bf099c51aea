"""``tracker bench``: per-stage timings, frames per second and the decode-only floor."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tracker.commands import options

HELP = "per-stage timings, frames per second and the decode-only floor"

ABOUT = (
    "Time the tracker on a recording (by default the demo that comes with it): each stage of a frame, the frames "
    "per second, and how fast the videos decode alone, the most tracking could reach. --scaling times it against "
    "the number of body parts and cameras; --long tracks many frames and reports the memory used."
)
EXAMPLE = "tracker bench"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker bench``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    inputs.add_argument(
        "recording", nargs="?", metavar="RECORDING", help="recording folder (default: the bundled demo)"
    )
    inputs.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    inputs.add_argument("--init", help="first pose TOML (default: the recording's init.toml)")
    outputs.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    parser.add_argument(
        "--scaling",
        action="store_true",
        help="time one iteration against the number of components (7-120) and of cameras (1-8)",
    )
    parser.add_argument("--repeats", type=options.positive_int, default=3, help="passes per figure (default 3)")
    parser.add_argument(
        "--long",
        type=options.positive_int,
        metavar="FRAMES",
        help="instead, track this many frames (the recording read in a loop) and report resident memory",
    )
    outputs.add_argument("--quiet", action="store_true", help="no progress bar (--long)")
    options.add_keypoint_options(parser, "time the keypoint cue at this rate")
    options.add_landmark_model_option(parser)
    options.add_tuning_options(parser, ("--iterations", "--spacing", "--resample-every", "--work-side", "--region"))


def run(args: argparse.Namespace) -> int:
    """Print the benchmark's tables (or one JSON object with ``--json``)."""
    import json

    from tracker.apps import bench

    settings = options.settings_from(args)
    print("preparing the numba kernels, then timing (medians of several passes)...", file=sys.stderr, flush=True)
    if args.scaling:
        result = bench.scaling()
        print(json.dumps(result, indent=2) if args.json else bench.format_scaling(result))
        return 0
    model = Path(args.model) if args.model else None
    init = Path(args.init) if args.init else None
    recording = Path(args.recording) if args.recording else bench.DEMO
    if args.long:
        bar = options.bar(args, None, "frame")
        long = bench.long_run(
            recording,
            args.long,
            settings,
            keypoint_step=args.keypoints,
            landmark_model=args.landmark_model,
            model_path=model,
            init_path=init,
            progress=bar,
        )
        print(json.dumps(long, indent=2) if args.json else bench.format_long(long))
        return 0
    result = bench.run(
        recording,
        settings,
        repeats=args.repeats,
        keypoint_step=args.keypoints,
        landmark_model=args.landmark_model,
        model_path=model,
        init_path=init,
    )
    print(json.dumps(result, indent=2) if args.json else bench.format_table(result))
    return 0
