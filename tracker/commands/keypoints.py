"""``tracker keypoints``: the 2-D keypoint detector over a recording, written to OUT/keypoints.npz."""

from __future__ import annotations

import argparse
import sys
import time

from tracker import stop_signals
from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "detect BlazePose's 33 landmarks in every camera and frame, write DIR/keypoints.npz"

ABOUT = (
    "Run the 2-D keypoint detector (BlazePose: 33 landmarks of the body) over every camera and frame of a "
    "recording and write OUT/keypoints.npz, from which tracker track, fit-model and sync then take the detections"
    " instead of detecting them again."
)
EXAMPLE = "tracker keypoints recordings/demo --out out/demo"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker keypoints``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    options.add_recording_argument(inputs)
    outputs.add_argument("--out", help="output folder (default: out/<recording name>)")
    options.add_recording_options(inputs)
    inputs.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    inputs.add_argument("--frames", type=options.positive_int, help="number of frames (default: all)")
    options.add_landmark_model_option(parser)
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Detect (or reuse OUT/keypoints.npz, or the --landmark-model's own file, when it holds the same frames, cameras
    and detector, or go on from where it
    stops when it holds the first of them) and print the time it took per view and how often a person was found per
    camera.  Interrupted (Ctrl-C, SIGTERM, SIGHUP), what was detected is kept in OUT/keypoints.npz and the
    run returns 130 (the CLI reports the signal's own code)."""
    from tracker.atomic import ensure_writable_folder
    from tracker.io.recording import open_recording
    from tracker.landmarks.detect_recording import cache_file, detect_recording

    rec = open_recording(args.recording, options.camera_names(args.cameras), args.calib)
    if not 0 <= args.start < rec.frame_count:
        raise TrackerInputError(
            f"{rec.path}: --start {args.start} is outside its frames 0..{rec.frame_count - 1}; pick a frame inside them"
        )
    stop = rec.frame_count if args.frames is None else min(rec.frame_count, args.start + args.frames)
    out = ensure_writable_folder(options.output_folder(args.out, rec))
    path = cache_file(out, rec, args.landmark_model)
    started = time.perf_counter()
    try:
        keypoints, detected = detect_recording(
            rec,
            args.start,
            stop,
            cache=path,
            progress=options.bar(args, "detecting", "frame"),
            landmark_model=args.landmark_model,
        )
    except KeyboardInterrupt:
        print(
            f"tracker: interrupted: the frames detected so far are saved in {path}; run it again for the rest",
            file=sys.stderr,
        )
        return stop_signals.INTERRUPTED
    spent = ""
    if detected:
        views = detected * len(rec.cameras)
        held = f", {stop - args.start - detected} of them there already" if detected < stop - args.start else ""
        spent = f"{held}, {1e3 * (time.perf_counter() - started) / views:.1f} ms per view with decoding"
    print(
        f"{'wrote' if detected else 'reused'} {path} (frames {args.start}..{stop - 1}, {len(rec.cameras)} cameras"
        f"{spent})"
    )
    found = (keypoints.confidence.max(axis=2) > 0).mean(axis=0)
    for name, share in zip(keypoints.camera_names, found):
        print(f"  {name}: a person in {100 * share:.1f} % of the frames")
    return 0
