"""``tracker track``: track a recording folder, write DIR/poses.npz and print a summary."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from tracker.commands import options
from tracker.commands.viewing import scene, serve
from tracker.errors import TrackerInputError

if TYPE_CHECKING:
    from tracker.evaluate import Report

HELP = "track a recording folder, write DIR/poses.npz and print a summary"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker track``."""
    parser.add_argument("recording", help="recording folder (calibration.toml and one video per camera)")
    parser.add_argument("--out", help="output folder (default: out/<recording name>)")
    add_tracking_options(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--overlay",
        metavar="VIDEO",
        help="also write a video (.mp4/.avi) of every camera with the tracked outlines and edge searches",
    )
    options.add_live_view_options(parser, "then review the result")
    options.add_viewer_options(parser)


def add_tracking_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker track`` that say how a recording is tracked (``tracker batch`` passes them on)."""
    parser.add_argument(
        "--model",
        help="body model TOML (default: the recording's model.toml, else models/human.toml fitted to the person "
        "and written to OUT/model.toml)",
    )
    parser.add_argument(
        "--init",
        help="pose at the first frame (default: the recording's init.toml, else fitted to the keypoints of the "
        "first frames)",
    )
    options.add_recording_options(parser)
    parser.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    parser.add_argument("--frames", type=options.positive_int, help="number of frames to track (default: all)")
    options.add_tuning_options(parser)
    options.add_keypoint_options(parser)
    parser.add_argument(
        "--background",
        default="none",
        metavar="none|median|DIR",
        help="search edges in the difference from the empty scene instead of the grey image: "
        "'median' estimates it from the recording (the person must move about), DIR holds "
        "<camera>.png images of it (default none)",
    )


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What a run of ``tracker track`` did: what its summary prints, and the viewer left to review it."""

    poses: Path  # the poses.npz written
    frames: int  # frames tracked
    views: int  # cameras tracked in
    iterations: int  # IRLS iterations per frame
    fps: float  # frames per second of the tracking loop (decoding included, start-up not)
    residual: float  # mean residual of the frames, pixels (NaN when no frame found an edge)
    counts: dict[int, int]  # frames per status (tracker.status)
    declined: int | None  # re-seeds the edges declined; None without the keypoint cue
    interrupted: bool  # stopped by Ctrl-C: the frames done are written
    report: Report | None  # the accuracy against the recording's truth.npz, when it has one
    review: Callable[[], int] | None = dataclasses.field(default=None, compare=False)  # --view: serve the review


def run(args: argparse.Namespace) -> int:
    """Track, write poses.npz and print the summary (and the evaluation against the recording's truth);
    130 after Ctrl-C with the frames done written."""
    outcome = track(args)
    print(f"wrote {outcome.poses} ({outcome.frames} frames)")
    if outcome.interrupted:
        print("interrupted: the frames done so far are saved", file=sys.stderr)
        return 130
    print_summary(outcome)
    return outcome.review() if outcome.review is not None else 0


def print_summary(outcome: Outcome) -> None:
    """What a finished run prints after the file it wrote: speed, residual, status counts and the accuracy."""
    from tracker.evaluate import format_report
    from tracker.status import LOST, RESEEDED, TRACKED, UNCERTAIN

    print(f"frames per second: {outcome.fps:.1f} ({outcome.views} views, {outcome.iterations} iterations per frame)")
    print(f"mean residual: {outcome.residual:.2f} px")
    counts = outcome.counts
    reseeded = ""
    if outcome.declined is not None:
        reseeded = f", {counts[RESEEDED]} re-seeded from the keypoints ({outcome.declined} declined by the edges)"
    print(f"status: {counts[TRACKED]} tracked, {counts[UNCERTAIN]} uncertain, {counts[LOST]} lost{reseeded}")
    if outcome.report is not None:
        print(format_report(outcome.report))


