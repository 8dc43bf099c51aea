"""Calibration boards: the ``--board`` spec, the board's 3-D corners, and corner detection in one image.

Two kinds of planar board are supported:

``chessboard:COLSxROWS:SQUARE_M``
    COLS x ROWS *inner* corners (a board of (COLS+1) x (ROWS+1) squares), squares SQUARE_M metres wide.
    Corner ``k = r * COLS + c`` (row r, column c) lies at ``(c * s, r * s, 0)`` in the board frame.

``charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT``
    OpenCV's ChArUco board of COLS x ROWS *squares* with ArUco markers of dictionary DICT (e.g.
    ``DICT_4X4_1000``) MARKER_M wide in its white squares. Its (COLS-1) x (ROWS-1) inner corners are
    numbered like OpenCV's: corner ``k = r * (COLS-1) + c`` at ``((c+1) s, (r+1) s, 0)``.

An ``:inverted`` suffix (or ``--inverted``) says the board is printed light-on-dark; the image is
then inverted before detection so the detectors see dark markers with a light quiet zone.

The board frame: x along a row of corners, y down the columns, z = x cross y, which points *into*
the board, away from a camera that sees its printed face.

Orientation of a chessboard. A chessboard detector finds the grid but not which of its corners
is corner 0: the same grid read in reverse (the board turned by 180 degrees) fits as well, and
OpenCV sometimes also reads the rows mirrored. Two cameras that read one board differently
disagree about its pose by 180 degrees, and the rig comes out wrong. Each detection is therefore
put in canonical order:

* handedness: with corners p_k, the image cross product (p_1 - p_0) x (p_COLS - p_0) is positive
  for a board seen from its face (x right, y down in a frontal view); a negative one means the
  rows were read mirrored, and they are reversed;
* colour: with the grid's inner squares (i, j), i < COLS-1, j < ROWS-1, and I(i, j) the image
  brightness at the square's centre (the mean of its four corners), the score
  sum (-1)^(i+j) I(i, j) is negative when square (0, 0) is dark. Turning the board by 180 degrees
  maps square (i, j) to (COLS-2-i, ROWS-2-j), which changes the parity by COLS+ROWS, so for
  COLS+ROWS odd (an odd x even board) the two readings have opposite scores and the one with
  square (0, 0) dark is kept. For COLS+ROWS even (6x6, 8x6, 7x5) the board looks the same turned
  round: such a *symmetric* board is fine for intrinsics but refused for a rig.

ChArUco boards carry their orientation in the marker ids. A double-sided ChArUco board whose back
is printed mirrored (as caliscope makes them, so that cameras facing each other share views) is
detected too: when the image finds too few corners, its left-right mirror image is searched and
the corners found there are mapped back, x -> W - 1 - x. The back print lies behind the front
one, so a corner has the same 3-D position on both sides (the board's thickness is neglected).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from tracker.errors import TrackerInputError

MIN_CORNERS = 6  # fewer corners in a view do not give a trustworthy pose
DETECT_SIDE = 1280  # chessboards are searched in a copy at most this many pixels wide (corners refined at full size)
_CHESSBOARD_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 40, 0.001)

_SPEC_HELP = (
    "write chessboard:COLSxROWS:SQUARE_M (inner corners, e.g. chessboard:9x6:0.025) or "
    "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT (squares, e.g. charuco:4x5:0.054:0.040:DICT_4X4_1000), "
    "optionally ending in :inverted"
)


@dataclass(frozen=True)
class Detection:
    """The corners of one board found in one image: ids (n,) into Board.object_points, pixels (n, 2)."""

    ids: np.ndarray
    pixels: np.ndarray


@dataclass(frozen=True)
class Board:
    """A planar calibration board (see the module docstring for the spec and the board frame)."""

    kind: str  # "chessboard" or "charuco"
    cols: int  # chessboard: inner corners per row; charuco: squares per row
    rows: int
    square: float  # metres
    marker: float = 0.0  # charuco marker side, metres
    dictionary: str = ""  # charuco ArUco dictionary name, e.g. DICT_4X4_1000
    inverted: bool = False

    @property
    def grid(self) -> tuple[int, int]:
        """Inner corners (per row, per column)."""
        return (self.cols, self.rows) if self.kind == "chessboard" else (self.cols - 1, self.rows - 1)

    @property
    def symmetric(self) -> bool:
        """A chessboard that looks the same turned by 180 degrees (COLS + ROWS even)."""
        return self.kind == "chessboard" and (self.cols + self.rows) % 2 == 0

    @cached_property
    def object_points(self) -> np.ndarray:
        """(N, 3) corner positions in the board frame, metres, indexed by corner id (computed once, read-only)."""
        cols, rows = self.grid
        c, r = np.meshgrid(np.arange(cols), np.arange(rows))
        offset = 0.0 if self.kind == "chessboard" else 1.0
        points = np.stack(
            [(c.ravel() + offset) * self.square, (r.ravel() + offset) * self.square, np.zeros(c.size)], axis=1
        )
        points.setflags(write=False)  # shared by every caller
        return points

    def describe(self) -> str:
        """The board in words, for messages: what was looked for."""
        side = " (light on dark)" if self.inverted else ""
        if self.kind == "chessboard":
            return f"{self.cols}x{self.rows} chessboard (inner corners){side}"
        return f"{self.cols}x{self.rows} ChArUco board (squares, {self.dictionary}){side}"

    def detector(self) -> BoardDetector:
        """A detector for this board; make one per thread (OpenCV's detectors keep state)."""
        return BoardDetector(self)


def parse_board(spec: str, inverted: bool = False) -> Board:
    """The Board of a ``--board`` spec; TrackerInputError with the accepted forms when it is malformed."""
    parts = [part.strip() for part in spec.strip().split(":")]
    if parts and parts[-1].lower() == "inverted":
        inverted = True
        parts = parts[:-1]

    def fail(problem: str) -> TrackerInputError:
        return TrackerInputError(f"--board {spec}: {problem}; {_SPEC_HELP}")

    if not parts or parts[0].lower() not in ("chessboard", "charuco"):
        raise fail("unknown board kind")
    kind = parts[0].lower()
    expected = 3 if kind == "chessboard" else 5
    if len(parts) != expected:
        raise fail(f"a {kind} spec has {expected} fields separated by ':'")
    match = re.fullmatch(r"(\d+)[xX](\d+)", parts[1])
    if not match:
        raise fail(f"size {parts[1]!r} is not COLSxROWS")
    cols, rows = int(match.group(1)), int(match.group(2))
    least = 2 if kind == "chessboard" else 3
    if cols < least or rows < least:
        raise fail(f"size {cols}x{rows} is too small (at least {least}x{least})")
    try:
        lengths = [float(value) for value in parts[2 : 4 if kind == "charuco" else 3]]
    except ValueError:
        raise fail("square and marker sizes must be numbers (metres)") from None
    if any(not np.isfinite(value) or value <= 0 for value in lengths):
        raise fail("square and marker sizes must be positive (metres)")
    if kind == "chessboard":
        return Board(kind, cols, rows, lengths[0], inverted=inverted)
    square, marker = lengths
    if marker >= square:
        raise fail(f"the marker ({marker:g} m) must be smaller than the square ({square:g} m)")
    dictionary = parts[4].upper()
    if not dictionary.startswith("DICT_"):
        dictionary = "DICT_" + dictionary
    if not hasattr(cv2.aruco, dictionary):
        names = [name for name in dir(cv2.aruco) if name.startswith("DICT_")]
        raise fail(f"unknown ArUco dictionary {parts[4]!r} (known: {', '.join(names)})")
    counted = re.fullmatch(r"DICT_\d+X\d+_(\d+)", dictionary)  # DICT_4X4_1000 holds 1000 markers
    size = int(counted.group(1)) if counted else None
    markers = (cols * rows) // 2
    if size is not None and markers > size:
        raise fail(f"a {cols}x{rows} board needs {markers} markers but {dictionary} has {size}")
    return Board(kind, cols, rows, square, marker, dictionary, inverted)


class BoardDetector:
    """Finds one board's corners in grey images."""

    def __init__(self, board: Board):
        self.board = board
        self._charuco: cv2.aruco.CharucoDetector | None = None
        if board.kind == "charuco":
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
            cv_board = cv2.aruco.CharucoBoard((board.cols, board.rows), board.square, board.marker, dictionary)
            self._charuco = cv2.aruco.CharucoDetector(cv_board)

    def detect(self, grey: np.ndarray) -> Detection | None:
        """The board's corners in one grey uint8 image, or None when fewer than MIN_CORNERS were found."""
        if self.board.inverted:
            grey = 255 - grey
        if self._charuco is not None:
            return self._detect_charuco(grey)
        return self._detect_chessboard(grey)

    def _detect_charuco(self, grey: np.ndarray) -> Detection | None:
        """The board's front side, else its mirrored back (double-sided boards): the back's corners are
        those of the front seen in a left-right flipped image, mapped back by x -> W - 1 - x."""
        assert self._charuco is not None  # called for ChArUco boards only
        for mirrored in (False, True):
            image = cv2.flip(grey, 1) if mirrored else grey
            corners, ids, _, _ = self._charuco.detectBoard(image)
            if ids is None or len(ids) < MIN_CORNERS:
                continue
            pixels = corners.reshape(-1, 2).astype(np.float64)
            if mirrored:
                pixels[:, 0] = grey.shape[1] - 1 - pixels[:, 0]
            ids = ids.ravel().astype(np.int64)
            if not _spans_plane(self.board.object_points[ids]):
                return None
            order = np.argsort(ids)
            return Detection(ids[order], pixels[order])
        return None

    def _detect_chessboard(self, grey: np.ndarray) -> Detection | None:
        cols, rows = self.board.grid
        height, width = grey.shape
        scale = min(1.0, DETECT_SIDE / max(height, width))
        small = (
            grey
            if scale == 1.0
            else cv2.resize(grey, (round(width * scale), round(height * scale)), interpolation=cv2.INTER_AREA)
        )
        found, corners = cv2.findChessboardCorners(small, (cols, rows), flags=_CHESSBOARD_FLAGS)
        if not found:
            return None
        corners = corners.reshape(-1, 2).astype(np.float64)
        if scale != 1.0:  # pixel centres: x_full + 0.5 = (x_small + 0.5) / scale
            corners = (corners + 0.5) / scale - 0.5
        grid = corners.reshape(rows, cols, 2)
        spacing = min(
            np.linalg.norm(np.diff(grid, axis=1), axis=2).min(), np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
        )
        half = int(np.clip(0.35 * spacing, 2, 15))  # the window must not reach the neighbouring corners
        refined = cv2.cornerSubPix(
            grey, corners.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), _SUBPIX_CRITERIA
        )
        grid = canonical_chessboard(grey, refined.reshape(rows, cols, 2).astype(np.float64), self.board.symmetric)
        return Detection(np.arange(cols * rows), grid.reshape(-1, 2))


