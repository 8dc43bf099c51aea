"""``tracker fit-model``: fit a body model's joints and part sizes to the person in a recording."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tracker.commands import options

HELP = "fit a body model's joints and part sizes to the person in a recording, write a model TOML"

ABOUT = (
    "Measure the person in a recording: fit a body model's joint positions and part sizes (lengths and radii) to "
    "the keypoint detector's landmarks, then to the outlines in the images, and write the fitted model for "
    "tracker track --model. It needs two cameras or more."
)
EXAMPLE = "tracker fit-model recordings/demo --out me.toml"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker fit-model``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    options.add_recording_argument(inputs)
    outputs.add_argument("--out", required=True, help="model TOML to write")
    inputs.add_argument(
        "--model",
        help="model to start from (default: the recording's model.toml, else models/human.toml)",
    )
    parser.add_argument(
        "--frames",
        type=options.positive_int,
        default=40,
        help="frames to fit to, spread over the recording (default 40)",
    )
    parser.add_argument(
        "--asymmetric",
        action="store_true",
        help="fit left and right parts apart (default: one size for both)",
    )
    options.add_recording_options(inputs)
    options.add_cache_option(outputs)
    options.add_landmark_model_option(parser)
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Fit, write ``--out`` and print what changed (docs/fit-model.md)."""
    from tracker.atomic import ensure_writable_folder, writable_file
    from tracker.landmarks.detect_recording import cache_file
    from tracker.landmarks.detector import require_detector
    from tracker.model import model_from_dict
    from tracker.overwrite import keep_inputs
    from tracker.shape.model_fit import GENERIC, fit_and_save
    from tracker.tomlfile import read_toml

    rec = options.recording(args)
    start = Path(args.model) if args.model else rec.model_path or GENERIC
    document = read_toml(start, "model", "pass --model with an existing models/*.toml")
    model_from_dict(document, start)  # a bad model is a one-line error before any detection
    keep_inputs(
        [args.out],
        [(start, "the model the fit starts from"), *options.recording_inputs(rec)],
        "write the fitted model to another file",
    )
    writable_file(args.out)  # before minutes of fitting, not after
    require_detector(args.landmark_model)
    cache = cache_file(ensure_writable_folder(options.output_folder(args.cache, rec)), rec, args.landmark_model)
    fit_and_save(
        rec,
        document,
        args.out,
        source=str(start),
        frames=args.frames,
        tie_sides=not args.asymmetric,
        cache=cache,
        landmark_model=args.landmark_model,
        progress=options.bar(args, "fitting", "step"),
        say=lambda line: print(line, file=sys.stderr),
    )
    print(f"wrote {args.out}")
    return 0
