"""The ``tracker`` command line (formats.md): parse, call, report; no algorithm here.

Bad input raises :class:`TrackerInputError` and exits with code 2 and one line;
an interrupted run (Ctrl-C) keeps the frames already written and exits 130.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import sys
import threading
import time
import warnings
from pathlib import Path

from tracker.errors import TrackerInputError


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _share(text: str) -> float:
    value = float(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {text}")
    return value


def _size(text: str) -> tuple[int, int]:
    width, _, height = text.lower().partition("x")
    if not (width.isdigit() and height.isdigit() and int(width) > 0 and int(height) > 0):
        raise argparse.ArgumentTypeError(f"must be WIDTHxHEIGHT in pixels, e.g. 640x480, got {text}")
    return int(width), int(height)


def _port(text: str) -> int:
    value = int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port number 0-65535, got {text}")
    return value


def _percentages(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or not all(0 < v <= 100 for v in values):
        raise argparse.ArgumentTypeError(f"must be percentages 1-100 separated by commas, e.g. 100,25, got {text}")
    return values


def _variances(text: str) -> tuple[float, ...]:
    """Comma-separated variances; whole numbers stay ints so they print as the paper's 10, 5, 1, 0."""
    try:
        values = tuple(int(float(v)) if float(v).is_integer() else float(v) for v in text.split(","))
    except (ValueError, OverflowError):
        values = ()
    if not values or not all(0 <= v < float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"must be variances >= 0 separated by commas, e.g. 10,0, got {text}")
    return values


def _cameras(text: str | None) -> list[str] | None:
    return [c.strip() for c in text.split(",") if c.strip()] if text else None


def _choose(given: str | None, found: Path | None, what: str, option: str, rec: Path) -> Path:
    if given:
        return Path(given)
    if found is None:
        raise TrackerInputError(f"{rec}: no {what} in the recording folder; pass {option}")
    return found


def cmd_track(args: argparse.Namespace) -> int:
    import numpy as np
    from tqdm import tqdm

    from tracker.evaluate import evaluate, format_report
    from tracker.io.posefile import load_pose_file
    from tracker.io.poses import PosesWriter, load_poses
    from tracker.io.recording import capture_times, frames
    from tracker.model import joint_centres
    from tracker.track import LOST, TRACKED, UNCERTAIN, Tracker

    if args.record and not args.view:
        raise TrackerInputError(f"{args.record}: --record writes the viewer session; add --view")
    rec, model = _opened(args)
    if not 0 <= args.start < rec.frame_count:
        raise TrackerInputError(f"{rec.path}: --start {args.start} is outside its frames 0..{rec.frame_count - 1}; "
                                "pick a frame inside them")
    init = load_pose_file(_choose(args.init, rec.init_path, "init.toml", "--init", rec.path), model)
    settings = settings_from(args, rec.fps)
    out = Path(args.out) if args.out else Path("out") / rec.path.resolve().name
    stop = rec.frame_count if args.frames is None else min(rec.frame_count, args.start + args.frames)
    background = _background(args, rec, out)
    print(f"tracking {rec.path} frames {args.start}..{stop - 1} with {len(rec.cameras)} camera(s) "
          f"({', '.join(c.name for c in rec.cameras)}), model {model.name!r} ({model.size} components)",
          file=sys.stderr)
    print("preparing the numba kernels (compiled once, then cached)...", file=sys.stderr, flush=True)
    tracker = Tracker(model, rec.cameras, init, settings)
    tracker.warm_up()
    truth = _truth(rec)
    live = _live_view(args, rec, model, init, settings, truth) if args.view else None
    overlay = None
    if args.overlay:
        from tracker.viewer.overlay import OverlayVideo

        overlay = OverlayVideo(Path(args.overlay), rec.cameras, rec.fps, model.size, settings.robust_c)
    if background is None:
        prepare = tracker.smooth
    else:
        from tracker.foreground import preparers

        prepare = preparers(background, tracker.smooth, keep_grey=overlay is not None)
    counts = {TRACKED: 0, UNCERTAIN: 0, LOST: 0}
    residuals = []
    interrupted = False
    times, last = capture_times(rec), None  # a live recording's capture times: its frames' time and time steps
    started = time.perf_counter()
    with PosesWriter(out / "poses.npz", list(model.names), list(model.joint_names), rec.fps) as writer:
        try:
            for index, images in tqdm(frames(rec, args.start, stop, prepare=prepare, colour=background is not None),
                                      total=stop - args.start, unit="frame", disable=args.quiet, file=sys.stderr):
                shown = images
                if background is not None and overlay is not None:
                    shown, images = zip(*images)
                at = None if times is None else float(times[index])
                begun = time.perf_counter()
                result = tracker.step(images, smoothed=True, dt=None if at is None or last is None else at - last)
                spent = time.perf_counter() - begun
                last = at
                writer.append(index, result.poses, joint_centres(result.poses), result.status, result.residual,
                              spent, at)
                if live is not None:
                    live.offer(index, images, result, spent)
                if overlay is not None:
                    overlay.write(shown, tracker.inspect())
                counts[result.status] += 1
                residuals.append(result.residual)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            if overlay is not None:
                overlay.close()
    elapsed = time.perf_counter() - started
    if live is not None:
        live.close()
    done = len(residuals)
    print(f"wrote {out / 'poses.npz'} ({done} frames)")
    if interrupted:
        print("interrupted: the frames done so far are saved", file=sys.stderr)
        return 130
    fps = done / elapsed if elapsed > 0 else float("inf")
    print(f"frames per second: {fps:.1f} ({len(rec.cameras)} views, {settings.iterations} iterations per frame)")
    print(f"mean residual: {np.nanmean(residuals) if np.isfinite(residuals).any() else float('nan'):.2f} px")
    print(f"status: {counts[TRACKED]} tracked, {counts[UNCERTAIN]} uncertain, {counts[LOST]} lost")
    results = load_poses(out / "poses.npz") if truth is not None or live is not None else None
    if truth is not None:
        print(format_report(evaluate(results, truth)))
    if live is not None and done > 0:
        from tracker.viewer.review import Review

        review = Review(live.scene, rec, model, results, truth, settings)
        review.show(done - 1)
        return _serve(f"tracking done; the viewer now reviews {out / 'poses.npz'}", review)
    return 0


