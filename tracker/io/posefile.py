"""Pose TOML files such as ``init.toml`` (formats.md, "Pose files").

``frame`` is the recording's frame the pose is of (0 when the file does not say:
files written before the key).  ``[pose.<component>]`` gives the world-from-component
``rotation`` (Rodrigues) and, for the root, the world ``translation``.  Other components
hang on their parent's joint; one missing from the file takes its rest orientation
relative to its parent.  The result is projected onto the model's joints (coercion), so
a hinge given a rotation off its axis keeps only the part about the axis.  A run starts
from a pose file only at the file's frame (:func:`starting_pose_file`).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import tomli_w

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.model import Model
from tracker.tomlfile import read_toml

_JOINT_TOLERANCE = 1e-3


def pose_frame(path: str | os.PathLike) -> int:
    """The frame the pose TOML at ``path`` is of: its ``frame``, 0 when it has none."""
    path = Path(path)
    frame = _read(path).get("frame", 0)
    if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
        raise TrackerInputError(
            f"{path}: frame = {frame!r} is not a frame number; write frame = N, the recording's frame the pose is of"
        )
    return frame


def starting_pose_file(
    start: int, given: str | os.PathLike | None, found: Path | None, *, by_itself: bool = True
) -> Path | None:
    """The pose file a run that starts at frame ``start`` starts from: ``given`` (``--init``), which must be the pose
    at that frame, else ``found`` (the recording's init.toml) if it is, else None: the run finds its first pose by
    itself.  A ``found`` file of another frame is passed over with a warning, or refused when the run cannot find its
    first pose by itself (not ``by_itself``)."""
    chosen = given if given is not None else found
    if chosen is None:
        return None
    path = Path(chosen)
    frame = pose_frame(path)
    if frame == start:
        return path
    if given is None and by_itself:
        warnings.warn(
            f"ignoring {path}, the pose at frame {frame}: the run starts at frame {start}, "
            "where it finds the first pose by itself",
            stacklevel=2,
        )
        return None
    alone = ", or no --init to find the first pose by itself" if by_itself else ""
    where = "" if by_itself else ", where it cannot find the first pose by itself"
    unsaid = "frame" not in _read(path)  # written before pose files said their frame: perhaps of another
    said = f" (it says no frame: add frame = {start} to it if it is the pose at frame {start})" if unsaid else ""
    raise TrackerInputError(
        f"{path}: is the pose at frame {frame}{said}, but the run starts at frame {start}{where}; pass --start "
        f"{frame}, or --init with a pose at frame {start}{alone}"
    )


def load_pose_file(path: str | os.PathLike, model: Model) -> np.ndarray:
    """World poses (N,4,4) of every component from a pose TOML."""
    path = Path(path)
    data = _read(path)
    table = data.get("pose")
    if not isinstance(table, dict) or not table:
        raise TrackerInputError(f"{path}: no [pose.<component>] tables; write at least the root's pose")
    unknown = sorted(set(table) - set(model.names))
    if unknown:
        raise TrackerInputError(
            f"{path}: unknown component {unknown[0]!r} (model {model.name!r} has {', '.join(model.names)}); "
            "fix the name"
        )
    root = model.names[0]
    if "translation" not in table.get(root, {}):
        raise TrackerInputError(f"{path}: the root {root!r} needs a `translation`; add it under [pose.{root}]")
    poses = np.empty((model.size, 4, 4))
    moved = []
    for i, name in enumerate(model.names):
        entry = table.get(name, {})
        try:
            rotation = _finite(entry.get("rotation"), name, "rotation") if "rotation" in entry else None
            translation = _finite(entry.get("translation"), name, "translation") if "translation" in entry else None
        except ValueError as exc:
            raise TrackerInputError(f"{path}: {exc}; fix the file") from None
        if i == 0:
            poses[0] = se3.from_rotvec(rotation if rotation is not None else np.zeros(3), translation)
            continue
        hanging = poses[model.parent[i]] @ model.rest[i]
        poses[i] = hanging
        if rotation is not None:
            poses[i, 0:3, 0:3] = se3.exp_so3(rotation)
        if translation is not None and np.linalg.norm(translation - hanging[0:3, 3]) > _JOINT_TOLERANCE:
            moved.append(name)
    if moved:
        warnings.warn(f"{path}: moved {', '.join(moved)} onto their parents' joints", stacklevel=2)
    return model.coerce(poses)


def at_frame(path: str | os.PathLike, frame: int) -> bytes:
    """The pose TOML at ``path`` as the pose of the recording's frame ``frame``: its tables as they are (the same
    numbers), its ``frame`` key set; for a copy that starts another recording (``tracker live --record``)."""
    return tomli_w.dumps(_read(Path(path)) | {"frame": int(frame)}).encode()


def _read(path: Path) -> dict:
    """The pose TOML at ``path``, parsed."""
    return read_toml(path, "pose", "pass --init with an existing init.toml")


def _finite(value, name: str, key: str) -> np.ndarray:
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        out = np.zeros(0)
    if out.shape != (3,) or not np.all(np.isfinite(out)):
        raise ValueError(f"[pose.{name}].{key} must be 3 finite numbers, got {value!r}")
    return out


def pose_table(model: Model, poses: np.ndarray) -> dict:
    """The ``pose`` table of a pose TOML: every component's rotation, the root's translation."""
    table = {}
    for i, name in enumerate(model.names):
        entry = {"rotation": [float(v) for v in se3.log_so3(np.ascontiguousarray(poses[i, 0:3, 0:3]))]}
        if i == 0:
            entry["translation"] = [float(v) for v in poses[i, 0:3, 3]]
        table[name] = entry
    return {"pose": table}


def save_pose_file(path: str | os.PathLike, model: Model, poses: np.ndarray, *, frame: int) -> None:
    """Write a pose TOML of the recording's frame ``frame`` atomically."""
    text = tomli_w.dumps({"frame": int(frame)} | pose_table(model, poses)).encode()

    atomic_write(path, lambda file: file.write(text))
