"""``tracker sync``: each camera's capture-time offset from the landmarks' motion, written to REC/sync.toml."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np

from tracker.commands import options
from tracker.errors import TrackerInputError

if TYPE_CHECKING:
    from tracker.keypoints.sync import Offsets

HELP = "find each camera's capture-time offset from the body's motion, write REC/sync.toml"


def add_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``tracker sync``."""
    parser.add_argument("recording", help="recording folder (calibration.toml and one video per camera)")
    parser.add_argument("--out", help="folder for the detections, OUT/keypoints.npz (default: out/<recording name>)")
    options.add_recording_options(parser)
    parser.add_argument(
        "--reach",
        type=options.positive_float,
        default=0.5,
        metavar="SECONDS",
        help="largest offset searched, either way (default 0.5 s)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Detect the landmarks in every frame (or reuse OUT/keypoints.npz), estimate the offsets, print one line per
    camera and write REC/sync.toml; a camera whose offset the motion does not decide is a one-line error after the
    others' lines, and nothing is written."""
    from tracker.atomic import ensure_writable_folder
    from tracker.io.recording import open_recording
    from tracker.io.sync import FILE, load_offsets, save_offsets
    from tracker.keypoints.detect import detect_recording
    from tracker.keypoints.sync import camera_offsets

    rec = open_recording(args.recording, options.camera_names(args.cameras), args.calib, paired=False)
    names = [camera.name for camera in rec.cameras]
    duration = rec.frame_count / rec.fps
    target = rec.path / FILE
    before = load_offsets(target, names, duration) if target.is_file() else None
    out = ensure_writable_folder(options.output_folder(args.out, rec))
    keypoints, _ = detect_recording(
        rec, 0, rec.frame_count, cache=out / "keypoints.npz", progress=options.bar(args, "detecting", "frame")
    )
    found = camera_offsets(
        keypoints.pixels, keypoints.confidence, rec.cameras, fps=rec.fps, reach=min(args.reach, duration / 2)
    )
    for name, seconds, sigma, decided in zip(names, found.seconds, found.sigma, found.decided):
        was = f"  (was {before[name]:+.4f})" if before is not None else ""
        spread = "reference" if name == names[0] else f"+-{sigma:.4f}"
        if decided:
            print(f"{name}  {seconds:+.4f} s  {spread}{was}")
    if not found.decided.all():
        raise TrackerInputError(
            f"{rec.path}: the landmarks' motion does not pin down the time offset of {_guesses(found, names)}, but the "
            "views agree nearly as well at other offsets: the body moves too slowly for the detector's noise, or too "
            "few frames show it in two views; record brisk movement that every camera sees, or write the offsets in "
            f"{target} by hand"
        )
    save_offsets(target, dict(zip(names, found.seconds)), dict(zip(names, found.sigma)))
    print(f"wrote {target}")
    return 0


def _guesses(found: Offsets, names: list[str]) -> str:
    """The cameras whose offset the motion does not decide, each with what its pairs with a decided camera suggest
    (that camera's offset plus the pair's shift), e.g. ``cam3 (its pairs: -0.052, -0.033 s)``."""
    told = []
    for camera in np.flatnonzero(~found.decided):
        guesses = [
            found.seconds[i] + shift if j == camera else found.seconds[j] - shift
            for (i, j), (shift, _, _) in found.pairs.items()
            if camera in (i, j) and found.decided[j if i == camera else i] and np.isfinite(shift)
        ]
        told.append(
            f"{names[camera]} (its pairs: {', '.join(f'{g:+.3f}' for g in guesses)} s)" if guesses else names[camera]
        )
    return ", ".join(told)