def _background(args: argparse.Namespace, rec, out: Path):
    """The --background of the run: None, the median of the recording (also saved under ``out``), or a folder."""
    if args.background == "none":
        return None
    from tracker.foreground import SAMPLES, load_background, median_background, sample_indices, save_background

    if args.background != "median":
        return load_background(args.background, rec)
    background = median_background(rec, SAMPLES, _bar(args, "background", "frame"))
    folder = save_background(background, rec, out / "background")
    print(f"background: per-pixel median of {len(sample_indices(rec.frame_count, SAMPLES))} frames per camera, saved in {folder} "
          f"(reuse with --background {folder})", file=sys.stderr)
    return background


def _truth(rec):
    from tracker.io.poses import load_poses

    return load_poses(rec.truth_path) if rec.truth_path is not None else None


def _scene(args: argparse.Namespace, rec, model, settings, truth=None):
    from tracker.viewer.scene import Scene, start_server

    server = start_server(args.host, args.port)
    names = None if truth is None else list(truth["joint_names"])
    return Scene(server, model, rec.cameras, settings.robust_c, names)


def _live_view(args: argparse.Namespace, rec, model, init, settings, truth):
    import numpy as np

    from tracker.viewer.live import LiveView
    from tracker.viewer.review import truth_rows

    record = Path(args.record) if args.record else None
    return LiveView(_scene(args, rec, model, settings, truth), model, rec.cameras, init, settings,
                    rate=args.view_rate, truth=truth_rows(truth, np.arange(rec.frame_count)), record=record)


def _serve(message: str, *closing) -> int:
    """Keep the viewer up until Ctrl-C (then exit 0: everything is already written)."""
    print(f"{message}; press Ctrl-C to quit", file=sys.stderr, flush=True)
    stop = threading.Event()
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    for item in closing:
        item.close()
    return 0


def _opened(args: argparse.Namespace):
    """The recording (``--cameras``, ``--calib``) and the body model (``--model``, else the recording's) a
    command works on."""
    from tracker.io.recording import open_recording
    from tracker.model import load_model

    rec = open_recording(args.recording, _cameras(args.cameras), args.calib)
    return rec, load_model(_choose(args.model, rec.model_path, "model.toml", "--model", rec.path))


def _bar(args: argparse.Namespace, desc: str, unit: str):
    """A transient progress bar on stderr (off with --quiet) to wrap an iterable in."""
    from tqdm import tqdm

    return functools.partial(tqdm, desc=desc, unit=unit, disable=args.quiet, file=sys.stderr, leave=False)


def _tracked(given: str | None, rec, model) -> tuple[Path, dict]:
    """The poses.npz a run of ``model`` on ``rec`` wrote (``given``, else out/<recording name>/poses.npz),
    loaded and checked against both; ``usable`` marks its frames with a finite pose that is not lost."""
    import numpy as np

    from tracker.io.poses import load_poses
    from tracker.track import LOST

    path = Path(given) if given else Path("out") / rec.path.resolve().name / "poses.npz"
    if not given and not path.is_file():
        raise TrackerInputError(f"{path}: no poses to review or refine; run `tracker track {rec.path}` first "
                                "or pass --poses")
    results = load_poses(path)
    if len(results["joints"]) == 0:
        raise TrackerInputError(f"{path}: holds no frames; track some first")
    if "poses" not in results or list(results["component_names"]) != list(model.names):
        raise TrackerInputError(f"{path}: its components do not match the model {model.name!r}; "
                                "pass the --model it was tracked with")
    if results["frame"].max(initial=0) >= rec.frame_count:
        raise TrackerInputError(f"{path}: frames beyond the recording's {rec.frame_count}; "
                                "pass the recording it was tracked from")
    results["usable"] = np.isfinite(results["poses"]).all(axis=(1, 2, 3))
    if "status" in results:
        results["usable"] &= results["status"] != LOST
    return path, results


