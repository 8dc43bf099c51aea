"""3-D marker recordings for ``tracker points``: C3D (read with ezc3d) and TRC files.

Both come out as one :class:`Markers`: the marker labels, their positions in
metres with NaN where a marker was not seen, the frame rate and the first
frame's number.  Units are read from the file (C3D ``POINT:UNITS``, TRC
``Units``: mm, cm or m).  In a C3D file a point whose residual is negative is a
gap (the C3D convention; ezc3d reads it as NaN), and so is a point at exactly
(0, 0, 0), which some writers use for a gap instead.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker.errors import TrackerInputError
from tracker.io.export.trc import read_trc

METRES_PER_UNIT = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
SUFFIXES = (".c3d", ".trc")


@dataclass(frozen=True)
class Markers:
    """``labels`` (M,), ``positions`` (F, M, 3) metres with NaN gaps, ``rate`` frames per second,
    ``first_frame`` the number of the first frame in the file."""

    path: Path
    labels: tuple[str, ...]
    positions: np.ndarray
    rate: float
    first_frame: int

    def index(self, name: str) -> int:
        """The column of marker ``name``: its full label, or the part after a ``subject:`` prefix
        (Vicon writes ``Daphnee:ELBOW``); an error names the file and the labels it has."""
        exact = [i for i, label in enumerate(self.labels) if label == name]
        found = exact or [i for i, label in enumerate(self.labels) if label.rpartition(":")[2] == name]
        if len(found) == 1:
            return found[0]
        if not found:
            shown = ", ".join(self.labels[:12]) + (", ..." if len(self.labels) > 12 else "")
            raise TrackerInputError(f"{self.path}: no marker {name!r} (it has {shown}); fix the name in the model")
        raise TrackerInputError(
            f"{self.path}: marker name {name!r} matches {len(found)} labels "
            f"({', '.join(self.labels[i] for i in found)}); use the full label in the model"
        )

    def select(self, names: Sequence[str]) -> np.ndarray:
        """Positions (F, len(names), 3) of the named markers, in that order."""
        return self.positions[:, [self.index(name) for name in names]]


def read_markers(path: str | os.PathLike) -> Markers:
    """Read a ``.c3d`` or ``.trc`` marker file; TrackerInputError on anything a user must fix."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise TrackerInputError(f"{path}: not a marker file; give a .c3d or .trc file")
    if not path.is_file():
        raise TrackerInputError(f"{path}: marker file not found; check the path")
    markers = _read_c3d(path) if path.suffix.lower() == ".c3d" else _read_trc(path)
    if not markers.labels or not len(markers.positions):
        raise TrackerInputError(f"{path}: holds no marker data; give a file with at least one marker and frame")
    if not np.isfinite(markers.positions).any():
        raise TrackerInputError(f"{path}: every marker position is a gap; give a file with measured markers")
    if not (np.isfinite(markers.rate) and markers.rate > 0):
        raise TrackerInputError(f"{path}: frame rate {markers.rate} is not positive; fix the file's rate")
    return markers


def _scale(path: Path, units: str) -> float:
    try:
        return METRES_PER_UNIT[units.strip().lower()]
    except KeyError:
        raise TrackerInputError(f"{path}: unknown units {units!r}; the file must give mm, cm or m") from None


def _read_c3d(path: Path) -> Markers:
    import ezc3d

    try:
        c3d = ezc3d.c3d(str(path))
        point = c3d["parameters"]["POINT"]
        labels = tuple(str(label) for label in point["LABELS"]["value"])
        units = point["UNITS"]["value"][0] if point.get("UNITS", {}).get("value") else "mm"
        rate = float(point["RATE"]["value"][0])
        first = int(c3d["header"]["points"]["first_frame"])
        data = np.asarray(c3d["data"]["points"], dtype=np.float64)  # (4, M, F)
        residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=np.float64)[0]  # (M, F)
    except (RuntimeError, OSError, KeyError, IndexError, ValueError) as error:
        raise TrackerInputError(f"{path}: not a readable C3D file ({error}); give a C3D file with POINT data") from None
    positions = np.transpose(data[:3], (2, 1, 0)) * _scale(path, units)  # (F, M, 3)
    gap = (residuals.T < 0) | (positions == 0.0).all(axis=2)
    positions[gap] = np.nan
    return Markers(path, labels[: positions.shape[1]], positions, rate, first)


def _read_trc(path: Path) -> Markers:
    trc = read_trc(path)
    try:
        rate = trc.rate
    except ValueError:
        raise TrackerInputError(
            f"{path}: DataRate {trc.header['DataRate']!r} is not a number; fix the header"
        ) from None
    first = int(trc.frame[0]) if len(trc.frame) else 1
    return Markers(path, trc.names, trc.markers * _scale(path, trc.units), rate, first)
