"""Tracking results in the files other tools read: TRC, C3D, BVH, CSV (``tracker export``).

Every format gets one row per frame index from the first to the last frame of
the poses file, at a constant rate: ``--fps`` if given, else the rate of the
file's ``frame`` and ``time`` arrays.  A frame index missing from the file is a
lost frame (formats.md).  The joint centres of a lost frame (status 2) and NaN
joints are gaps: ``NaN`` in TRC and CSV, invalid points (residual -1) in C3D.
A BVH has no gaps: a lost frame repeats the pose of the last frame that was not
lost.  TRC, C3D and CSV keep the tracker's world (right-handed, z up); BVH is
y up, as BVH readers expect (see :mod:`tracker.io.export.bvh`).

- trc: joint centres as markers in millimetres, for OpenSim and Pose2Sim;
- c3d: joint centres as POINT data in millimetres, for Mokka, Vicon, Visual3D;
- bvh: the model's skeleton and joint rotations, metres, for Blender;
- csv: frame, time, status, residual and joint centres in metres, for spreadsheets.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError
from tracker.io.export.units import seconds
from tracker.io.poses import load_poses
from tracker.overwrite import keep_inputs
from tracker.status import LOST, TRACKED

FORMATS = ("trc", "c3d", "bvh", "csv")


@dataclass(frozen=True)
class Rows:
    """A poses file on a regular grid of frame indices.

    ``frame`` (F,) every index from the file's first to its last frame, ``rate``
    frames per second, ``status`` (F,) 0/1/2 (2 for a frame missing from the
    file; 0 when the file has no status), ``residual`` (F,) pixels (NaN if
    unknown), ``joints`` (F, J, 3) metres with NaN gaps for lost frames and NaN
    joints, ``poses`` (F, N, 4, 4) as in the file (NaN for missing frames) or
    None when the file has none.
    """

    frame: np.ndarray
    rate: float
    status: np.ndarray
    residual: np.ndarray
    joint_names: tuple[str, ...]
    joints: np.ndarray
    component_names: tuple[str, ...]
    poses: np.ndarray | None

    @property
    def time(self) -> np.ndarray:
        """Seconds from the first frame: (frame - frame[0]) / rate."""
        return seconds(self.frame, self.rate)


def frame_rate(data: dict[str, np.ndarray], path: Path, fps: float | None = None) -> float:
    """``fps`` if given, else frames per second from the first and last ``frame`` and ``time``."""
    if fps is not None:
        return float(fps)
    frame = data["frame"]
    if "time" not in data or len(frame) < 2 or not data["time"][-1] > data["time"][0]:
        raise TrackerInputError(
            f"{path}: no 'time' array of two or more frames to take the frame rate from; pass --fps"
        )
    rate = float((frame[-1] - frame[0]) / (data["time"][-1] - data["time"][0]))
    if not np.isfinite(rate) or rate <= 0:
        raise TrackerInputError(f"{path}: 'frame' and 'time' give no positive frame rate; pass --fps")
    return rate


MAX_GAP_FACTOR = 100  # frame numbers may spread over this many times the frames held (plus 1000), gaps included


def regular_rows(data: dict[str, np.ndarray], path: Path, fps: float | None = None) -> Rows:
    """The arrays of :func:`tracker.io.poses.load_poses` on every frame index from first to last.

    Missing frames become lost rows; the joints of lost rows and NaN joints become NaN.
    """
    count = len(data["joints"])
    if count == 0:
        raise TrackerInputError(f"{path}: holds no frames; export a poses file with at least one frame")
    rate = frame_rate(data, path, fps)
    given = data["frame"]
    order = np.argsort(given)
    given = given[order]
    span = int(given[-1] - given[0]) + 1
    if span > MAX_GAP_FACTOR * count + 1000:
        raise TrackerInputError(
            f"{path}: its {count} frames are spread over frame numbers {given[0]}..{given[-1]}; "
            "exports write every frame in between, so split the file or renumber its frames"
        )
    frame = np.arange(given[0], given[-1] + 1)
    row = given - given[0]

    def spread(values: np.ndarray, fill: float) -> np.ndarray:
        out = np.full((len(frame),) + values.shape[1:], fill, dtype=values.dtype)
        out[row] = values[order]
        return out

    status = spread(data.get("status", np.full(count, TRACKED, np.int8)), LOST)
    joints = spread(data["joints"], np.nan)
    joints[status == LOST] = np.nan
    joints[~np.isfinite(joints).all(axis=2)] = np.nan
    has_poses = "poses" in data
    return Rows(
        frame=frame,
        rate=rate,
        status=status,
        residual=spread(data.get("residual", np.full(count, np.nan)), np.nan),
        joint_names=tuple(data["joint_names"]),
        joints=joints,
        component_names=tuple(data["component_names"]) if has_poses else (),
        poses=spread(data["poses"], np.nan) if has_poses else None,
    )


def default_out(poses: Path, fmt: str) -> Path:
    """POSES beside itself with the format's suffix: out/demo/poses.npz -> out/demo/poses.trc."""
    return poses.with_suffix(f".{fmt}")