def cmd_background(args: argparse.Namespace) -> int:
    from tracker.foreground import MINIMUM_FREE, cleared_background, save_background
    from tracker.io.atomic import ensure_writable_folder

    rec, model = _opened(args)
    poses_path, results = _tracked(args.poses, rec, model)
    usable = results["usable"]
    if usable.sum() < MINIMUM_FREE + 2:
        raise TrackerInputError(f"{poses_path}: only {usable.sum()} frames with a pose that is not lost; "
                                "track more frames, or mend the run first")
    if args.samples is not None and args.samples < MINIMUM_FREE + 2:
        raise TrackerInputError(f"--samples {args.samples}: too few to clear anything (a pixel needs "
                                f"{MINIMUM_FREE} frames free of the body); use {MINIMUM_FREE + 2} or more")
    out = ensure_writable_folder(Path(args.out) if args.out else poses_path.parent / "background-cleared")
    given = {key: value for key, value in (("samples", args.samples), ("margin", args.margin)) if value is not None}
    cleared = cleared_background(rec, model, results["frame"][usable], results["poses"][usable],
                                 progress=_bar(args, "background", "frame"), **given)
    folder = save_background(cleared.background, rec, out)
    print(f"background: median of {len(cleared.frames)} tracked frames per camera with the body masked out "
          f"(frames {cleared.frames[0]}..{cleared.frames[-1]}), saved in {folder} (use with --background {folder})")
    for camera, replaced, hidden in zip(rec.cameras, cleared.replaced, cleared.hidden):
        print(f"  {camera.name}: {100 * replaced:.1f} % of pixels cleared of the body, "
              f"{100 * hidden:.1f} % covered in nearly every frame (kept as the plain median)")
    return 0


def cmd_refine(args: argparse.Namespace) -> int:
    import numpy as np

    from tracker.calibrate.refine import ROUNDS, refine_rig
    from tracker.camera import load_calibration, save_calibration
    from tracker.foreground import camera_stacks, sample_indices
    from tracker.io.atomic import ensure_writable_folder
    from tracker.io.readers import grey
    from tracker.track import Tracker

    rec, model = _opened(args)
    poses_path, results = _tracked(args.poses, rec, model)
    names = [camera.name for camera in rec.cameras]
    fixed = _cameras(args.fix) or []
    unknown = [name for name in fixed if name not in names]
    if unknown:
        raise TrackerInputError(f"{rec.calibration_path}: --fix names {', '.join(unknown)}, not among the cameras "
                                f"tracked ({', '.join(names)})")
    out = Path(args.out)
    if out.resolve() == rec.calibration_path.resolve():
        raise TrackerInputError(f"{out}: is the calibration being refined; write the refined rig to another file")
    ensure_writable_folder(out.parent)
    stop = rec.frame_count if args.frames is None else args.start + args.frames
    usable = results["usable"] & (results["frame"] >= args.start) & (results["frame"] < stop)
    if usable.sum() == 0:
        raise TrackerInputError(f"{poses_path}: no frame in {args.start}..{stop - 1} has a pose that is not lost; "
                                "pick frames the run tracked (--start, --frames)")
    picked = np.flatnonzero(usable)[sample_indices(int(usable.sum()), args.samples)]
    settings = settings_from(args, rec.fps)
    smooth = Tracker(model, rec.cameras, results["poses"][picked[0]], settings).smooth
    if args.background:
        from tracker.foreground import load_background, preparers

        prepare = preparers(load_background(args.background, rec), smooth)
    else:
        prepare = [lambda frame: smooth(grey(frame))] * len(rec.cameras)
    stacks = camera_stacks(rec, results["frame"][picked], _bar(args, "reading", "frame"))
    frames = list(zip(*([prepare[k](image) for image in stack] for k, stack in enumerate(stacks))))
    refined = refine_rig(model, rec.cameras, results["poses"][picked], frames, settings, args.rounds or ROUNDS,
                         [names.index(name) for name in fixed], not args.hold_poses, _bar(args, "refining", "round"))
    moved = {camera.name: camera for camera in refined.cameras}
    rig = [dataclasses.replace(camera, rotation=moved[camera.name].rotation,
                               translation=moved[camera.name].translation) if camera.name in moved else camera
           for camera in load_calibration(rec.calibration_path)]
    save_calibration(rig, out)
    print(f"refined {rec.calibration_path} to the body of {poses_path} in {len(picked)} frames "
          f"({results['frame'][picked[0]]}..{results['frame'][picked[-1]]}); wrote {out} (use with --calib {out})")
    for k, name in enumerate(names):
        print(f"  {name}: turned {refined.rotation_deg[k]:.2f} deg, moved {1000 * refined.shift_m[k]:.0f} mm; "
              f"edge distance {refined.residual_before[k]:.2f} -> {refined.residual_after[k]:.2f} px"
              + (" (fixed)" if name in fixed else ""))
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from tracker.track import Settings
    from tracker.viewer.review import Review

    rec, model = _opened(args)
    poses_path, results = _tracked(args.poses, rec, model)
    settings = Settings()
    background = None
    if args.background:
        from tracker.foreground import load_background

        background = load_background(args.background, rec)
    truth = _truth(rec)
    review = Review(_scene(args, rec, model, settings, truth), rec, model, results, truth, settings, background)
    review.show(0)
    if args.record:
        review.record(Path(args.record), progress=not args.quiet)
        review.close()
        print(f"wrote {args.record}")
        return 0
    return _serve(f"reviewing {poses_path} ({len(results['frame'])} frames)", review)


