"""``tracker background``: the empty scene with a tracked run's body masked out, for ``tracker track --background``."""

from __future__ import annotations

import argparse
from pathlib import Path

from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "estimate the empty scene with a tracked run's body masked out, for tracker track --background"

ABOUT = (
    "Make a picture of the empty scene for each camera from a tracked run: the median of many frames with the "
    "tracked body masked out. tracker track --background then searches the body's edges in the difference from "
    "it, which helps in a cluttered room."
)
EXAMPLE = "tracker background myrec"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker background``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    options.add_recording_argument(inputs)
    inputs.add_argument("--poses", help="poses.npz of a run on it (default: out/<recording name>/poses.npz)")
    inputs.add_argument("--model", help="body model TOML it was tracked with (default: the recording's model.toml)")
    outputs.add_argument("--out", help="folder for <camera>.png (default: background-cleared beside the poses)")
    options.add_recording_options(inputs)
    parser.add_argument(
        "--samples", type=options.positive_int, help="tracked frames per camera the median is taken over (default 50)"
    )
    parser.add_argument(
        "--margin",
        type=options.positive_float,
        help="pixels the tracked silhouette is widened by, at a 480-pixel short side; grows "
        "with the image (default 12)",
    )
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Write <camera>.png of the cleared background and print how much of each camera was cleared."""
    from tracker.atomic import ensure_writable_folder
    from tracker.tracking.foreground import MINIMUM_FREE, cleared_background, save_background

    rec, model = options.opened(args)
    poses_path, results = options.tracked(args.poses, rec, model)
    usable = results["usable"]
    if usable.sum() < MINIMUM_FREE + 2:
        raise TrackerInputError(
            f"{poses_path}: only {usable.sum()} frames with a pose that is not lost; "
            "track more frames, or mend the run first"
        )
    if args.samples is not None and args.samples < MINIMUM_FREE + 2:
        raise TrackerInputError(
            f"--samples {args.samples}: too few to clear anything (a pixel needs "
            f"{MINIMUM_FREE} frames free of the body); use {MINIMUM_FREE + 2} or more"
        )
    out = ensure_writable_folder(Path(args.out) if args.out else poses_path.parent / "background-cleared")
    given = {key: value for key, value in (("samples", args.samples), ("margin", args.margin)) if value is not None}
    cleared = cleared_background(
        rec,
        model,
        frames=results["frame"][usable],
        poses=results["poses"][usable],
        progress=options.bar(args, "background", "frame"),
        **given,
    )
    folder = save_background(cleared.background, rec, out)
    print(
        f"background: median of {len(cleared.frames)} tracked frames per camera with the body masked out "
        f"(frames {cleared.frames[0]}..{cleared.frames[-1]}), saved in {folder} (use with --background {folder})"
    )
    for camera, replaced, hidden in zip(rec.cameras, cleared.replaced, cleared.hidden):
        print(
            f"  {camera.name}: {100 * replaced:.1f} % of pixels cleared of the body, "
            f"{100 * hidden:.1f} % covered in nearly every frame (kept as the plain median)"
        )
    return 0
