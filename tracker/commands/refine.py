"""``tracker refine``: the rig's extrinsics refined to the outlines of a tracked body, written as a calibration.toml."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "refine the rig's extrinsics to the outlines of a tracked body, write a calibration.toml"

ABOUT = (
    "Correct the cameras' positions in the calibration so that the outline of a tracked body fits every camera's "
    "images better, and write the corrected calibration; track again with --calib to use it."
)
EXAMPLE = "tracker refine myrec --out myrec/refined.toml"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker refine``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    options.add_recording_argument(inputs)
    inputs.add_argument("--poses", help="poses.npz of a run on it (default: out/<recording name>/poses.npz)")
    inputs.add_argument("--model", help="body model TOML it was tracked with (default: the recording's model.toml)")
    outputs.add_argument("--out", required=True, help="calibration TOML to write")
    options.add_recording_options(inputs)
    parser.add_argument("--fix", metavar="CAMERAS", help="comma-separated cameras to hold as calibrated")
    inputs.add_argument("--start", type=int, default=0, help="first frame to use (default 0)")
    inputs.add_argument("--frames", type=options.positive_int, help="number of frames to use from there (default: all)")
    parser.add_argument(
        "--samples",
        type=options.positive_int,
        default=30,
        help="tracked frames the outlines are measured in, spread evenly (default 30)",
    )
    parser.add_argument(
        "--rounds",
        type=options.positive_int,
        help="rounds of measuring and moving the cameras, searches narrowing (default 8)",
    )
    inputs.add_argument(
        "--background",
        metavar="DIR",
        help="an empty scene (<camera>.png, e.g. from tracker background): search the differences "
        "from it instead of the grey images",
    )
    parser.add_argument(
        "--hold-poses",
        action="store_true",
        help="take the poses as right (e.g. ground truth, motion capture) and move only the "
        "cameras; by default each frame's body is fitted again after every round",
    )
    options.add_tuning_options(parser, ("--spacing", "--search-range", "--iterations", "--max-turn"))
    outputs.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    """Write the refined calibration and print each camera's move and edge distance before and after."""
    import numpy as np

    from tracker.atomic import ensure_writable_folder
    from tracker.calibrate.refine import ROUNDS, refine_rig
    from tracker.camera import load_calibration, save_calibration
    from tracker.io.readers import grey
    from tracker.overwrite import keep_inputs
    from tracker.tracking.edge_cue import smoother
    from tracker.tracking.foreground import camera_stacks, sample_indices

    rec, model = options.opened(args)
    poses_path, results = options.tracked(args.poses, rec, model)
    names = [camera.name for camera in rec.cameras]
    fixed = options.camera_names(args.fix) or []
    unknown = [name for name in fixed if name not in names]
    if unknown:
        raise TrackerInputError(
            f"{rec.calibration_path}: --fix names {', '.join(unknown)}, not among the cameras "
            f"tracked ({', '.join(names)})"
        )
    out = Path(args.out)
    keep_inputs(
        [out],
        [
            (rec.calibration_path, "the calibration being refined"),
            (poses_path, "the poses file the rig is refined to"),
            (args.model, "the body model being read"),
            *options.recording_inputs(rec),
        ],
        "write the refined rig to another file",
    )
    ensure_writable_folder(out.parent)
    stop = rec.frame_count if args.frames is None else args.start + args.frames
    usable = results["usable"] & (results["frame"] >= args.start) & (results["frame"] < stop)
    if usable.sum() == 0:
        raise TrackerInputError(
            f"{poses_path}: no frame in {args.start}..{stop - 1} has a pose that is not lost; "
            "pick frames the run tracked (--start, --frames)"
        )
    picked = np.flatnonzero(usable)[sample_indices(int(usable.sum()), args.samples)]
    settings = options.settings_from(args, rec.fps)
    smooth = smoother(settings, rec.cameras)
    if args.background:
        from tracker.tracking.foreground import load_background, preparers

        prepare = preparers(load_background(args.background, rec), smooth)
    else:
        prepare = [lambda frame: smooth(grey(frame))] * len(rec.cameras)
    stacks = camera_stacks(rec, results["frame"][picked], options.bar(args, "reading", "frame"))
    frames = list(zip(*([prepare[k](image) for image in stack] for k, stack in enumerate(stacks))))
    refined = refine_rig(
        model,
        rec.cameras,
        results["poses"][picked],
        frames=frames,
        settings=settings,
        rounds=args.rounds or ROUNDS,
        fixed=[names.index(name) for name in fixed],
        refit=not args.hold_poses,
        progress=options.bar(args, "refining", "round"),
    )
    moved = {camera.name: camera for camera in refined.cameras}
    rig = [
        dataclasses.replace(camera, rotation=moved[camera.name].rotation, translation=moved[camera.name].translation)
        if camera.name in moved
        else camera
        for camera in load_calibration(rec.calibration_path)
    ]
    save_calibration(rig, out)
    print(
        f"refined {rec.calibration_path} to the body of {poses_path} in {len(picked)} frames "
        f"({results['frame'][picked[0]]}..{results['frame'][picked[-1]]}); wrote {out} (use with --calib {out})"
    )
    for k, name in enumerate(names):
        print(
            f"  {name}: turned {refined.rotation_deg[k]:.2f} deg, moved {1000 * refined.shift_m[k]:.0f} mm; "
            f"edge distance {refined.residual_before[k]:.2f} -> {refined.residual_after[k]:.2f} px"
            + (" (fixed)" if name in fixed else "")
        )
    return 0
