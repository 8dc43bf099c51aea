"""``tracker synth``: render a recording with ground truth from a model, a rig and a motion."""

from __future__ import annotations

import argparse

from tracker.commands.options import positive_int

HELP = "render a recording with ground truth from a model, a rig and a motion"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker synth``."""
    parser.add_argument("--model", required=True, help="body model TOML")
    parser.add_argument("--calib", required=True, help="camera rig calibration.toml")
    parser.add_argument("--motion", required=True, help="bvh:PATH (a BVH clip, retargeted) or procedural")
    parser.add_argument("--out", required=True, help="recording folder to write")
    parser.add_argument("--frames", type=positive_int, default=160, help="frames to render (default 160)")
    parser.add_argument("--start", type=int, default=0, help="first BVH frame (default 0)")
    parser.add_argument("--stride", type=positive_int, default=2, help="BVH frames per rendered frame (default 2)")
    parser.add_argument("--seed", type=int, default=0, help="random seed for noise and backgrounds")


def run(args: argparse.Namespace) -> int:
    """Render the recording folder and say where it is."""
    from tracker.synth import synthesize

    synthesize(
        args.model,
        args.calib,
        args.out,
        motion=args.motion,
        frames=args.frames,
        start=args.start,
        stride=args.stride,
        seed=args.seed,
    )
    print(f"wrote recording {args.out}")
    return 0
