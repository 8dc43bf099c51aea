"""``tracker sync``: each camera's capture-time offset from the landmarks' motion, written to REC/sync.toml."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np

from tracker.commands import options
from tracker.errors import TrackerInputError

if TYPE_CHECKING:
    from tracker.apps.sync import Refined
    from tracker.landmarks.time_offsets import Offsets

HELP = "find each camera's capture-time offset from the body's motion, write REC/sync.toml"

ABOUT = (
    "For cameras that do not record in step (webcams, phones, action cameras), find how much later or earlier "
    "each one's frames were taken than the first camera's, from the body's motion the keypoint detector sees, and"
    " write it to REC/sync.toml, which tracker track then reads."
)
EXAMPLE = "tracker sync myrec"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker sync``."""
    inputs = parser.add_argument_group("inputs")
    outputs = parser.add_argument_group("outputs")
    refining = parser.add_argument_group("refining by the edges (--refine)")
    options.add_recording_argument(inputs)
    outputs.add_argument("--out", help="folder for the detections, OUT/keypoints.npz (default: out/<recording name>)")
    options.add_recording_options(inputs)
    parser.add_argument(
        "--reach",
        type=options.positive_float,
        default=0.5,
        metavar="SECONDS",
        help="largest offset searched, either way (default 0.5 s)",
    )
    refining.add_argument(
        "--refine",
        action="store_true",
        help="then refine each camera's offset by its edges against the body tracked in the other cameras (tracks "
        "the recording once per camera but the first, in OUT/sync/without-<camera>/)",
    )
    refining.add_argument(
        "--model", help="--refine: body model TOML (default: the recording's model.toml, else fitted)"
    )
    refining.add_argument(
        "--init",
        help="--refine: pose at the first frame (default: the recording's init.toml, else fitted to the keypoints)",
    )
    refining.add_argument("--frames", type=options.positive_int, help="--refine: frames to track (default: all)")
    options.add_landmark_model_option(parser)
    outputs.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Detect the landmarks in every frame (or reuse OUT/keypoints.npz), estimate the offsets, print one line per
    camera and write REC/sync.toml; a camera whose offset the motion does not decide is a one-line error after the
    others' lines, and nothing is written.  Fewer than two cameras is a one-line error before any detection."""
    from tracker.atomic import ensure_writable_folder
    from tracker.io.posefile import pose_frame
    from tracker.io.recording import open_recording, rig_names
    from tracker.io.sync_file import FILE, load_offsets, save_offsets
    from tracker.landmarks.detect_recording import cache_file, detect_recording
    from tracker.landmarks.time_offsets import camera_offsets

    given = [option for option in ("model", "init", "frames") if getattr(args, option) is not None]
    if given and not args.refine:
        raise TrackerInputError(
            f"{args.recording}: --{given[0]} is for the tracks of --refine; add --refine or drop it"
        )
    rec = open_recording(args.recording, options.camera_names(args.cameras), args.calib, paired=False)
    names = [camera.name for camera in rec.cameras]
    if len(names) < 2:
        alone, fix = (
            (f"--cameras picks one camera ({names[0]})", "pick two or more")
            if args.cameras is not None
            else (f"only camera {names[0]} has a video", "add the other cameras' videos")
        )
        raise TrackerInputError(f"{rec.path}: {alone}, but tracker sync times cameras against one another; {fix}")
    if args.init is not None and (frame := pose_frame(args.init)) != 0:
        raise TrackerInputError(
            f"{args.init}: is the pose at frame {frame}, but the tracks of --refine start at frame 0; pass --init "
            "with the pose at frame 0, or leave --init out to find the first pose by itself"
        )
    duration = rec.frame_count / rec.fps
    target = rec.path / FILE
    before = None
    if target.is_file():
        before = load_offsets(target, rig_names(rec), duration)
        left_out = [name for name, offset in before.items() if offset != 0.0 and name not in names]
        if left_out:
            why = "which --cameras leaves out" if rec.picked else "whose video is missing"
            raise TrackerInputError(
                f"{target}: also holds the offset of {', '.join(left_out)}, {why} and this run would drop; sync "
                "every camera, or move the file away to start afresh"
            )
    out = ensure_writable_folder(options.output_folder(args.out, rec))
    keypoints, _ = detect_recording(
        rec,
        0,
        rec.frame_count,
        cache=cache_file(out, rec, args.landmark_model),
        progress=options.bar(args, "detecting", "frame"),
        landmark_model=args.landmark_model,
    )
    found = camera_offsets(
        keypoints.pixels, keypoints.confidence, rec.cameras, fps=rec.fps, reach=min(args.reach, duration / 2)
    )
    seconds, sigma, decided = found.seconds, found.sigma, found.decided
    notes = [""] * len(names)
    refined = None
    if args.refine:
        refined = _refined(args, rec, found, out)
        seconds = np.where(refined.decided, refined.seconds, seconds)
        sigma = np.where(refined.decided, refined.sigma, sigma)
        decided = refined.decided | decided
        notes = [_source(found, refined, camera) for camera in range(len(names))]
    for camera, name in enumerate(names):
        was = f"  (was {before[name]:+.4f})" if before is not None else ""
        spread = "reference" if camera == 0 else f"+-{sigma[camera]:.4f}"
        if decided[camera]:
            print(f"{name}  {seconds[camera]:+.4f} s  {spread}{notes[camera]}{was}")
    if not decided.all():
        raise TrackerInputError(
            f"{rec.path}: the {'edges and the ' if refined is not None else ''}landmarks' motion does not pin down "
            f"the time offset of {_guesses(found, refined, names)}, but the views agree nearly as well at other "
            "offsets: the body moves too slowly for the detector's noise, or too few frames show it in two views; "
            f"record brisk movement that every camera sees, or write the offsets in {target} by hand"
        )
    save_offsets(target, dict(zip(names, seconds)), dict(zip(names, sigma)))
    print(f"wrote {target}")
    return 0


