"""``tracker points``: fit and track a deformable multi-part model to 3-D markers (C3D, TRC)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from tracker.commands import options
from tracker.commands.viewing import serve

HELP = "fit and track a deformable multi-part model to 3-D markers (C3D, TRC)"

ABOUT = (
    "Fit a model of joined, deformable parts to 3-D marker positions from motion capture (C3D or TRC), follow it "
    "through the frames and write OUT/poses.npz and OUT/shapes.npz; --view shows the fitted parts in the browser."
)
EXAMPLE = "tracker points tests/data/markers/Vicon.c3d --model models/vicon_arm.points.toml --frames 40"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker points``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    viewer = parser.add_argument_group("viewer")
    inputs.add_argument("markers", metavar="FILE", help="marker file: .c3d or .trc")
    inputs.add_argument("--model", required=True, help="points model TOML: parts, their markers and parents")
    outputs.add_argument("--out", help="output folder for poses.npz and shapes.npz (default: out/<file name>)")
    inputs.add_argument(
        "--start",
        type=int,
        help="first frame, counted from 0 in the file (default: the first with 3 markers seen on every part)",
    )
    inputs.add_argument("--frames", type=options.positive_int, help="number of frames to span (default: all)")
    inputs.add_argument("--every", type=options.positive_int, default=1, help="fit every N-th frame (default 1)")
    parser.add_argument(
        "--level",
        choices=("rigid", "global", "local"),
        default="rigid",
        help="what moves after the first frame: rigid (pose only, the shapes fitted on the first "
        "frame; default), global (also the superquadric shape) or local (also the nodes)",
    )
    fit: dict[str, Any] = dict(choices=("first-order", "second-order"), dest="fit")
    parser.add_argument(
        "--fit",
        default="first-order",
        help="how the parts follow the markers in time: first-order (default), --steps fitting steps per "
        "frame, no momentum; second-order: parts with mass and momentum (faster, looser), and a part whose "
        "markers vanish keeps moving",
        **fit,
    )
    parser.add_argument("--dynamics", **fit | options.renamed("--fit"))  # --dynamics is the motion prior in track
    parser.add_argument(
        "--steps",
        type=options.positive_int,
        default=40,
        help="fitting steps per frame with --fit first-order (default 40)",
    )
    parser.add_argument(
        "--sigma",
        type=options.positive_float,
        default=0.01,
        help="marker noise, metres: how much the data weigh against the membrane (default 0.01)",
    )
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")
    viewer.add_argument(
        "--view", action="store_true", help="then show the fitted parts, markers and joints in the browser viewer"
    )
    options.add_viewer_options(viewer)


def run(args: argparse.Namespace) -> int:
    """Fit, write poses.npz and shapes.npz, print the residuals per part; then show or record them if asked.
    130 after Ctrl-C with the frames done written."""
    import numpy as np

    from tracker.io.markers import read_markers
    from tracker.io.poses import PosesWriter, load_poses
    from tracker.overwrite import keep_inputs
    from tracker.physics.points import PointsSettings, load_points_model, start_frame, track
    from tracker.physics.shapes import ShapesWriter
    from tracker.status import LOST, TRACKED, UNCERTAIN

    markers = read_markers(args.markers)
    model = load_points_model(args.model)
    points = markers.select(model.marker_names)
    first = start_frame(points, model, args.start)
    frames = range(first, len(points) if args.frames is None else min(len(points), first + args.frames), args.every)
    settings = PointsSettings(sigma=args.sigma, steps=args.steps, level=args.level, dynamics=args.fit)
    out = Path(args.out) if args.out else Path("out") / markers.path.stem
    keep_inputs(
        [out / "poses.npz", out / "shapes.npz", args.record],
        [(args.markers, "the marker file being fitted"), (args.model, "the points model being read")],
        "write the results elsewhere (--out, --record)",
    )
    print(
        f"fitting {markers.path} frames {markers.first_frame + frames.start}..{markers.first_frame + frames[-1]} "
        f"(every {args.every}, "
        f"{markers.rate:g} Hz) with model {model.name!r}: {len(model.parts)} parts, "
        f"{len(model.joint_names)} joints, {len(model.marker_names)} markers",
        file=sys.stderr,
    )
    shapes = ShapesWriter(out / "shapes.npz", model)
    interrupted = False
    progress = options.bar(args, None, "frame", leave=True)
    started = time.perf_counter()
    with PosesWriter(out / "poses.npz", list(model.parts), list(model.joint_names), markers.rate) as writer:
        try:
            fits = track((points[f] for f in frames), model, settings=settings, interval=args.every / markers.rate)
            for index, fitted in progress(zip(frames, fits), total=len(frames)):
                shapes.append(markers.first_frame + index, fitted)  # before poses: see shapes.write below
                writer.append(
                    markers.first_frame + index,
                    fitted.poses,
                    fitted.joints,
                    status=fitted.status,
                    residual=fitted.rms * 1000.0,
                )
        except KeyboardInterrupt:
            interrupted = True
        finally:
            done = len(writer)
            final = shapes.write(done)  # the frames poses.npz holds, even if Ctrl-C fell between the two appends
    elapsed = time.perf_counter() - started
    results = load_poses(out / "poses.npz")
    counts = np.bincount(results["status"], minlength=3)
    print(
        f"{'interrupted after' if interrupted else 'fitted'} {done} frames in {elapsed:.1f} s "
        f"({done / elapsed if elapsed else 0:.1f} frames/s): {counts[TRACKED]} with every part seen, "
        f"{counts[UNCERTAIN]} with a part unseen, {counts[LOST]} lost"
    )
    if done:
        table = final["residual"] * 1000.0
        print("RMS marker-to-node distance per part, mm (median / 95th percentile / max over frames):")
        for p, name in enumerate(model.parts):
            column = table[:, p][np.isfinite(table[:, p])]
            if len(column):
                print(
                    f"  {name:<14} {len(model.markers[p]):>2} markers  {np.median(column):6.1f} "
                    f"{np.percentile(column, 95):6.1f} {column.max():6.1f}"
                )
        print(f"joint violation: max {final['violation'].max() * 1000.0:.3g} mm")
    print(f"wrote {out / 'poses.npz'} and {out / 'shapes.npz'}")
    if interrupted:
        options.say_interrupted()
        return 130
    if not done or not (args.view or args.record):
        return 0
    from tracker.viewer.marker_view import PointsView
    from tracker.viewer.scene import start_server

    view = PointsView(
        start_server(args.host, args.port, quiet=not args.view),
        results,
        final,
        points[results["frame"] - markers.first_frame],
        markers.rate / args.every,
    )
    view.show(0)
    if args.record:
        view.record(Path(args.record), progress=not args.quiet)
        print(f"wrote {args.record}")
    return serve(f"showing {out} ({done} frames)") if args.view else 0
