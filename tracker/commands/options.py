"""Options that several commands share, and what they resolve to: argument types, the recording and
model of a run, a tracked poses.npz, tracking Settings and the progress bar (formats.md).

Only the command modules import this one.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tracker.errors import TrackerInputError

if TYPE_CHECKING:
    from tracker.apps.track import Tracking
    from tracker.io.recording import Recording


def positive_int(text: str) -> int:
    """Argument type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def whole_number(text: str) -> int:
    """Argument type: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number (0 or more), got {text}")
    return value


def positive_float(text: str) -> float:
    """Argument type: a finite number > 0."""
    value = float(text)
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def camera_seconds(text: str) -> tuple[tuple[str, float], ...]:
    """Argument type: ``cam1=0.021,cam2=-0.05``, seconds per camera name, as (name, seconds) pairs."""
    pairs = []
    for item in (part.strip() for part in text.split(",") if part.strip()):
        name, _, value = item.partition("=")
        try:
            seconds = float(value)
        except ValueError:
            seconds = float("nan")
        if not name.strip() or not math.isfinite(seconds):
            raise argparse.ArgumentTypeError(f"must be CAMERA=SECONDS[,CAMERA=SECONDS...], got {item!r}")
        pairs.append((name.strip(), seconds))
    return tuple(pairs)


def on_off(text: str) -> bool:
    """Argument type: on or off."""
    if text not in ("on", "off"):
        raise argparse.ArgumentTypeError(f"must be on or off, got {text}")
    return text == "on"


def share(text: str) -> float:
    """Argument type: a number between 0 and 1."""
    value = float(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1, got {text}")
    return value


def port(text: str) -> int:
    """Argument type: a TCP port number 0-65535."""
    value = int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port number 0-65535, got {text}")
    return value


def keypoint_step(text: str) -> int:
    """Argument type of ``--keypoints``: every -> 1, off -> 0, N -> every N-th frame."""
    if text in ("every", "off"):
        return 1 if text == "every" else 0
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be every, off or a whole number of frames >= 1, got {text}")
    return value


def keypoint_step_at(args: argparse.Namespace, fps: float) -> int:
    """``--keypoints`` as a step (0: off) for footage of ``fps`` frames a second: the given one, or by default
    :func:`tracker.apps.keypoint_stream.default_step`."""
    from tracker.apps.keypoint_stream import default_step

    return default_step(fps) if args.keypoints is None else args.keypoints


def add_keypoint_options(parser: argparse.ArgumentParser, what: str | None = None) -> None:
    """``--keypoints``: how often the 2-D keypoint detector runs beside the tracker (``what``: the help's
    first words, if not tracking's)."""
    from tracker.apps.keypoint_stream import RATE

    what = what or (
        "run the 2-D keypoint detector (BlazePose) on every N-th frame beside the tracker and fuse its "
        "landmarks with the edges (interpolated between); detections are cached in OUT/keypoints.npz"
    )
    parser.add_argument(
        "--keypoints",
        type=keypoint_step,
        default=None,
        metavar="every|N|off",
        help=f"{what} (default: the footage's frame rate / {RATE:g} rounded, about {RATE:g} detections a second: 4 at "
        "60 fps, every frame below 22.5 fps)",
    )


def add_landmark_model_option(parser: Options, default: str | None = None) -> None:
    """``--landmark-model lite|full|heavy``: the keypoint detector's landmark model, ``default`` (if not the one of
    the commands that read recorded folders, :data:`tracker.landmarks.landmark_models.RECORDED`) when not given."""
    from tracker.landmarks.landmark_models import MODELS, RECORDED

    default = default or RECORDED
    parser.add_argument(
        "--landmark-model",
        choices=MODELS,
        default=default,
        help=f"the keypoint detector's landmark model (BlazePose lite, full or heavy: lighter is faster, heavier more "
        f"accurate; docs/keypoints.md); each model's detections are cached apart (default {default})",
    )


def camera_names(text: str | None) -> list[str] | None:
    """The names in a comma-separated list of cameras (``--cameras``, ``--fix``); None when not given, empty when
    it names none (``""`` or ``","``)."""
    return None if text is None else [c.strip() for c in text.split(",") if c.strip()]


def choose(given: str | None, found: Path | None, *, what: str, option: str, rec: Path) -> Path:
    """The file an option names, else the one found in the recording folder ``rec``."""
    if given:
        return Path(given)
    if found is None:
        raise TrackerInputError(f"{rec}: no {what} in the recording folder; pass {option}")
    return found


Options = argparse._ActionsContainer
"""Where a command's options are added: its parser, or one of the parser's argument groups (inputs, outputs, ...)."""


def add_recording_argument(group) -> None:
    """The recording folder a command works on, ``RECORDING``, in ``group`` (its inputs)."""
    group.add_argument(
        "recording", metavar="RECORDING", help="recording folder (calibration.toml and one video per camera)"
    )


def add_recording_options(inputs: Options) -> None:
    """``--cameras`` and ``--calib``: which cameras of a recording folder, and their calibration."""
    inputs.add_argument("--cameras", help="comma-separated camera names (default: every camera with a video)")
    inputs.add_argument(
        "--calib",
        metavar="TOML",
        help="calibration to use instead of the recording's calibration.toml (e.g. from tracker refine)",
    )


def add_cache_option(outputs: Options) -> None:
    """``--cache DIR``: the folder that keeps the keypoint detector's landmarks, for the commands whose ``--out`` is a
    file (the others keep them in their ``--out`` folder)."""
    outputs.add_argument(
        "--cache",
        metavar="DIR",
        help="folder that keeps the keypoint detector's landmarks (keypoints.npz), which later runs reuse "
        "(default: out/<recording name>, or out/<recording name>-<hash> when that holds another recording's)",
    )


def tuning_fields() -> dict[str, tuple[str, dataclasses.Field]]:
    """The settings fields that have a flag (:func:`tracker.tracking.settings.setting`), by flag: the group's name and
    the field, in the order the groups and their fields are declared."""
    from tracker.tracking.settings import Settings

    found = {}
    for name, group in vars(Settings()).items():
        for spec in dataclasses.fields(group):
            if spec.metadata["flag"]:
                found[spec.metadata["flag"]] = (name, spec)
    return found


KINDS: dict[str | None, Callable[[str], Any]] = {
    "count": positive_int,
    "positive": positive_float,
    "whole": whole_number,
    "share": share,
    "on-off": on_off,
}


def add_tuning_options(
    parser: argparse.ArgumentParser, which: tuple[str, ...] | None = None, *, recorded: bool = True
) -> None:
    """The tracker's tuning options that a command offers (their flags, ``which``; default all, but those only for a
    recorded folder when not ``recorded``), one argument group per settings group, each with the field's help, kind,
    choices and default (:mod:`tracker.tracking.settings`)."""
    from tracker.tracking.settings import Settings

    defaults, groups = Settings(), {}
    for flag, (group, spec) in tuning_fields().items():
        if which is not None and flag not in which or spec.metadata["recorded"] and not recorded:
            continue
        if group not in groups:
            title = (type(getattr(defaults, group)).__doc__ or group).strip()
            groups[group] = parser.add_argument_group(f"tuning: {title}")
        default = getattr(getattr(defaults, group), spec.name)
        kind = spec.metadata["kind"]
        kwargs: dict[str, Any] = dict(
            dest=f"{group}.{spec.name}", default=None, help=f"{spec.metadata['help']} (default {_shown(default)})"
        )
        if spec.metadata["choices"]:
            kwargs["choices"] = spec.metadata["choices"]
        else:
            kwargs["type"] = KINDS[kind]
            kwargs["metavar"] = {"on-off": "on|off"}.get(kind, spec.name.upper())
        groups[group].add_argument(flag, **kwargs)
        if spec.metadata["renamed"]:
            groups[group].add_argument(spec.metadata["renamed"], **kwargs | renamed(flag))


def _shown(default: Any) -> str:
    """A setting's default as its help shows it."""
    if isinstance(default, bool):
        return "on" if default else "off"
    if isinstance(default, float) and math.isinf(default):
        return "none"
    return f"{default:g}" if isinstance(default, float) else str(default)


class _Renamed(argparse.Action):
    """Stores the value like the option's new name does, after a warning that names the new one."""

    def __init__(self, *args: Any, new: str, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.new = new

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print(f"tracker: warning: {option_string} is now {self.new}; the old name will go", file=sys.stderr)
        setattr(namespace, self.dest, values)


def renamed(new: str) -> dict[str, Any]:
    """add_argument keywords for an old option name kept for old scripts: hidden from --help, and a
    warning naming ``new`` when used."""
    return dict(action=_Renamed, new=new, help=argparse.SUPPRESS)


def settings_from(args: argparse.Namespace, frame_rate: float | None = None):
    """Settings with the tuning options the user gave (the others at their defaults) and the frame rate
    of the images (the Kalman filter's time step)."""
    from tracker.tracking.settings import Settings

    given: dict[str, dict[str, Any]] = {"motion": {"frame_rate": frame_rate}} if frame_rate is not None else {}
    for group, spec in tuning_fields().values():
        value = getattr(args, f"{group}.{spec.name}", None)
        if value is not None:
            given.setdefault(group, {})[spec.name] = value
    return Settings().but(**given)


def add_tracking_options(parser: argparse.ArgumentParser, *, inputs: Options) -> None:
    """The options of ``tracker track`` that say how a recording is tracked (``tracker batch`` passes them on;
    :func:`tracking` resolves them): the body model, first pose, cameras and frames in ``inputs`` (a group of
    ``parser``), how to track them in ``parser``."""
    inputs.add_argument(
        "--model",
        help="body model TOML (default: the recording's model.toml, else models/human.toml fitted to the person "
        "and written to OUT/model.toml)",
    )
    inputs.add_argument(
        "--init",
        help="pose at the first frame (default: the recording's init.toml, else fitted to the keypoints of the "
        "first frames)",
    )
    add_recording_options(inputs)
    inputs.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    inputs.add_argument("--frames", type=positive_int, help="number of frames to track (default: all)")
    add_tuning_options(parser)
    add_keypoint_options(parser)
    add_landmark_model_option(parser)
    parser.add_argument(
        "--background",
        default="none",
        metavar="none|median|DIR",
        help="search edges in the difference from the empty scene instead of the grey image: "
        "'median' estimates it from the recording (the person must move about), DIR holds "
        "<camera>.png images of it (default none)",
    )


def add_live_view_options(viewer: Options, after: str) -> None:
    """``--view`` and ``--view-rate``: the browser viewer following a run, and ``after`` it what it shows."""
    viewer.add_argument(
        "--view", action="store_true", help=f"show the run in the browser viewer (about 30 updates a second), {after}"
    )
    viewer.add_argument(
        "--view-rate", type=positive_float, default=30.0, help="viewer updates per second while tracking (default 30)"
    )


def add_viewer_options(viewer: Options, record: bool = True) -> None:
    """``--host`` and ``--port`` of the browser viewer, and ``--record`` of its session when ``record``."""
    viewer.add_argument(
        "--host",
        default="127.0.0.1",
        help="address the viewer listens on (default 127.0.0.1; 0.0.0.0 opens it to the network)",
    )
    viewer.add_argument(
        "--port",
        type=port,
        default=8080,
        help="viewer port (default 8080, or the next free one; 0 picks any free port)",
    )
    if record:
        viewer.add_argument(
            "--record",
            metavar="FILE.viser",
            help="also write the viewer session as a .viser file, which plays in a browser without the tracker "
            "(docs/viewer.md)",
        )


def record_file(args: argparse.Namespace) -> Path | None:
    """The file ``--record`` names (None when not given), its folder made and checked writable now: a place that
    cannot be written is a one-line error before any viewer starts or any frame is drawn."""
    from tracker.atomic import writable_file

    return writable_file(args.record) if args.record else None


def recording(args: argparse.Namespace):
    """The recording a command works on (``--cameras``, ``--calib``)."""
    from tracker.io.recording import open_recording

    return open_recording(args.recording, camera_names(args.cameras), args.calib)


HOLDS = "recording.txt"
"""The file in a default output folder that names the recording whose results it holds (its resolved path)."""


def output_folder(given: str | None, rec, *, claim: bool = True) -> Path:
    """The folder a command writes a recording's results to: ``given`` (``--out``), else the default,
    out/<recording name>, unless that folder holds another recording's (its :data:`HOLDS` names another folder):
    then out/<recording name>-<8 hex digits of the SHA-1 of the recording's resolved path>, so that two recordings
    whose folders share a name never mix their results (formats.md, "Output folders").  With ``claim`` (a command
    that writes there) the default folder is made, :data:`HOLDS` written in it when it has none, and the folder said
    on standard error."""
    if given:
        return Path(given)
    import hashlib

    from tracker.atomic import atomic_write

    source = rec.path.resolve()
    folder = Path("out") / source.name
    held = _holder(folder)
    if held is not None and held != str(source):
        folder = folder.with_name(f"{source.name}-{hashlib.sha1(str(source).encode()).hexdigest()[:8]}")
    if claim:
        if _holder(folder) is None:
            atomic_write(folder / HOLDS, lambda file: file.write(f"{source}\n".encode()))
        other = "" if held is None or held == str(source) else f" (out/{source.name} holds {held})"
        print(f"output folder: {folder}{other}", file=sys.stderr)
    return folder


def _holder(folder: Path) -> str | None:
    """The recording (resolved path) whose results ``folder`` holds, as its :data:`HOLDS` says; None without one."""
    try:
        return (folder / HOLDS).read_text().strip() or None
    except (OSError, UnicodeDecodeError):
        return None


def tracking(args: argparse.Namespace) -> tuple[Recording, Tracking]:
    """The recording that the tracking options of ``args`` (:func:`add_tracking_options`, and ``recording``) name,
    and how to track it (:func:`tracker.apps.track.track`)."""
    from tracker.apps.track import Tracking

    rec = recording(args)
    return rec, Tracking(
        settings_from(args, rec.fps),
        keypoint_step_at(args, rec.fps),
        args.landmark_model,
        start=args.start,
        frames=args.frames,
        model=args.model,
        init=args.init,
        background=args.background,
    )


def opened(args: argparse.Namespace):
    """The recording (``--cameras``, ``--calib``) and the body model (``--model``, else the recording's) a
    command works on."""
    from tracker.model import load_model

    rec = recording(args)
    return rec, load_model(choose(args.model, rec.model_path, what="model.toml", option="--model", rec=rec.path))


def truth(rec):
    """The recording's truth.npz arrays, or None when it has none."""
    from tracker.io.poses import load_poses

    return load_poses(rec.truth_path) if rec.truth_path is not None else None


def recording_inputs(rec) -> list[tuple[Path | None, str]]:
    """The files of the recording ``rec`` that a command reads, each with what it is, for
    :func:`tracker.overwrite.keep_inputs` (None for those it does not have)."""
    return [
        (rec.calibration_path, "the calibration being read"),
        *(
            (source, f"the footage of camera {camera.name} being read")
            for camera, source in zip(rec.cameras, rec.sources)
        ),
        (rec.model_path, "the recording's body model"),
        (rec.init_path, "the recording's first pose"),
        (rec.truth_path, "the recording's true poses"),
        (rec.timestamps_path, "the recording's capture times"),
    ]


def tracked(given: str | None, rec, model) -> tuple[Path, dict]:
    """The poses.npz a run of ``model`` on ``rec`` wrote (``given``, else out/<recording name>/poses.npz),
    loaded and checked against both; ``usable`` marks its frames with a finite pose that is not lost."""
    import numpy as np

    from tracker.io.poses import load_poses
    from tracker.status import LOST

    path = Path(given) if given else output_folder(None, rec, claim=False) / "poses.npz"
    if not given and not path.is_file():
        raise TrackerInputError(
            f"{path}: no poses to review or refine; run `tracker track {rec.path}` first or pass --poses"
        )
    results = load_poses(path)
    if len(results["joints"]) == 0:
        raise TrackerInputError(f"{path}: holds no frames; track some first")
    if "poses" not in results or list(results["component_names"]) != list(model.names):
        raise TrackerInputError(
            f"{path}: its components do not match the model {model.name!r}; pass the --model it was tracked with"
        )
    if results["frame"].max(initial=0) >= rec.frame_count:
        raise TrackerInputError(
            f"{path}: frames beyond the recording's {rec.frame_count}; pass the recording it was tracked from"
        )
    results["usable"] = np.isfinite(results["poses"]).all(axis=(1, 2, 3))
    if "status" in results:
        results["usable"] &= results["status"] != LOST
    return path, results


def say_interrupted() -> None:
    """Tell on standard error that a run was stopped (Ctrl-C, SIGTERM, SIGHUP) with its frames done written."""
    print("tracker: interrupted: the frames done so far are saved", file=sys.stderr)


def bar(args: argparse.Namespace, desc: str | None, unit: str, *, leave: bool = False):
    """A progress bar on the terminal's standard error (off with --quiet) to wrap an iterable in; it stays on the
    screen when done only with ``leave``.  It writes to its own copy of file descriptor 2, so it still shows
    while MediaPipe's native logs are muted (:func:`tracker.landmarks.detector.native_logs_muted`)."""
    from tqdm import tqdm

    file = sys.stderr if args.quiet else _terminal(sys.stderr)
    return functools.partial(tqdm, desc=desc, unit=unit, disable=args.quiet, file=file, leave=leave)


@functools.cache
def _terminal(stream):
    """A text stream on a copy of ``stream``'s file descriptor, made once per stream (``stream`` itself when it
    has none, e.g. when captured)."""
    try:
        descriptor = stream.fileno()
    except (AttributeError, OSError, ValueError):
        return stream
    stream.flush()
    return os.fdopen(os.dup(descriptor), "w", buffering=1)
