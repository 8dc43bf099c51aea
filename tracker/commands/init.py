"""``tracker init``: place the first pose by hand in the browser viewer and save init.toml."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tracker.commands import options
from tracker.commands.viewing import scene, serve
from tracker.errors import TrackerInputError

HELP = "place the first pose by hand in the browser viewer and save init.toml"

ABOUT = (
    "Place the body in the first frame by hand in the web browser (move and turn the body and each limb, or let "
    "it snap to the images) and save the pose as the init.toml that tracker track starts from. It starts from the"
    " recording's init.toml, else from the pose fitted to the keypoint detector's landmarks."
)
EXAMPLE = "tracker init recordings/demo --out my-init.toml"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker init``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    viewer = parser.add_argument_group("viewer")
    options.add_recording_argument(inputs)
    outputs.add_argument("--out", required=True, help="init.toml to write")
    inputs.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    inputs.add_argument(
        "--init",
        help="pose to start from, of the frame --start names (default: the recording's init.toml if it is of that "
        "frame, else the pose fitted to the keypoints)",
    )
    inputs.add_argument("--start", type=int, default=0, help="the frame to place the pose in (default 0)")
    options.add_recording_options(inputs)
    options.add_cache_option(outputs)
    options.add_landmark_model_option(parser)
    options.add_viewer_options(viewer, record=False)


def run(args: argparse.Namespace) -> int:
    """Serve the placement until Ctrl-C (its save button writes ``--out``)."""
    from tracker.atomic import writable_file
    from tracker.io.posefile import load_pose_file, starting_pose_file
    from tracker.overwrite import keep_inputs
    from tracker.tracking.settings import Settings
    from tracker.viewer.placement import Placement

    rec, model = options.opened(args)
    if not 0 <= args.start < rec.frame_count:
        raise TrackerInputError(
            f"{rec.path}: --start {args.start} is outside its frames 0..{rec.frame_count - 1}; pick a frame inside them"
        )
    start = starting_pose_file(args.start, args.init, rec.init_path)
    out = Path(args.out)
    keep_inputs(
        [out],
        [(start, "the pose the placement starts from"), (args.model, "the body model being read")]
        + options.recording_inputs(rec),
        "save the placed pose to another file (and track with --init FILE)",
    )
    writable_file(out)  # before the placement, whose save button would fail in the viewer's thread
    poses = (
        load_pose_file(start, model)
        if start is not None
        else keypoint_pose(rec, model, args.start, cache=args.cache, landmark_model=args.landmark_model)
    )
    Placement(scene(args, rec, model, settings=Settings()), rec, model, poses, out, frame=args.start)
    return serve(f"placing the pose of frame {args.start} of {rec.path}; save writes {out}")


def keypoint_pose(rec, model, start: int, *, cache: str | None = None, landmark_model: str) -> np.ndarray:
    """The pose fitted to the keypoints (by ``landmark_model``) of the frames from ``start`` (docs/keypoints.md,
    "Automatic first pose"), their detections cached in the folder ``cache`` (``--cache``, default out/<recording
    name>); the rest pose where the cameras look when the detector is not installed."""
    from tracker.atomic import ensure_writable_folder
    from tracker.landmarks.detect_recording import cache_file, detect_recording
    from tracker.landmarks.detector import missing
    from tracker.model import rest_poses
    from tracker.seeding.first_pose import FRAMES, first_pose
    from tracker.viewer.placement import in_view

    reason = missing()
    if reason is not None:
        print(f"starting from the rest pose: {reason}")
        return rest_poses(model, in_view(rec.cameras))
    stop = min(rec.frame_count, start + FRAMES)
    path = cache_file(ensure_writable_folder(options.output_folder(cache, rec)), rec, landmark_model)
    keypoints, _ = detect_recording(rec, start, stop, cache=path, landmark_model=landmark_model)
    print(f"starting from the pose fitted to the keypoints of frames {start}..{stop - 1} ({path})")
    return first_pose(rec, model, keypoints)
