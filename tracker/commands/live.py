"""``tracker live``: track cameras live (V4L2 through OpenCV), optionally recording them.

    tracker live --camera /dev/video0 --camera /dev/video2 --calib C --model M --init I
                 [--size WxH] [--fps F] [--record DIR] [--out DIR] [--view]

How cameras are matched, captured, dropped and recorded: :mod:`tracker.apps.live`.
"""

from __future__ import annotations

import argparse
import sys
from contextlib import ExitStack
from pathlib import Path

from tracker import stop_signals
from tracker.commands import options
from tracker.errors import TrackerInputError

HELP = "track cameras live (V4L2 through OpenCV), optionally recording them"

ABOUT = (
    "Track the body from cameras plugged into this machine (or from video files played in real time) as the "
    "frames arrive, and write the poses to OUT/poses.npz; --view shows it in the browser as it goes and --record "
    "keeps the frames as a recording folder."
)
EXAMPLE = (
    "tracker live --camera /dev/video0 --camera /dev/video2 --calib rig.toml --model models/human.toml --init "
    "init.toml --view"
)


def size(text: str) -> tuple[int, int]:
    """Argument type: WIDTHxHEIGHT in pixels."""
    width, _, height = text.lower().partition("x")
    if not (width.isdigit() and height.isdigit() and int(width) > 0 and int(height) > 0):
        raise argparse.ArgumentTypeError(f"must be WIDTHxHEIGHT in pixels, e.g. 640x480, got {text}")
    return int(width), int(height)


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker live``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    viewer = parser.add_argument_group("viewer")
    inputs.add_argument(
        "--camera",
        action="append",
        required=True,
        metavar="[NAME=]DEVICE",
        help="a camera: a V4L2 device such as /dev/video0, or a video file played at its frame "
        "rate; repeat for each camera; matched to the calibration's cameras in order, or "
        "to the one called NAME",
    )
    inputs.add_argument("--calib", required=True, help="calibration.toml of the cameras")
    inputs.add_argument("--model", required=True, help="body model TOML")
    inputs.add_argument("--init", required=True, help="pose at the first frame (init.toml)")
    inputs.add_argument(
        "--size",
        type=size,
        metavar="WxH",
        help="image size to ask the cameras for (default: each camera's calibrated size, which the camera must give)",
    )
    inputs.add_argument(
        "--fps",
        type=options.positive_float,
        help="frame rate to ask the cameras for (default: the driver's); a video file is played at this rate "
        "(default: its own)",
    )
    outputs.add_argument("--out", help="output folder for poses.npz (default out/live)")
    outputs.add_argument(
        "--record",
        metavar="DIR",
        help="also write the tracked frames as a recording folder that `tracker track DIR --smooth none` replays to "
        "the same poses",
    )
    options.add_tuning_options(parser, recorded=False)
    options.add_keypoint_options(
        parser,
        "offer every N-th frame set to the 2-D keypoint detector, a worker process that takes one when it is free "
        "(the tracker never waits), and fuse its landmarks with the edges",
    )
    from tracker.landmarks.landmark_models import LIVE

    options.add_landmark_model_option(parser, LIVE)
    options.add_live_view_options(viewer, "while it tracks")
    options.add_viewer_options(viewer, record=False)


def run(args: argparse.Namespace) -> int:
    """``tracker live``: 0 when the sources ended, 128 plus the signal's number after a stop signal (130 after
    Ctrl-C, 143 after SIGTERM, 129 after SIGHUP); TrackerInputError for bad input and
    when every camera stopped delivering (after the output is written)."""
    from tracker.apps.live import DEFAULT_OUT, Recorder, assign_cameras, drops, open_sources, track_live
    from tracker.camera import load_calibration
    from tracker.io.capture import Capture
    from tracker.io.posefile import at_frame, load_pose_file
    from tracker.model import load_model
    from tracker.tracking.frame_loop import Tracker

    calibration_path = Path(args.calib)
    rig = assign_cameras(args.camera, load_calibration(calibration_path), calibration_path)
    cameras = [camera for camera, _ in rig]
    model = load_model(args.model)
    init = load_pose_file(args.init, model)
    out = Path(args.out) if args.out else DEFAULT_OUT
    with ExitStack() as stack:
        sources = open_sources(
            [device for _, device in rig], cameras, size=args.size, fps=args.fps, calibration=calibration_path
        )
        capture = stack.enter_context(Capture(sources, [camera.name for camera in cameras]))
        # live landmarks are an earlier frame set's, moved by the motion tracked since: they cannot lead a limb
        # the edges lost (Lead.retry), which would take it to where it was then, nor judge the predicted motion
        # or the frame's (ConstantVelocity.carried, KeypointCue.dragged), having moved with the last poses
        settings = options.settings_from(args, capture.fps).but(
            keypoints=dict(lead=0.0, drag=0.0), motion=dict(check_prediction=False)
        )
        tracker = Tracker(model, cameras, init, settings)
        print(
            "live: "
            + ", ".join(
                f"{camera.name} = {source.name} ({source.size[0]}x{source.size[1]}, {source.fps:g} fps)"
                for camera, source in zip(cameras, sources)
            ),
            file=sys.stderr,
        )
        recorder = None
        if args.record:
            copies: dict[str, Path | bytes] = {
                "calibration.toml": calibration_path,
                "model.toml": Path(args.model),
                "init.toml": at_frame(args.init, 0),  # the live run's first frame is the recording's frame 0
            }
            recorder = stack.enter_context(Recorder(Path(args.record), cameras, capture.fps, copies))
        view = None
        if args.view:
            from tracker.viewer.live_view import LiveView
            from tracker.viewer.scene import Scene, start_server

            server = start_server(args.host, args.port)
            stack.callback(server.stop)
            view = LiveView(
                Scene(server, model, cameras, tracker.settings.solve.robust_c), tracker, rate=args.view_rate
            )
            stack.callback(view.close)
        detector = None
        step = options.keypoint_step_at(args, capture.fps)
        if step:
            from tracker.landmarks.live_detection import LiveDetector

            detector = LiveDetector(cameras, step, landmark_model=args.landmark_model)
            stack.callback(detector.close)
            print("starting the keypoint detector...", file=sys.stderr, flush=True)
            detector.wait_until_ready()
        summary = track_live(
            capture, tracker, cameras=cameras, out=out, recorder=recorder, view=view, detector=detector
        )
    counts = summary.counts
    print(f"wrote {out / 'poses.npz'} ({summary.frames} frames)")
    if recorder is not None:
        print(
            f"wrote recording {args.record} ({summary.recorded} frames; `tracker track {args.record} --smooth none` "
            "with the same settings replays them)"
        )
    rate = summary.frames / summary.seconds if summary.seconds > 0 else 0.0
    captured = ", ".join(f"{name} {count}" for name, count in zip(counts.names, counts.captured))
    print(f"frames per second: {rate:.1f} tracked; frames captured: {captured}")
    print(f"sets: {counts.sets} paired, {counts.taken} tracked; {drops(counts)}")
    if detector is not None:
        print(
            f"keypoints: {detector.used} detections fused; the detector took {detector.taken} of the "
            f"{detector.offered} frame sets offered"
        )
    if summary.stopped_by:
        options.say_interrupted()
        return stop_signals.exit_code(summary.stopped_by)
    if not counts.live:
        raise TrackerInputError(
            f"every camera stopped delivering (see above); the {summary.frames} frames "
            f"tracked are in {out / 'poses.npz'}; check the cameras and their connections"
        )
    return 0