def track(args: argparse.Namespace) -> Outcome:
    """Track the recording of ``args`` (the options of ``tracker track``) and write OUT/poses.npz; after Ctrl-C,
    the frames done are written and the outcome says it was interrupted."""
    import numpy as np

    from tracker.evaluate import evaluate
    from tracker.io.poses import PosesWriter, load_poses
    from tracker.io.readers import keeping_grey
    from tracker.io.recording import capture_times
    from tracker.io.stepwrite import step_and_write
    from tracker.keypoints.stream import tracked_frames
    from tracker.status import LOST, RESEEDED, TRACKED, UNCERTAIN
    from tracker.tracking.track import Tracker, reductions

    if args.record and not args.view:
        raise TrackerInputError(f"{args.record}: --record writes the viewer session; add --view")
    rec = options.recording(args)
    if not 0 <= args.start < rec.frame_count:
        raise TrackerInputError(
            f"{rec.path}: --start {args.start} is outside its frames 0..{rec.frame_count - 1}; pick a frame inside them"
        )
    settings = options.settings_from(args, rec.fps)
    out = options.output_folder(args.out, rec)
    stop = rec.frame_count if args.frames is None else min(rec.frame_count, args.start + args.frames)
    step = options.keypoint_step_at(args, rec.fps)
    model = _model(args, rec, out, step)
    background = _background(args, rec, out)
    init, begin = _first_pose(args, rec, model, stop, out, settings, step)
    print(
        f"tracking {rec.path} frames {begin}..{stop - 1} with {len(rec.cameras)} camera(s) "
        f"({', '.join(c.name for c in rec.cameras)}), model {model.name!r} ({model.size} components)",
        file=sys.stderr,
    )
    # the detector starts up while the kernels load; fed the tracker's own images unless they are differences
    stream = _keypoints(
        rec, begin, stop, out, step, None if background is not None else reductions(settings, rec.cameras)
    )
    recovery = None
    if stream is not None:
        from tracker.keypoints.recovery import Recovery

        recovery = Recovery(model, rec.cameras)
    print("preparing the numba kernels (compiled once, then cached)...", file=sys.stderr, flush=True)
    tracker = Tracker(model, rec.cameras, init, settings)
    tracker.warm_up()
    truth = options.truth(rec)
    live = _live_view(args, rec, model, init, settings, truth) if args.view else None
    overlay = None
    if args.overlay:
        from tracker.viewer.overlay import OverlayVideo

        overlay = OverlayVideo(Path(args.overlay), rec.cameras, rec.fps, model.size, settings.robust_c)
    # the overlay and the viewer draw on the frames as they are, not on what the edge search reads (smoothed,
    # reduced at HD, or colour differences)
    shows = overlay is not None or live is not None
    if background is None:
        prepare: Callable[[np.ndarray], object] | list[Callable[[np.ndarray], object]] = (
            keeping_grey(tracker.smooth) if shows else tracker.smooth
        )
    else:
        from tracker.tracking.foreground import preparers

        measured = preparers(background, tracker.smooth)
        prepare = [keeping_grey(camera) for camera in measured] if shows else list(measured)
    counts = {TRACKED: 0, UNCERTAIN: 0, LOST: 0, RESEEDED: 0}
    residuals = []
    interrupted = False
    times, last = capture_times(rec), None  # a live recording's capture times: its frames' time and time steps
    progress = options.bar(args, None, "frame", leave=True)
    started = time.perf_counter()
    with PosesWriter(out / "poses.npz", list(model.names), list(model.joint_names), rec.fps) as writer:
        try:
            read = tracked_frames(stream, rec, begin, stop, prepare=prepare, colour=background is not None)
            for index, images in progress(read, total=stop - begin):
                shown = images
                if shows:
                    shown, images = zip(*images)
                at = None if times is None else float(times[index])
                keypoints = None if stream is None else stream.get(index)
                result, spent = step_and_write(
                    tracker, writer, index, images, at=at, previous=last, keypoints=keypoints, check=recovery
                )
                last = at
                if live is not None:
                    live.offer(index, shown, result, spent)
                if overlay is not None:
                    overlay.write(shown, tracker.inspect())
                counts[result.status] += 1
                residuals.append(result.residual)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            if overlay is not None:
                overlay.close()
            if stream is not None:
                stream.close()
    elapsed = time.perf_counter() - started
    if live is not None:
        live.close()
    done = len(residuals)
    poses = out / "poses.npz"
    results = load_poses(poses) if not interrupted and (truth is not None or live is not None) else None
    report = evaluate(results, truth) if results is not None and truth is not None else None
    review: Callable[[], int] | None = None
    if live is not None and results is not None and done > 0:
        from tracker.viewer.review import Review

        def serve_review() -> int:
            shown = Review(live.scene, rec, model, results, truth, settings)
            shown.show(done - 1)
            return serve(f"tracking done; the viewer now reviews {poses}", shown)

        review = serve_review

    return Outcome(
        poses=poses,
        frames=done,
        views=len(rec.cameras),
        iterations=settings.iterations,
        fps=done / elapsed if elapsed > 0 else float("inf"),
        residual=float(np.nanmean(residuals)) if np.isfinite(residuals).any() else float("nan"),
        counts=counts,
        declined=None if recovery is None else recovery.declined,
        interrupted=interrupted,
        report=report,
        review=review,
    )