def cmd_init(args: argparse.Namespace) -> int:
    from tracker.io.posefile import load_pose_file
    from tracker.model import rest_poses
    from tracker.track import Settings
    from tracker.viewer.placement import Placement, in_view

    rec, model = _opened(args)
    start = Path(args.init) if args.init else rec.init_path
    poses = load_pose_file(start, model) if start is not None else rest_poses(model, in_view(rec.cameras))
    out = Path(args.out)
    Placement(_scene(args, rec, model, Settings()), rec, model, poses, out)
    return _serve(f"placing the first pose of {rec.path}; save writes {out}")


def cmd_eval(args: argparse.Namespace) -> int:
    from tracker.evaluate import evaluate, format_report
    from tracker.io.poses import load_poses

    print(format_report(evaluate(load_poses(args.poses), load_poses(args.truth))))
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    from tracker.synth import synthesize

    synthesize(args.model, args.calib, args.out, motion=args.motion, frames=args.frames, start=args.start,
               stride=args.stride, seed=args.seed)
    print(f"wrote recording {args.out}")
    return 0


def cmd_live(args: argparse.Namespace) -> int:
    from tracker import live

    return live.run(args)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from tracker.calibrate import command

    return command.run(args)


def cmd_export(args: argparse.Namespace) -> int:
    from tracker.io import export

    return export.run(args)


def cmd_bench(args: argparse.Namespace) -> int:
    import json

    from tracker import bench

    settings = settings_from(args)
    print("preparing the numba kernels, then timing (medians of several passes)...", file=sys.stderr, flush=True)
    if args.scaling:
        result = bench.scaling()
        print(json.dumps(result, indent=2) if args.json else bench.format_scaling(result))
        return 0
    result = bench.run(Path(args.recording) if args.recording else bench.DEMO, settings, args.repeats)
    print(json.dumps(result, indent=2) if args.json else bench.format_table(result))
    return 0


def cmd_points(args: argparse.Namespace) -> int:
    import numpy as np
    from tqdm import tqdm

    from tracker.io.markers import read_markers
    from tracker.io.poses import PosesWriter
    from tracker.io.shapes import ShapesWriter
    from tracker.physics.points import PointsSettings, load_points_model, start_frame, track
    from tracker.track import LOST, TRACKED, UNCERTAIN

    markers = read_markers(args.markers)
    model = load_points_model(args.model)
    points = markers.select(model.marker_names)
    first = start_frame(points, model, args.start)
    frames = range(first, len(points) if args.frames is None else min(len(points), first + args.frames),
                   args.every)
    settings = PointsSettings(sigma=args.sigma, steps=args.steps, level=args.level, dynamics=args.dynamics)
    out = Path(args.out) if args.out else Path("out") / markers.path.stem
    print(f"fitting {markers.path} frames {markers.first_frame + frames.start}..{markers.first_frame + frames[-1]} "
          f"(every {args.every}, "
          f"{markers.rate:g} Hz) with model {model.name!r}: {len(model.parts)} parts, "
          f"{len(model.joint_names)} joints, {len(model.marker_names)} markers", file=sys.stderr)
    shapes = ShapesWriter(out / "shapes.npz", model)
    interrupted = False
    started = time.perf_counter()
    with PosesWriter(out / "poses.npz", list(model.parts), list(model.joint_names), markers.rate) as writer:
        try:
            fits = track((points[f] for f in frames), model, settings, args.every / markers.rate)
            for index, fitted in tqdm(zip(frames, fits), total=len(frames), unit="frame", disable=args.quiet,
                                      file=sys.stderr):
                shapes.append(markers.first_frame + index, fitted)  # before poses: see shapes.write below
                writer.append(markers.first_frame + index, fitted.poses, fitted.joints, fitted.status,
                              fitted.rms * 1000.0)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            done = len(writer)
            final = shapes.write(done)  # the frames poses.npz holds, even if Ctrl-C fell between the two appends
    elapsed = time.perf_counter() - started
    results = writer.arrays()
    counts = np.bincount(results["status"], minlength=3)
    print(f"{'interrupted after' if interrupted else 'fitted'} {done} frames in {elapsed:.1f} s "
          f"({done / elapsed if elapsed else 0:.1f} frames/s): {counts[TRACKED]} with every part seen, "
          f"{counts[UNCERTAIN]} with a part unseen, {counts[LOST]} lost")
    if done:
        table = final["residual"] * 1000.0
        print("RMS marker-to-node distance per part, mm (median / 95th percentile / max over frames):")
        for p, name in enumerate(model.parts):
            column = table[:, p][np.isfinite(table[:, p])]
            if len(column):
                print(f"  {name:<14} {len(model.markers[p]):>2} markers  {np.median(column):6.1f} "
                      f"{np.percentile(column, 95):6.1f} {column.max():6.1f}")
        print(f"joint violation: max {final['violation'].max() * 1000.0:.3g} mm")
    print(f"wrote {out / 'poses.npz'} and {out / 'shapes.npz'}")
    if interrupted or not done or not (args.view or args.record):
        return 130 if interrupted else 0
    from tracker.viewer.points import PointsView
    from tracker.viewer.scene import start_server

    view = PointsView(start_server(args.host, args.port, quiet=not args.view), results, final,
                      points[results["frame"] - markers.first_frame], markers.rate / args.every)
    view.show(0)
    if args.record:
        view.record(Path(args.record), progress=not args.quiet)
        print(f"wrote {args.record}")
    return _serve(f"showing {out} ({done} frames)") if args.view else 0


