"""``tracker export``: write a poses.npz as TRC, C3D, BVH or CSV for other tools."""

from __future__ import annotations

import argparse

from tracker.commands.options import positive_float

HELP = "write poses.npz as TRC, C3D, BVH or CSV for other tools"

ABOUT = (
    "Write a tracked run (poses.npz) in a format other tools read: TRC for OpenSim and Pose2Sim, C3D for motion-"
    "capture software, BVH for Blender (it needs the body model) or CSV for a spreadsheet. The file goes beside "
    "POSES unless --out names another."
)
EXAMPLE = "tracker export out/demo/poses.npz --to trc"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker export``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    inputs.add_argument("poses", metavar="POSES", help="poses.npz written by tracker track (or a truth.npz)")
    outputs.add_argument(
        "--to",
        required=True,
        metavar="FORMAT",
        type=str.lower,
        help="trc (OpenSim/Pose2Sim markers, mm, z up), c3d (POINT data, mm, z up), "
        "bvh (the model's skeleton for Blender, metres, y up) or csv (metres, z up)",
    )
    outputs.add_argument("--out", help="output file (default: POSES with the format's suffix, e.g. poses.trc)")
    inputs.add_argument("--model", help="body model TOML the poses were tracked with (bvh only, where it is needed)")
    inputs.add_argument(
        "--fps", type=positive_float, help="frames per second (default: from the poses file's frame and time arrays)"
    )


def run(args: argparse.Namespace) -> int:
    """Write the file and print ``wrote FILE``."""
    from tracker.io.export import export

    target = export(args.poses, args.to, args.out, model=args.model, fps=args.fps)
    print(f"wrote {target}")
    return 0
