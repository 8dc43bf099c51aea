"""A batch's records on disk (docs/batch.md): the manifest that lets an interrupted ``tracker batch`` resume,
and the summary of its recordings.

``DIR/manifest.json`` holds the tracking options of the batch and, for every recording it took on, either
``{"state": "started", "name": ...}`` (its results folder ``DIR/name`` belongs to the batch but is not finished:
a resumed batch empties it and tracks the recording again) or its finished :class:`Row` (``done`` or
``failed``), which names the folder too.  A recording keeps its folder's name for the life of the batch.  The
manifest is rewritten atomically after every change, so a batch stopped at any moment leaves one that says what
is finished.
``DIR/summary.csv`` holds the rows, one per recording, with the columns of :data:`COLUMNS`.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from pathlib import Path

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError

FORMAT = "tracker batch manifest"
VERSION = 1

DONE = "done"
FAILED = "failed"
STARTED = "started"


@dataclasses.dataclass(frozen=True)
class Row:
    """One recording of a batch: how its tracking ended and what ``tracker track`` reported of it."""

    recording: str  # the recording folder, absolute
    name: str  # its results folder under the batch's output folder
    state: str  # DONE or FAILED
    frames: int = 0  # frames tracked
    fps: float = math.nan  # frames per second of the tracking loop
    residual_px: float = math.nan  # mean residual
    lost: int = 0  # frames lost
    mpjpe_mm: float = math.nan  # against the recording's truth.npz, NaN without one
    attempts: int = 1  # tries it took (a crashed try is retried, a one-line input error is not)
    seconds: float = math.nan  # wall time of the try that finished, start-up included
    error: str = ""  # the one-line error of a failed recording


COLUMNS = tuple(field.name for field in dataclasses.fields(Row))
"""The columns of summary.csv, in order."""


class Manifest:
    """The batch's manifest at ``path`` (module docstring): each recording's results folder and state, under
    ``options``."""

    def __init__(self, path: Path, options: dict) -> None:
        self.path = path
        self.options = options
        self.names: dict[str, str] = {}  # recording -> its results folder's name, for every recording taken on
        self.rows: dict[str, Row] = {}  # recording -> its finished row

    @classmethod
    def open(cls, path: Path, options: dict) -> Manifest:
        """The manifest at ``path``, or a new one when there is none; a one-line error when it was written for
        other tracking options (the finished results would not match the ones still to come) or is unreadable."""
        manifest = cls(path, options)
        if not path.exists():
            return manifest
        try:
            data = json.loads(path.read_text())
            if data.get("format") != FORMAT or data.get("version") != VERSION:
                raise ValueError("not a tracker batch manifest")
            for recording, entry in data["recordings"].items():
                manifest.names[recording] = str(entry["name"])
                if entry.get("state") != STARTED:
                    manifest.rows[recording] = Row(**entry)
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise TrackerInputError(
                f"{path}: unreadable batch manifest ({error}); remove it to start the batch afresh, or pick another "
                "--out"
            ) from None
        if data.get("options") != options:
            changed = sorted(
                key for key in {*options, *data.get("options", {})} if options.get(key) != data["options"].get(key)
            )
            raise TrackerInputError(
                f"{path}: this batch was started with other tracking options ({', '.join(changed)}); run it again "
                "with the same options to resume, or pick another --out"
            )
        return manifest

    def row(self, recording: str) -> Row | None:
        """The finished row of ``recording``, or None when it is not finished."""
        return self.rows.get(recording)

    def finished(self) -> list[Row]:
        """The rows of every finished recording, in the order the batch took them on."""
        return [self.rows[recording] for recording in self.names if recording in self.rows]

    def start(self, names: dict[str, str]) -> None:
        """Mark the recordings of ``names`` (recording -> results folder name) started, their results folders now
        the batch's, and save."""
        self.names.update(names)
        for recording in names:
            self.rows.pop(recording, None)
        self.save()

    def finish(self, row: Row) -> None:
        """Record ``row`` as its recording's outcome and save."""
        self.rows[row.recording] = row
        self.save()

    def save(self) -> None:
        """Write the manifest atomically."""
        recordings = {
            recording: dataclasses.asdict(self.rows[recording])
            if recording in self.rows
            else {"state": STARTED, "name": name}
            for recording, name in self.names.items()
        }
        text = json.dumps(
            {"format": FORMAT, "version": VERSION, "options": self.options, "recordings": recordings}, indent=1
        )
        atomic_write(self.path, lambda file: file.write(text.encode()))


def write_summary(rows: list[Row], path: Path) -> None:
    """``rows`` as a CSV table with a header of :data:`COLUMNS`, written atomically."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    writer.writerows([getattr(row, column) for column in COLUMNS] for row in rows)
    atomic_write(path, lambda file: file.write(text.getvalue().encode()))


def format_summary(rows: list[Row]) -> str:
    """``rows`` as a table for the terminal: one line a recording, a failed one with its error after it."""
    width = max([len("recording"), *(len(row.name) for row in rows)])
    lines = [
        f"{'recording':<{width}}  {'state':<6}  {'frames':>6}  {'fps':>6}  {'residual':>8}  {'lost':>5}  "
        f"{'MPJPE':>8}  {'tries':>5}"
    ]
    for row in rows:
        mpjpe = "-" if math.isnan(row.mpjpe_mm) else f"{row.mpjpe_mm:.1f} mm"
        residual = "-" if math.isnan(row.residual_px) else f"{row.residual_px:.2f} px"
        fps = "-" if math.isnan(row.fps) else f"{row.fps:.1f}"
        lines.append(
            f"{row.name:<{width}}  {row.state:<6}  {row.frames:>6}  {fps:>6}  {residual:>8}  {row.lost:>5}  "
            f"{mpjpe:>8}  {row.attempts:>5}"
        )
        if row.error:
            lines.append(f"{'':<{width}}  {row.error}")
    return "\n".join(lines)
