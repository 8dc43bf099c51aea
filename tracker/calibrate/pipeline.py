"""The calibration pipeline of ``tracker calibrate``: a camera rig from a folder of board videos.

Steps: find the board in every camera's frames (tracker/calibrate/board.py, sources.py);
calibrate each camera's intrinsics from its own views (intrinsics.py) unless ``--fix-intrinsics``
gives them; unless ``--intrinsics-only``, find the cameras' poses from the views they share
(extrinsics.py: board poses, robust pairwise poses, a spanning tree, bundle adjustment); put the
world frame at the first camera or at the board; report the reprojection RMS per camera (the
command writes calibration.toml and prints the report).

``--world board``: the world is the board in the first frame it is seen in, taken as lying
face up on the floor: world x along the board's rows, y = -(board y), z = -(board z), so z points
up out of the floor towards the cameras looking down at it. The origin is the board's first
corner (chessboard) or its outer corner (ChArUco).

``--intrinsics-only`` writes every camera at the world origin (identity rotation, zero
translation): only its intrinsics mean anything.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from tracker.calibrate.board import MIN_CORNERS, Board
from tracker.calibrate.extrinsics import (
    FLOOR_FROM_BOARD,
    RigResult,
    SplitRigError,
    calibrate_rig,
    to_world,
)
from tracker.calibrate.intrinsics import MIN_VIEWS, Intrinsics, calibrate_intrinsics
from tracker.calibrate.sources import CameraViews, detect_all, find_sources
from tracker.camera import Camera, load_calibration
from tracker.errors import TrackerInputError
from tracker.geometry import se3


@dataclass
class Calibration:
    cameras: list[Camera]
    views: list[CameraViews]
    intrinsics: list[Intrinsics | None]  # None for fixed intrinsics
    rig: RigResult | None  # None with intrinsics only

    def report(self) -> str:
        """One line per camera: views, intrinsic RMS, extrinsic RMS before and after the adjustment."""
        lines = []
        width = max(len(camera.name) for camera in self.cameras)
        for c, (camera, views) in enumerate(zip(self.cameras, self.views)):
            line = (
                f"{camera.name:<{width}}  {camera.size[0]}x{camera.size[1]}  "
                f"board in {len(views.detections)}/{views.searched} frames"
            )
            intrinsics = self.intrinsics[c]
            if intrinsics is not None:
                line += f"  intrinsics RMS {intrinsics.rms:.3f} px ({intrinsics.views} views)"
            if self.rig is not None:
                line += (
                    f"  rig RMS {self.rig.rms[c]:.3f} px over {self.rig.frames[c]} views"
                    f" (before adjustment {self.rig.initial_rms[c]:.3f} px)"
                )
            lines.append(line)
        if self.rig is not None and self.rig.dropped:
            lines.append(f"{self.rig.dropped} corner observations rejected as outliers")
        return "\n".join(lines)


def calibrate(
    folder,
    board: Board,
    *,
    intrinsics_only: bool = False,
    fixed=None,
    world: str = "first-camera",
    refine_intrinsics: bool = False,
    max_frames: int = 300,
    progress: bool = False,
) -> Calibration:
    """The whole calibration of a folder (see the module docstring); raises TrackerInputError."""
    views = find_sources(folder)
    if board.symmetric and len(views) > 1 and not intrinsics_only:
        raise TrackerInputError(
            f"--board: a {board.cols}x{board.rows} chessboard looks the same turned by 180 degrees, so the cameras "
            "cannot agree on its orientation; use a chessboard with one odd and one even count of inner corners "
            "(e.g. 9x6) or a ChArUco board (or calibrate --intrinsics-only)"
        )
    fixed_cameras = _fixed_intrinsics(fixed, views) if fixed else None
    detect_all(board, views, max_frames=max_frames, progress=progress)

    for camera in views:
        if not camera.detections:
            raise TrackerInputError(
                f"{camera.source}: no {board.describe()} found in any of the {camera.searched} frames searched; "
                "check --board (chessboard sizes count inner corners, ChArUco sizes count squares"
                f"{'' if board.inverted else ', add :inverted for a light-on-dark board'}) "
                "and that the board is in view"
            )
        if fixed_cameras is None and len(camera.detections) < MIN_VIEWS:
            raise TrackerInputError(
                f"{camera.source}: too few board views for intrinsics: found the {board.describe()} in "
                f"{len(camera.detections)} of {camera.searched} frames, need at least {MIN_VIEWS} "
                f"(each with {MIN_CORNERS}+ corners); record more views of the board, tilted and in different "
                "parts of the image"
            )
        if fixed_cameras is not None and fixed_cameras[camera.name].size != camera.size:
            size = fixed_cameras[camera.name].size
            raise TrackerInputError(
                f"{fixed}: camera {camera.name!r} is {size[0]}x{size[1]} there but {camera.source} is "
                f"{camera.size[0]}x{camera.size[1]}; give the intrinsics of this camera at this resolution"
            )

    intrinsics: list[Intrinsics | None] = []
    cameras = []
    for camera in views:
        if fixed_cameras is not None:
            known = fixed_cameras[camera.name]
            intrinsics.append(None)
            cameras.append(replace(known, rotation=np.eye(3), translation=np.zeros(3)))  # name and size checked above
        else:
            result = calibrate_intrinsics(board, camera.detections, camera.size)
            intrinsics.append(result)
            cameras.append(Camera(camera.name, camera.size, result.matrix, result.distortions, np.eye(3), np.zeros(3)))
    if intrinsics_only:
        return Calibration(cameras, views, intrinsics, None)

    first = min(f for camera in views for f in camera.detections)
    try:
        rig = calibrate_rig(
            board,
            cameras,
            [camera.detections for camera in views],
            refine_intrinsics=refine_intrinsics,
            keep_frames=(first,),
        )
    except SplitRigError as error:
        raise _split_rig_error(folder, views, error.unreached) from None
    cameras = rig.cameras
    if world == "board":
        root_from_board = rig.root_from_board.get(first)
        if root_from_board is None:  # the first view gave no usable pose: take the earliest that did
            root_from_board = rig.root_from_board[min(rig.root_from_board)]
        cameras = to_world(cameras, FLOOR_FROM_BOARD @ se3.inverse(root_from_board))
        heights = [camera.center[2] for camera in cameras]
        if np.median(heights) < 0:
            warnings.warn(
                f"{folder}: most cameras are below the board's plane in the world frame (--world board "
                "takes the board as lying face up on the floor in the first frame it is seen)",
                stacklevel=2,
            )
    return Calibration(cameras, views, intrinsics, rig)


def _fixed_intrinsics(path, views: list[CameraViews]) -> dict[str, Camera]:
    known = {camera.name: camera for camera in load_calibration(path)}
    missing = [camera.name for camera in views if camera.name not in known]
    if missing:
        raise TrackerInputError(
            f"{path}: no camera named {', '.join(map(repr, missing))} (it has {', '.join(map(repr, known))}); "
            "name the cameras there like the videos"
        )
    return known


def _split_rig_error(folder, views: list[CameraViews], unreached: list[int]) -> TrackerInputError:
    """The message for cameras that share no board view with the first camera."""
    frames = [set(camera.detections) for camera in views]
    alone = [c for c in unreached if not any(frames[c] & frames[o] for o in range(len(views)) if o != c)]
    if alone:
        c = alone[0]
        return TrackerInputError(
            f"{views[c].source}: camera {views[c].name!r} shares no board view with the other cameras (it sees the "
            f"board in {len(frames[c])} frames, none of them seen by another camera); record frames in which it "
            "and at least one other camera see the board at the same time"
        )
    names = ", ".join(views[c].name for c in unreached)
    return TrackerInputError(
        f"{folder}: cameras {names} share no board view with {views[0].name} or the cameras linked to it; record "
        "frames in which a camera of each group sees the board at the same time as one of the other"
    )
