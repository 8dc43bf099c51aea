"""TRC marker files (OpenSim, Pose2Sim): writer and reader.

A TRC file is tab-separated text, laid out as OpenSim writes it (every field of
the name, axis and data lines followed by a tab)::

    PathFileType  4  (X/Y/Z)  <file name>
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    60  60  160  15  mm  60  1  160
    Frame#  Time  <marker 1>  ''  ''  <marker 2>  ''  ''  ...
    ''  ''  X1  Y1  Z1  X2  Y2  Z2  ...
    (an empty line)
    1  0.000000000  x  y  z  x  y  z  ...

``Frame#`` counts from 1: the exported frame is the recording's frame index
plus one.  ``Time`` is seconds from the first row.  A gap (marker not seen) is
``NaN``; a reader also takes an empty field as a gap.  Our files keep the
tracker's world, right-handed with z up; OpenSim's is y up, so rotate by -90
degrees about x on import there if needed (Pose2Sim and OpenSim's marker
import offer this).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError
from tracker.io.export.units import MM_PER_M, seconds
from tracker.tomlfile import read_text

HEADER_KEYS = (
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
)


@dataclass(frozen=True)
class Trc:
    """A parsed TRC file: ``header`` (the values of :data:`HEADER_KEYS` as text, by key),
    ``names`` (M,) marker names, ``frame`` (F,) the ``Frame#`` column, ``time`` (F,)
    seconds, ``markers`` (F, M, 3) in the file's units with NaN gaps."""

    header: dict[str, str]
    names: tuple[str, ...]
    frame: np.ndarray
    time: np.ndarray
    markers: np.ndarray

    @property
    def rate(self) -> float:
        """DataRate, frames per second."""
        return float(self.header["DataRate"])

    @property
    def units(self) -> str:
        return self.header["Units"]


def trc_lines(file_name: str, names: Sequence[str], *, frame: np.ndarray, rate: float, joints: np.ndarray) -> list[str]:
    """The lines (without newlines) of a TRC file of ``joints`` (F, M, 3) metres, written in mm.

    ``frame`` (F,) are recording frame indices (written plus one); rows are ``rate`` apart in time.
    """
    count, markers = len(frame), len(names)
    rate_text = f"{rate:.10g}"
    values = (rate_text, rate_text, str(count), str(markers), "mm", rate_text, str(int(frame[0]) + 1), str(count))
    axes = "".join(f"X{k}\tY{k}\tZ{k}\t" for k in range(1, markers + 1))
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{file_name}",
        "\t".join(HEADER_KEYS),
        "\t".join(values),
        "Frame#\tTime\t" + "".join(f"{name}\t\t\t" for name in names),
        "\t\t" + axes,
        "",
    ]
    data = np.column_stack([seconds(frame, rate), np.reshape(joints, (count, 3 * markers)) * MM_PER_M])
    row_format = "%.9f\t" + "%.6f\t" * (3 * markers)
    for index, row in zip(frame, data):
        lines.append(f"{int(index) + 1}\t" + (row_format % tuple(row)).replace("nan", "NaN"))
    return lines


def write_trc(
    path: str | os.PathLike, names: Sequence[str], *, frame: np.ndarray, rate: float, joints: np.ndarray
) -> None:
    """Write ``joints`` (F, M, 3) metres, NaN for gaps, as the TRC file ``path`` (mm, atomically)."""
    path = Path(path)
    text = "\n".join(trc_lines(path.name, names, frame=frame, rate=rate, joints=joints)) + "\n"

    atomic_write(path, lambda file: file.write(text.encode()))


def read_trc(path: str | os.PathLike) -> Trc:
    """Parse a TRC file; TrackerInputError when it is missing or malformed."""
    path = Path(path)
    lines = read_text(path, "TRC", "check the path").splitlines()
    try:
        return _parse_trc(lines)
    except (ValueError, IndexError, KeyError) as error:
        raise TrackerInputError(
            f"{path}: not a valid TRC file ({error}); give a tab-separated OpenSim .trc file"
        ) from None


def _parse_trc(lines: list[str]) -> Trc:
    if not lines or not lines[0].startswith("PathFileType"):
        raise ValueError("no PathFileType line")
    header = dict(zip(lines[1].split("\t"), (value.strip() for value in lines[2].split("\t"))))
    for key in HEADER_KEYS[:5]:
        if key not in header:
            raise KeyError(f"header has no {key}")
    names = tuple(name.strip() for name in lines[3].split("\t")[2:] if name.strip())
    if len(names) != int(header["NumMarkers"]):
        raise ValueError(f"NumMarkers is {header['NumMarkers']} but {len(names)} marker names follow")
    width = 2 + 3 * len(names)
    rows = []
    for line in lines[5:]:
        if not line.strip():
            continue
        fields = line.rstrip("\r\n").split("\t")
        if len(fields) > width and any(field.strip() for field in fields[width:]):
            raise ValueError(f"a data row holds {len(fields)} fields, more than the {width} of Frame#, Time, X Y Z")
        fields = (fields + [""] * width)[:width]
        rows.append([float(field) if field.strip() else np.nan for field in fields])
    data = np.array(rows, dtype=np.float64).reshape(len(rows), width)
    return Trc(
        header=header,
        names=names,
        frame=data[:, 0].astype(np.int64),
        time=data[:, 1],
        markers=data[:, 2:].reshape(len(rows), len(names), 3),
    )
