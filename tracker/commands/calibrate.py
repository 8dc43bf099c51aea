"""``tracker calibrate``: calibrate a camera rig from videos or photos of a board, write calibration.toml."""

from __future__ import annotations

import argparse
import sys

from tracker.commands.options import positive_int
from tracker.errors import TrackerInputError

HELP = "calibrate a camera rig from videos or photos of a board"

ABOUT = (
    "Find each camera's lens and position from videos or photos of a printed chessboard or ChArUco board filmed "
    "by every camera at once, and write the calibration.toml a recording folder needs. It prints how many pixels "
    "each camera's board corners miss by."
)
EXAMPLE = "tracker calibrate boards/ --board charuco:7x5:0.04:0.03:DICT_4X4_50 --out myrec/calibration.toml"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker calibrate``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    inputs.add_argument(
        "folder",
        metavar="DIR",
        help="folder with one board video (<cam>.mp4|.avi|.mkv) or image folder (<cam>/) per camera, frame-synchronous",
    )
    inputs.add_argument(
        "--board",
        required=True,
        metavar="SPEC",
        help="chessboard:COLSxROWS:SQUARE_M (inner corners) or "
        "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT (squares); add :inverted for "
        "light-on-dark boards",
    )
    outputs.add_argument("--out", required=True, metavar="calibration.toml", help="the calibration file to write")
    inputs.add_argument(
        "--fix-intrinsics",
        metavar="calibration.toml",
        help="take each camera's K and distortion from this file (by camera name) and keep them fixed",
    )
    parser.add_argument(
        "--intrinsics-only",
        action="store_true",
        help="calibrate each camera's intrinsics only (cameras need not share views)",
    )
    parser.add_argument(
        "--world",
        choices=("first-camera", "board"),
        default="first-camera",
        help="world frame: the first camera (default), or the board where first seen, on the floor with z up",
    )
    inputs.add_argument("--inverted", action="store_true", help="the board is printed light on dark")
    parser.add_argument(
        "--refine-intrinsics",
        action="store_true",
        help="let the bundle adjustment refine the intrinsics as well as the poses",
    )
    parser.add_argument(
        "--max-frames",
        type=positive_int,
        default=300,
        metavar="N",
        help="search about N frames per camera, evenly spread (default 300)",
    )


def run(args: argparse.Namespace) -> int:
    """Write the calibration and print the per-camera RMS; returns 0 (errors raise TrackerInputError)."""
    from tracker.atomic import writable_file
    from tracker.calibrate.board import parse_board
    from tracker.calibrate.pipeline import calibrate
    from tracker.camera import save_calibration
    from tracker.overwrite import keep_inputs

    if args.fix_intrinsics and args.intrinsics_only:
        raise TrackerInputError("--fix-intrinsics with --intrinsics-only leaves nothing to calibrate; drop one of them")
    if args.refine_intrinsics and args.fix_intrinsics:
        raise TrackerInputError("--refine-intrinsics contradicts --fix-intrinsics; drop one of them")
    keep_inputs(
        [args.out],
        [(args.fix_intrinsics, "the calibration the intrinsics are taken from (--fix-intrinsics)")],
        "write the new calibration to another file",
    )
    writable_file(args.out)  # before the videos are read, not after
    board = parse_board(args.board, inverted=args.inverted)
    result = calibrate(
        args.folder,
        board,
        intrinsics_only=args.intrinsics_only,
        fixed=args.fix_intrinsics,
        world=args.world,
        refine_intrinsics=args.refine_intrinsics,
        max_frames=args.max_frames,
        progress=sys.stderr.isatty(),
    )
    save_calibration(result.cameras, args.out)
    print(result.report())
    print(f"wrote {args.out}")
    return 0