def _refined(args: argparse.Namespace, rec, found: Offsets, out):
    """The offsets refined by the edges (:func:`tracker.apps.sync.refine_offsets`), the tracks in OUT/sync/."""
    import functools

    from tracker.apps.keypoint_stream import default_step
    from tracker.apps.sync import refine_offsets
    from tracker.apps.track import Tracking
    from tracker.tracking.settings import Settings

    tracking = Tracking(
        Settings().but(motion=dict(frame_rate=rec.fps)),
        default_step(rec.fps),
        args.landmark_model,
        frames=args.frames,
        model=args.model,
        init=args.init,
    )
    return refine_offsets(rec, found, tracking, out=out / "sync", bar=functools.partial(options.bar, args))


def _source(found: Offsets, refined: Refined, camera: int) -> str:
    """What a camera's line says of where its offset comes from: the edges (and what the landmarks said), or the
    landmarks (and what the edges said)."""
    if camera == 0:
        return ""
    landmarks = f"{found.seconds[camera]:+.4f}" if found.decided[camera] else "undecided"
    edges = f"{refined.seconds[camera]:+.4f}" if np.isfinite(refined.seconds[camera]) else "no track"
    if refined.decided[camera]:
        return f"  by the edges (landmarks {landmarks})"
    return f"  by the landmarks (edges {edges}, undecided)"


def _guesses(found: Offsets, refined: Refined | None, names: list[str]) -> str:
    """The cameras whose offset the motion does not decide, each with what its pairs with a decided camera suggest
    (that camera's offset plus the pair's shift), e.g. ``cam3 (its pairs: -0.052, -0.033 s)``, and the edges' least
    when refined (``; its edges: -0.071 +- 0.031 s``)."""
    told = []
    undecided = ~found.decided if refined is None else ~(found.decided | refined.decided)
    for camera in np.flatnonzero(undecided):
        guesses = [
            found.seconds[i] + shift if j == camera else found.seconds[j] - shift
            for (i, j), (shift, _, _) in found.pairs.items()
            if camera in (i, j) and found.decided[j if i == camera else i] and np.isfinite(shift)
        ]
        said = [f"its pairs: {', '.join(f'{g:+.3f}' for g in guesses)} s"] if guesses else []
        if refined is not None and np.isfinite(refined.seconds[camera]):
            said.append(f"its edges: {refined.seconds[camera]:+.3f} +- {refined.sigma[camera]:.3f} s")
        told.append(f"{names[camera]} ({'; '.join(said)})" if said else names[camera])
    return ", ".join(told)