def export(
    poses: str | os.PathLike,
    fmt: str,
    out: str | os.PathLike | None = None,
    *,
    model: str | os.PathLike | None = None,
    fps: float | None = None,
) -> Path:
    """Write the poses file ``poses`` as ``fmt`` (one of :data:`FORMATS`) to ``out``; return the path written.

    BVH needs ``model``, the body model the poses were tracked with.
    """
    poses = Path(poses)
    if fmt not in FORMATS:
        raise TrackerInputError(f"{poses}: cannot export to {fmt!r}; choose --to {', '.join(FORMATS)}")
    if fmt == "bvh" and model is None:
        raise TrackerInputError(
            f"{poses}: BVH export needs the body model the poses were tracked with; "
            "pass --model (e.g. models/human.toml)"
        )
    target = Path(out) if out is not None else default_out(poses, fmt)
    keep_inputs(
        [target],
        [(poses, "the poses file being exported"), (model, "the body model of the export")],
        "write the export to another file",
    )
    rows = regular_rows(load_poses(poses), poses, fps)
    if fmt == "trc":
        from tracker.io.export.trc import write_trc

        write_trc(target, rows.joint_names, frame=rows.frame, rate=rows.rate, joints=rows.joints)
    elif fmt == "c3d":
        from tracker.io.export.c3d import write_c3d

        write_c3d(target, rows.joint_names, first_frame=int(rows.frame[0]), rate=rows.rate, joints=rows.joints)
    elif fmt == "csv":
        from tracker.io.export.csv import write_csv

        write_csv(
            target,
            rows.joint_names,
            frame=rows.frame,
            time=rows.time,
            status=rows.status,
            residual=rows.residual,
            joints=rows.joints,
        )
    else:
        from tracker.io.export.bvh import write_bvh
        from tracker.model import load_model

        assert model is not None  # checked above for BVH
        body = load_model(model)
        write_bvh(target, body, _bvh_poses(rows, poses, body.names, Path(model)), status=rows.status, rate=rows.rate)
    return target


def _bvh_poses(rows: Rows, path: Path, names: tuple[str, ...], model_path: Path) -> np.ndarray:
    """The poses (F, N, 4, 4) in the model's component order, checked for a BVH export."""
    from tracker.io.export.bvh import usable

    if rows.poses is None:
        raise TrackerInputError(
            f"{path}: holds joint centres but no 'poses' array, which BVH needs; "
            "export it --to trc, c3d or csv, or export a poses.npz written by tracker track"
        )
    if set(rows.component_names) != set(names):
        raise TrackerInputError(
            f"{path}: its components ({', '.join(rows.component_names)}) are not those of {model_path} "
            f"({', '.join(names)}); pass the --model the poses were tracked with"
        )
    spaced = [name for name in names if len(name.split()) != 1]
    if spaced:
        raise TrackerInputError(
            f"{model_path}: BVH joint names are single words; rename the components {', '.join(map(repr, spaced))}"
        )
    poses = rows.poses[:, [rows.component_names.index(name) for name in names]]
    if not usable(poses, rows.status).any():
        raise TrackerInputError(
            f"{path}: every frame is lost, so there is no pose for a BVH; export a run that tracked"
        )
    return poses