def canonical_chessboard(grey: np.ndarray, grid: np.ndarray, symmetric: bool) -> np.ndarray:
    """The (rows, cols, 2) corner grid put in canonical order (see the module docstring)."""
    edge_x = grid[0, 1] - grid[0, 0]
    edge_y = grid[1, 0] - grid[0, 0]
    if edge_x[0] * edge_y[1] - edge_x[1] * edge_y[0] < 0:
        grid = grid[::-1]
    if symmetric:
        return grid
    centres = 0.25 * (grid[:-1, :-1] + grid[1:, :-1] + grid[:-1, 1:] + grid[1:, 1:])
    blurred = cv2.blur(grey, (3, 3))
    x = np.clip(np.round(centres[..., 0]).astype(int), 0, grey.shape[1] - 1)
    y = np.clip(np.round(centres[..., 1]).astype(int), 0, grey.shape[0] - 1)
    brightness = blurred[y, x].astype(np.float64)
    j, i = np.indices(brightness.shape)
    score = np.sum(np.where((i + j) % 2 == 0, 1.0, -1.0) * brightness)
    return grid if score <= 0 else grid[::-1, ::-1]


def _spans_plane(points: np.ndarray) -> bool:
    """Whether board points are spread in two directions (not all on one line)."""
    centred = points[:, :2] - points[:, :2].mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    return len(points) >= MIN_CORNERS and singular[1] > 0.2 * singular[0]