def cmd_experiment(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from tracker.physics import tables

    if args.name == "insect" and (args.densities or args.variances):
        raise TrackerInputError("--densities and --variances choose the superquadric grid; the insect has neither")
    if args.name == "superquadric":
        from tracker.physics import experiment

        densities = args.densities or experiment.DENSITIES
        variances = args.variances or experiment.VARIANCES
        frames = {} if args.frames is None else {"frames": args.frames}
        with tqdm(total=len(densities) * len(variances), unit="cell", disable=args.quiet, file=sys.stderr) as bar:
            rows = experiment.run(densities, variances, seed=args.seed, progress=lambda row: bar.update(), **frames)
        claims = experiment.check_claims(rows)
        if args.json:
            print(json.dumps({"rows": rows, "paper": {f"{d}/{v}": list(e) for (d, v), e in
                                                       experiment.PAPER_TABLES.items()},
                              "errors": list(experiment.ERRORS),
                              "claims": [{"claim": c, "held": h, "detail": d} for c, h, d in claims]}, indent=1))
        else:
            print("\n".join(tables.superquadric_table(rows) + ["", "claims:"] + tables.claims_lines(claims)))
        return 0
    from tracker.physics import insect

    frames = args.frames or insect.PERIOD
    results = {}
    for name, sparse in (("dense", False), ("sparse (7 points per part)", True)):
        with tqdm(total=frames, unit="frame", desc=name.split()[0], disable=args.quiet, file=sys.stderr) as bar:
            results[name] = insect.run(sparse, frames=frames, seed=args.seed,
                                       progress=lambda *_: bar.update())
    if args.json:
        print(json.dumps({name: {**r.summary, "violation": r.violation.tolist(),
                                 "position_error": r.position_error.tolist()} for name, r in results.items()},
                         indent=1))
    else:
        print("\n".join(tables.insect_table(results)))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tracker", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    track = sub.add_parser("track", help="track a recording folder, write DIR/poses.npz and print a summary")
    track.add_argument("recording", help="recording folder (calibration.toml and one video per camera)")
    track.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    track.add_argument("--init", help="pose at the first frame (default: the recording's init.toml)")
    track.add_argument("--out", help="output folder (default: out/<recording name>)")
    _recording_options(track)
    track.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    track.add_argument("--frames", type=_positive_int, help="number of frames to track (default: all)")
    add_tuning_options(track)
    track.add_argument("--background", default="none", metavar="none|median|DIR",
                       help="search edges in the difference from the empty scene instead of the grey image: "
                            "'median' estimates it from the recording (the person must move about), DIR holds "
                            "<camera>.png images of it (default none)")
    track.add_argument("--quiet", action="store_true", help="no progress bar")
    track.add_argument("--overlay", metavar="VIDEO",
                       help="also write a video (.mp4/.avi) of every camera with the tracked outlines and edge "
                            "searches")
    add_live_view_options(track, "then review the result")
    _viewer_options(track)
    track.set_defaults(run=cmd_track)

    background = sub.add_parser("background", help="estimate the empty scene with a tracked run's body masked out, "
                                                   "for tracker track --background")
    background.add_argument("recording", help="recording folder")
    background.add_argument("--poses", help="poses.npz of a run on it (default: out/<recording name>/poses.npz)")
    background.add_argument("--model", help="body model TOML it was tracked with (default: the recording's "
                                            "model.toml)")
    background.add_argument("--out", help="folder for <camera>.png (default: background-cleared beside the poses)")
    _recording_options(background)
    background.add_argument("--samples", type=_positive_int,
                            help="tracked frames per camera the median is taken over (default 50)")
    background.add_argument("--margin", type=_positive_float,
                            help="pixels the tracked silhouette is widened by, at a 480-pixel short side; grows "
                                 "with the image (default 12)")
    background.add_argument("--quiet", action="store_true", help="no progress bar")
    background.set_defaults(run=cmd_background)

    refine = sub.add_parser("refine", help="refine the rig's extrinsics to the outlines of a tracked body, "
                                           "write a calibration.toml")
    refine.add_argument("recording", help="recording folder")
    refine.add_argument("--poses", help="poses.npz of a run on it (default: out/<recording name>/poses.npz)")
    refine.add_argument("--model", help="body model TOML it was tracked with (default: the recording's model.toml)")
    refine.add_argument("--out", required=True, help="calibration TOML to write")
    _recording_options(refine)
    refine.add_argument("--fix", metavar="CAMERAS", help="comma-separated cameras to hold as calibrated")
    refine.add_argument("--start", type=int, default=0, help="first frame to use (default 0)")
    refine.add_argument("--frames", type=_positive_int, help="number of frames to use from there (default: all)")
    refine.add_argument("--samples", type=_positive_int, default=30,
                        help="tracked frames the outlines are measured in, spread evenly (default 30)")
    refine.add_argument("--rounds", type=_positive_int,
                        help="rounds of measuring and moving the cameras, searches narrowing (default 8)")
    refine.add_argument("--background", metavar="DIR",
                        help="an empty scene (<camera>.png, e.g. from tracker background): search the differences "
                             "from it instead of the grey images")
    refine.add_argument("--hold-poses", action="store_true",
                        help="take the poses as right (e.g. ground truth, motion capture) and move only the cameras; "
                             "by default each frame's body is fitted again after every round")
    add_tuning_options(refine, ("spacing", "search_range", "iterations", "max_turn"))
    refine.add_argument("--quiet", action="store_true", help="no progress bars")
    refine.set_defaults(run=cmd_refine)

    view = sub.add_parser("view", help="review poses.npz over its recording in the browser viewer")
    view.add_argument("recording", help="recording folder")
    view.add_argument("--poses", help="poses.npz to review (default: out/<recording name>/poses.npz)")
    view.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    _recording_options(view)
    view.add_argument("--background", metavar="DIR",
                      help="the empty scene a run was tracked against (tracker track --background; a median one is "
                           "saved in OUT/background): the panels then show and search the difference images")
    view.add_argument("--quiet", action="store_true", help="no progress bar while recording")
    _viewer_options(view)
    view.set_defaults(run=cmd_view)

    init = sub.add_parser("init", help="place the first pose by hand in the browser viewer and save init.toml")
    init.add_argument("recording", help="recording folder")
    init.add_argument("--out", required=True, help="init.toml to write")
    init.add_argument("--model", help="body model TOML (default: the recording's model.toml)")
    init.add_argument("--init", help="pose to start from (default: the recording's init.toml, else the rest pose)")
    _recording_options(init)
    _viewer_options(init, record=False)
    init.set_defaults(run=cmd_init)

    ev = sub.add_parser("eval", help="MPJPE, PA-MPJPE, PCK@50mm and lost frames of poses.npz against truth.npz")
    ev.add_argument("poses")
    ev.add_argument("truth")
    ev.set_defaults(run=cmd_eval)

    synth = sub.add_parser("synth", help="render a recording with ground truth from a model, a rig and a motion")
    synth.add_argument("--model", required=True, help="body model TOML")
    synth.add_argument("--calib", required=True, help="camera rig calibration.toml")
    synth.add_argument("--motion", required=True, help="bvh:PATH (a BVH clip, retargeted) or procedural")
    synth.add_argument("--out", required=True, help="recording folder to write")
    synth.add_argument("--frames", type=_positive_int, default=160, help="frames to render (default 160)")
    synth.add_argument("--start", type=int, default=0, help="first BVH frame (default 0)")
    synth.add_argument("--stride", type=_positive_int, default=2, help="BVH frames per rendered frame (default 2)")
    synth.add_argument("--seed", type=int, default=0, help="random seed for noise and backgrounds")
    synth.set_defaults(run=cmd_synth)
    live = sub.add_parser("live", help="track cameras live (V4L2 through OpenCV), optionally recording them")
    live.add_argument("--camera", action="append", required=True, metavar="[NAME=]DEVICE",
                      help="a camera: a V4L2 device such as /dev/video0, or a video file played at its frame "
                           "rate; repeat for each camera; matched to the calibration's cameras in order, or "
                           "to the one called NAME")
    live.add_argument("--calib", required=True, help="calibration.toml of the cameras")
    live.add_argument("--model", required=True, help="body model TOML")
    live.add_argument("--init", required=True, help="pose at the first frame (init.toml)")
    live.add_argument("--size", type=_size, metavar="WxH",
                      help="image size to ask the cameras for (default: each camera's calibrated size, "
                           "which the camera must give)")
    live.add_argument("--fps", type=_positive_float, help="frame rate to ask the cameras for (default: the driver's)")
    live.add_argument("--out", help="output folder for poses.npz (default out/live)")
    live.add_argument("--record", metavar="DIR",
                      help="also write the tracked frames as a recording folder that `tracker track DIR` "
                           "replays to the same poses")
    add_tuning_options(live)
    add_live_view_options(live, "while it tracks")
    _viewer_options(live, record=False)
    live.set_defaults(run=cmd_live)

    calibration = sub.add_parser("calibrate", help="calibrate a camera rig from videos or photos of a board")
    calibration.add_argument("folder", metavar="DIR",
                             help="folder with one board video (<cam>.mp4|.avi|.mkv) or image folder (<cam>/) per "
                                  "camera, frame-synchronous")
    calibration.add_argument("--board", required=True, metavar="SPEC",
                             help="chessboard:COLSxROWS:SQUARE_M (inner corners) or "
                                  "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT (squares); add :inverted for "
                                  "light-on-dark boards")
    calibration.add_argument("--out", required=True, metavar="calibration.toml", help="the calibration file to write")
    calibration.add_argument("--fix-intrinsics", metavar="calibration.toml",
                             help="take each camera's K and distortion from this file (by camera name) and keep "
                                  "them fixed")
    calibration.add_argument("--intrinsics-only", action="store_true",
                             help="calibrate each camera's intrinsics only (cameras need not share views)")
    calibration.add_argument("--world", choices=("first-camera", "board"), default="first-camera",
                             help="world frame: the first camera (default), or the board where first seen, "
                                  "on the floor with z up")
    calibration.add_argument("--inverted", action="store_true", help="the board is printed light on dark")
    calibration.add_argument("--refine-intrinsics", action="store_true",
                             help="let the bundle adjustment refine the intrinsics as well as the poses")
    calibration.add_argument("--max-frames", type=_positive_int, default=300, metavar="N",
                             help="search about N frames per camera, evenly spread (default 300)")
    calibration.set_defaults(run=cmd_calibrate)

    exporter = sub.add_parser("export", help="write poses.npz as TRC, C3D, BVH or CSV for other tools")
    exporter.add_argument("poses", metavar="POSES", help="poses.npz written by tracker track (or a truth.npz)")
    exporter.add_argument("--to", required=True, metavar="FORMAT", type=str.lower,
                          help="trc (OpenSim/Pose2Sim markers, mm, z up), c3d (POINT data, mm, z up), "
                               "bvh (the model's skeleton for Blender, metres, y up) or csv (metres, z up)")
    exporter.add_argument("--out", help="output file (default: POSES with the format's suffix, e.g. poses.trc)")
    exporter.add_argument("--model", help="body model TOML the poses were tracked with (bvh only, where it is needed)")
    exporter.add_argument("--fps", type=_positive_float,
                          help="frames per second (default: from the poses file's frame and time arrays)")
    exporter.set_defaults(run=cmd_export)

    points = sub.add_parser("points", help="fit and track a deformable multi-part model to 3-D markers (C3D, TRC)")
    points.add_argument("markers", metavar="FILE", help="marker file: .c3d or .trc")
    points.add_argument("--model", required=True, help="points model TOML: parts, their markers and parents")
    points.add_argument("--out", help="output folder for poses.npz and shapes.npz (default: out/<file name>)")
    points.add_argument("--start", type=int,
                        help="first frame, counted from 0 in the file (default: the first with 3 markers seen on "
                             "every part)")
    points.add_argument("--frames", type=_positive_int, help="number of frames to span (default: all)")
    points.add_argument("--every", type=_positive_int, default=1, help="fit every N-th frame (default 1)")
    points.add_argument("--level", choices=("rigid", "global", "local"), default="rigid",
                        help="what moves after the first frame: rigid (pose only, the shapes fitted on the first "
                             "frame; default), global (also the superquadric shape) or local (also the nodes)")
    points.add_argument("--dynamics", choices=("first-order", "second-order"), default="first-order",
                        help="first-order (default): --steps fitting steps per frame, no momentum; second-order: "
                             "parts with mass and momentum follow the markers in time (about 3-5x faster, looser), "
                             "and a part whose markers vanish keeps moving")
    points.add_argument("--steps", type=_positive_int, default=40,
                        help="fitting steps per frame with --dynamics first-order (default 40)")
    points.add_argument("--sigma", type=_positive_float, default=0.01,
                        help="marker noise, metres: how much the data weigh against the membrane (default 0.01)")
    points.add_argument("--quiet", action="store_true", help="no progress bar")
    points.add_argument("--view", action="store_true",
                        help="then show the fitted parts, markers and joints in the browser viewer")
    _viewer_options(points)
    points.set_defaults(run=cmd_points)

    experiment = sub.add_parser("experiment", help="the physics paper's experiments: Tables I-IV, or the insect")
    experiment.add_argument("name", choices=("superquadric", "insect"),
                            help="superquadric: the error analysis of Tables I-IV (4 densities x 4 noise levels, "
                                 "beside the paper's values); insect: five parts and four joints tracked from dense "
                                 "and sparse points")
    experiment.add_argument("--frames", type=_positive_int,
                            help="frames per run (default: 20 for superquadric, 36 for insect)")
    experiment.add_argument("--seed", type=int, default=0, help="random seed of the data and noise (default 0)")
    experiment.add_argument("--densities", type=_percentages, metavar="LIST",
                            help="superquadric: comma-separated data densities in percent (default 100,75,50,25)")
    experiment.add_argument("--variances", type=_variances, metavar="LIST",
                            help="superquadric: comma-separated noise variances (default 10,5,1,0)")
    experiment.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    experiment.add_argument("--quiet", action="store_true", help="no progress bar")
    experiment.set_defaults(run=cmd_experiment)

    bench = sub.add_parser("bench", help="per-stage timings, frames per second and the decode-only floor")
    bench.add_argument("recording", nargs="?", help="recording folder (default: the bundled demo)")
    bench.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    bench.add_argument("--scaling", action="store_true",
                       help="time one iteration against the number of components (7-120) and of cameras (1-8)")
    bench.add_argument("--repeats", type=_positive_int, default=3, help="passes per figure (default 3)")
    add_tuning_options(bench, ("iterations", "spacing", "resample_every"))
    bench.set_defaults(run=cmd_bench)
    return parser


TUNING = ("iterations", "spacing", "resample_every", "search_range", "motion", "damping", "max_turn")


def _recording_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cameras", help="comma-separated camera names (default: every camera with a video)")
    parser.add_argument("--calib", metavar="TOML",
                        help="calibration to use instead of the recording's calibration.toml (e.g. from tracker refine)")


def add_tuning_options(parser: argparse.ArgumentParser, which: tuple[str, ...] = TUNING) -> None:
    """The tracker's tuning options (Settings fields) that a command offers."""
    options = {
        "iterations": (["--iterations"], dict(type=_positive_int, help="IRLS iterations per frame (default 6)")),
        "spacing": (["--spacing"], dict(type=_positive_float, help="pixels between outline samples (default 4)")),
        "resample_every": (["--resample-every"], dict(
            type=_positive_int, help="sample the outlines afresh every N-th iteration, moving them to first order "
                                     "between (default 3; 1 = every iteration)")),
        "search_range": (["--search-range"], dict(
            type=_positive_int, help="edge search in the first iteration, pixels either side (default 20; the "
                                     "last uses 6)")),
        "motion": (["--dynamics", "--motion"], dict(
            dest="motion", choices=("none", "constant-velocity", "kalman"),
            help="motion model that predicts each frame's pose: none, constant-velocity (default) or kalman "
                 "(a second-order Kalman filter per component whose prediction and covariance set the prior)")),
        "max_turn": (["--max-turn"], dict(
            type=_positive_float, metavar="RAD",
            help="largest rotation of any component in one iteration; a larger step is scaled down whole, which "
                 "keeps a body from flipping on clutter but slows it in fast motion (default: no limit)")),
        "damping": (["--damping"], dict(type=_share, help="share of the last frame's motion carried into the "
                                                          "prediction (default 1; 0.5 steadies a single camera)")),
    }
    for key in which:
        flags, kwargs = options[key]
        parser.add_argument(*flags, **kwargs)


def settings_from(args: argparse.Namespace, frame_rate: float | None = None):
    """Settings with the tuning options the user gave (the others at their defaults) and the frame rate
    of the images (the Kalman filter's time step)."""
    from tracker.track import Settings

    given = {key: getattr(args, key, None) for key in TUNING}
    given["frame_rate"] = frame_rate
    return Settings(**{key: value for key, value in given.items() if value is not None})


def add_live_view_options(parser: argparse.ArgumentParser, after: str) -> None:
    parser.add_argument("--view", action="store_true",
                        help=f"show the run in the browser viewer (about 30 updates a second), {after}")
    parser.add_argument("--view-rate", type=_positive_float, default=30.0,
                        help="viewer updates per second while tracking (default 30)")


def _viewer_options(parser: argparse.ArgumentParser, record: bool = True) -> None:
    parser.add_argument("--host", default="127.0.0.1",
                        help="address the viewer listens on (default 127.0.0.1; 0.0.0.0 opens it to the network)")
    parser.add_argument("--port", type=_port, default=8080,
                        help="viewer port (default 8080, or the next free one; 0 picks any free port)")
    if record:
        parser.add_argument("--record", metavar="FILE.viser",
                            help="also write the viewer session as a .viser file for viser's static client")


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"tracker: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices only: no BLAS thread storms
    import cv2

    cv2.setNumThreads(1)  # the reader threads already run in parallel; OpenCV's own pool only contends
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.showwarning = _show_warning
    try:
        return args.run(args)
    except TrackerInputError as exc:
        print(f"tracker: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("tracker: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