def _model(args: argparse.Namespace, rec, out: Path, step: int):
    """The body model: ``--model``, else the recording's model.toml, else models/human.toml fitted to the person
    (:func:`tracker.shape.fit.fit_and_save`), written to OUT/model.toml."""
    from tracker.model import load_model

    if args.model or rec.model_path is not None:
        return load_model(args.model or rec.model_path)
    from tracker.atomic import ensure_writable_folder
    from tracker.keypoints.detector import missing
    from tracker.shape.fit import GENERIC, fit_and_save
    from tracker.tomlfile import read_toml

    reason = missing() if step else "--keypoints off"
    if reason is not None:
        raise TrackerInputError(
            f"{rec.path}: no model.toml in the recording folder, and fitting one needs the keypoint detector "
            f"({reason}); pass --model"
        )
    path = ensure_writable_folder(out) / "model.toml"
    print(f"model: no model.toml, fitting {GENERIC.name} to the person in {rec.path}", file=sys.stderr)
    fit_and_save(
        rec,
        read_toml(GENERIC, "model", "reinstall the tracker: models/human.toml is part of it"),
        path,
        source=str(GENERIC),
        cache=path.parent / "keypoints.npz",
        progress=options.bar(args, "fitting the model", "step"),
        say=lambda line: print(line, file=sys.stderr),
    )
    print(f"model: wrote {path}; pass it with --model to reuse it", file=sys.stderr)
    return load_model(path)


def _first_pose(args: argparse.Namespace, rec, model, stop: int, out: Path, settings, step: int):
    """The pose at the first frame and that frame: ``--init``, else the recording's init.toml, else fitted to the
    keypoints of the first frames (:func:`tracker.keypoints.first_pose.first_pose`, detections cached in
    OUT/keypoints.npz).  When they show nobody, the detector keeps trying a second of frames later, and
    tracking starts where it first finds the person."""
    from tracker.io.posefile import load_pose_file

    given = args.init or rec.init_path
    if given is not None:
        return load_pose_file(given, model), args.start
    if not step:
        raise TrackerInputError(
            f"{rec.path}: no init.toml in the recording folder and --keypoints off; pass --init, or let the "
            "keypoint detector find the first pose (--keypoints every or N)"
        )
    from tracker.atomic import ensure_writable_folder
    from tracker.keypoints.detect import detect_recording
    from tracker.keypoints.first_pose import FRAMES, first_pose

    cache = ensure_writable_folder(out) / "keypoints.npz"
    tries = range(args.start, max(args.start + 1, stop - FRAMES + 1), max(1, round(rec.fps)))
    for begin in tries:
        last = min(stop, begin + FRAMES)
        print(
            f"first pose: no init.toml, fitting the body to the keypoints of frames {begin}..{last - 1}",
            file=sys.stderr,
        )
        keypoints, _ = detect_recording(rec, begin, last, cache=cache)
        try:
            return first_pose(rec, model, keypoints, settings=settings), begin
        except TrackerInputError as error:
            if len(rec.cameras) < 2 or begin == tries[-1]:
                raise
            print(f"first pose: {error}; trying again a second later", file=sys.stderr)
    raise TrackerInputError(f"{rec.path}: no frames to fit a first pose to; pass --init")


def _keypoints(rec, begin: int, stop: int, out: Path, step: int, reduction):
    """The detector's stream of every ``step``-th frame (``--keypoints``; cached in OUT/keypoints.npz), or None
    (off); fed the tracker's images, reduced by ``reduction``, unless that is None."""
    if not step:
        return None
    from tracker.atomic import ensure_writable_folder
    from tracker.keypoints.stream import KeypointStream, schedule_words

    stream = KeypointStream(rec, begin, stop, step, ensure_writable_folder(out) / "keypoints.npz", reduction)
    every = schedule_words(step)
    source = f"reused from {stream.cache}" if stream.reused is not None else "detected beside the tracker"
    print(f"keypoints: {every}, {source}", file=sys.stderr)
    return stream


def _background(args: argparse.Namespace, rec, out: Path):
    """The --background of the run: None, the median of the recording (also saved under ``out``), or a folder."""
    if args.background == "none":
        return None
    from tracker.tracking.foreground import SAMPLES, load_background, median_background, sample_indices, save_background

    if args.background != "median":
        return load_background(args.background, rec)
    background = median_background(rec, SAMPLES, options.bar(args, "background", "frame"))
    folder = save_background(background, rec, out / "background")
    print(
        f"background: per-pixel median of {len(sample_indices(rec.frame_count, SAMPLES))} frames per camera, "
        f"saved in {folder} "
        f"(reuse with --background {folder})",
        file=sys.stderr,
    )
    return background


def _live_view(args: argparse.Namespace, rec, model, init, settings, truth):
    """The viewer following the run (``--view``, ``--view-rate``, ``--record``), with the truth's joints."""
    import numpy as np

    from tracker.viewer.live import LiveView
    from tracker.viewer.review import truth_rows

    record = Path(args.record) if args.record else None
    return LiveView(
        scene(args, rec, model, settings, truth),
        model,
        rec.cameras,
        init,
        settings,
        rate=args.view_rate,
        truth=truth_rows(truth, np.arange(rec.frame_count)),
        record=record,
    )
