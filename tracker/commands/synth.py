"""``tracker synth``: render a recording with ground truth from a model, a rig and a motion."""

from __future__ import annotations

import argparse

from tracker.commands.options import camera_names, camera_seconds, positive_float, positive_int

HELP = "render a recording with ground truth from a model, a rig and a motion"

ABOUT = (
    "Render a test recording whose true poses are known: a body model going through a motion, filmed by the "
    "cameras of a calibration, written as a recording folder with its truth.npz (and init.toml), ready for "
    "tracker track and tracker eval."
)
EXAMPLE = "tracker synth --model models/human.toml --calib calib/ring4.toml --motion procedural --out out/ring"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker synth``: what to render, and how the render departs from the plain model."""
    from tracker.synthetic.texture import CHOICES  # numpy only: cheap at start-up, unlike tracker.synthetic.synth

    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    inputs.add_argument("--model", required=True, help="body model TOML")
    inputs.add_argument("--calib", required=True, help="camera rig calibration.toml")
    inputs.add_argument(
        "--motion",
        required=True,
        help="bvh:PATH (a BVH clip, retargeted), procedural, athletic (hops, kicks, spins) or seated (at a desk)",
    )
    outputs.add_argument("--out", required=True, help="recording folder to write")
    outputs.add_argument(
        "--force",
        action="store_true",
        help="replace the recording already in --out (its videos, calibration and truth); never the files read",
    )
    parser.add_argument("--frames", type=positive_int, default=160, help="frames to render (default 160)")
    parser.add_argument("--start", type=int, default=0, help="first BVH frame (default 0)")
    parser.add_argument("--stride", type=positive_int, default=2, help="BVH frames per rendered frame (default 2)")
    parser.add_argument(
        "--fps", type=positive_float, default=60.0, help="frame rate of the made-up motions (default 60)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed for noise, backgrounds, motion, body, texture")
    parser.add_argument(
        "--texture", choices=CHOICES, default="none", help="clothing pattern on the body (default none)"
    )
    parser.add_argument(
        "--body",
        choices=("model", "capsules", "stretched"),
        default="model",
        help="model: the tracking model itself; capsules: capsule parts of perturbed sizes; stretched: the model's "
        "parts with perturbed lengths and radii; the truth is then the rendered body's joints (default model)",
    )
    parser.add_argument(
        "--jitter",
        type=float,
        default=0.1,
        help="capsules, stretched: lengths and radii within +-this share (default 0.1)",
    )
    parser.add_argument(
        "--table", metavar="CAMERAS", help="comma-separated cameras (or all) with a table before them hiding the legs"
    )
    parser.add_argument(
        "--zoom", type=positive_float, default=1.0, help="focal lengths x this (> 1 cuts the body at the borders)"
    )
    parser.add_argument(
        "--distance", type=positive_float, default=1.0, help="cameras moved back, this many times as far (default 1)"
    )
    parser.add_argument(
        "--motion-blur", type=positive_int, default=1, help="sub-frame renders averaged per frame (default 1: none)"
    )
    parser.add_argument(
        "--shutter", type=positive_float, default=0.5, help="motion blur's exposure in frame intervals (default 0.5)"
    )
    parser.add_argument(
        "--backdrop",
        choices=("photos", "room"),
        default="photos",
        help="photos: the background photos (with people in them); room: an empty furnished room rendered from "
        "the rig (default photos)",
    )
    parser.add_argument(
        "--face", action="store_true", help="paint a face on the front of the head and hair on its back and top"
    )
    outputs.add_argument(
        "--no-init",
        action="store_true",
        help="write the first true pose as truth_init.toml, not init.toml, so that tracking needs --init",
    )
    parser.add_argument(
        "--time-offsets",
        type=camera_seconds,
        default=(),
        metavar="CAM=SECONDS,...",
        help="render these cameras late (or early, negative) by so many seconds, as a rig that is not frame-locked "
        "records; the truth keeps the frames' times and the recording does not say (tracker sync finds them)",
    )
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Render the recording folder and say where it is."""
    from tracker.synthetic.synth import Staging, synthesize

    staging = Staging(
        texture=args.texture,
        body=args.body,
        jitter=args.jitter,
        tables=tuple(camera_names(args.table) or ()),
        zoom=args.zoom,
        distance=args.distance,
        motion_blur=args.motion_blur,
        shutter=args.shutter,
        backdrop=args.backdrop,
        face=args.face,
        time_offsets=args.time_offsets,
    )
    synthesize(
        args.model,
        args.calib,
        args.out,
        motion=args.motion,
        frames=args.frames,
        start=args.start,
        stride=args.stride,
        seed=args.seed,
        fps=args.fps,
        progress=not args.quiet,
        staging=staging,
        write_init=not args.no_init,
        replace=args.force,
    )
    print(f"wrote recording {args.out}")
    return 0
