"""The viewer's scene and camera panels (viser): what is drawn, not when.

World frame as in the calibration (z up, metres).  Drawn: the model as shaded
meshes of its clipped quadrics at the current poses (the parts the images do not
hold grey and see-through, :mod:`tracker.tracking.held`), its joints and bones, the
ground grid (z = 0), every camera as a frustum showing its current image, the
truth skeleton when there is one (blue), and the root's trajectory.  Beside the
3-D view, one image panel per camera with the search lines, outlines and found
edges (:mod:`tracker.viewer.overlay`; the parts the images do not hold dim).
"""

from __future__ import annotations

import contextlib
import io
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import viser
import viser.transforms as vtf

from tracker.atomic import atomic_write
from tracker.model import Model, joint_centres
from tracker.status import HELD
from tracker.tracking.workspace import Inspection
from tracker.viewer.mesh import component_meshes
from tracker.viewer.overlay import component_colours, draw

BODY = (235, 120, 40)  # shaded meshes and bones
LOOSE = (150, 150, 150)  # the meshes of parts the images do not hold (tracker.tracking.held) ...
LOOSE_OPACITY = 0.3  # ... see-through
TRUTH = (40, 150, 255)  # the truth skeleton
TRAJECTORY = (250, 220, 60)
FRUSTUM_WIDTH = 200  # pixels of the images shown on the frustums (the panels get full size)


class _Silent(viser.ViserServer):
    """A viser server that prints nothing: viser prints its address in a box when it starts and "(viser) Server
    stopped" when it stops (also at exit), whatever its ``verbose``, on standard output."""

    def __init__(self, **kwargs) -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            super().__init__(**kwargs)

    def stop(self) -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            super().stop()


def start_server(host: str = "127.0.0.1", port: int = 8080, quiet: bool = False) -> viser.ViserServer:
    """A viser server on ``host:port`` (the next free port if taken); says its URL on stderr, unless ``quiet``: a
    server no one is meant to open (one that only records a .viser file) says nothing at all.

    Any address other than loopback opens the viewer to the network, so it warns.
    """
    if host not in ("127.0.0.1", "localhost", "::1") and not quiet:
        print(
            f"tracker: warning: the viewer listens on {host}: anyone who can reach this machine can see it",
            file=sys.stderr,
        )
    server = (_Silent if quiet else viser.ViserServer)(host=host, port=port, verbose=False)
    server.scene.set_up_direction("+z")
    server.scene.configure_default_lights(cast_shadow=False)  # shadow maps double the cost of every redraw
    if not quiet:
        shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
        print(f"viewer: http://{shown}:{server.get_port()}", file=sys.stderr, flush=True)
    return server


def add_plot(
    gui,
    title: str,
    *,
    label: str,
    colour: str,
    x: np.ndarray,
    y: np.ndarray,
    y_range: tuple[float, float] | None = None,
):
    """A uPlot line chart of ``y`` against frame numbers ``x`` in the GUI panel (``y_range`` fixes its axis)."""
    scales: dict[str, dict[str, object]] = {"x": {"time": False}}
    if y_range is not None:
        scales["y"] = {"auto": False, "range": list(y_range)}
    return gui.add_uplot(
        (np.asarray(x, np.float64), np.asarray(y, np.float64)),
        ({"label": "frame"}, {"label": label, "stroke": colour, "width": 1.5}),
        title=title,
        scales=scales,
        aspect=2.5,
    )


PLOTS = (
    ("status", "0 tracked, 1 uncertain, 2 lost", "#d04020", (-0.1, 2.1)),
    ("residual", "residual (px)", "#2060d0", None),
    ("fps", "tracker fps", "#20a040", None),
)


def run_plot_values(status: np.ndarray, residual: np.ndarray, elapsed: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame status, residual (-1 where no edge was found) and tracker speed (0 where unknown)."""
    elapsed = np.asarray(elapsed, np.float64)
    known = elapsed > 0
    return {
        "status": np.asarray(status, np.float64),
        "residual": np.nan_to_num(np.asarray(residual, np.float64), nan=-1.0),
        "fps": np.where(known, 1.0 / np.where(known, elapsed, 1.0), 0.0),
    }


def add_run_plots(gui, *, frames, status, residual, elapsed) -> dict:
    """The status, residual and speed plots of a run, keyed as :data:`PLOTS`."""
    values = run_plot_values(status, residual, elapsed)
    return {
        key: add_plot(gui, key, label=label, colour=colour, x=frames, y=values[key], y_range=y_range)
        for key, label, colour, y_range in PLOTS
    }


def write_viser(serializer, path) -> None:
    """Write a scene serializer's recording as a .viser file, atomically."""
    data = serializer.serialize()
    atomic_write(Path(path), lambda file: file.write(data))


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    return vtf.SO3.from_matrix(rotation).wxyz


def bones(model: Model, joints: np.ndarray) -> np.ndarray:
    """Segments (N-1, 2, 3) from each joint to its parent's joint."""
    child = np.arange(1, model.size)
    return np.stack([joints[model.parent[child]], joints[child]], 1)


@dataclass
class Frame:
    """Everything drawn for one frame; ``images`` are grey, one per camera, or None."""

    poses: np.ndarray
    images: list[np.ndarray] | None = None
    inspection: Inspection | None = None
    truth: np.ndarray | None = None  # truth joint centres (J, 3), NaN where unknown
    label: str = ""
    held: np.ndarray | None = None  # which parts the images hold (N,) codes (tracker.status), None: unknown


class Scene:
    """Builds the scene on a server and redraws it for each :class:`Frame`."""

    def __init__(
        self,
        server: viser.ViserServer,
        model: Model,
        cameras,
        robust_c: float = 2.0,
        truth_names: list[str] | None = None,
    ):
        self.server, self.model, self.cameras, self.robust_c = server, model, cameras, robust_c
        self.colours = component_colours(model.size)
        scene = server.scene
        scene.add_grid("/ground", width=8.0, height=8.0, plane="xy", cell_size=0.5)
        self.meshes = [
            scene.add_mesh_simple(f"/body/{name}", vertices, faces, color=BODY, flat_shading=False)
            for name, (vertices, faces) in zip(model.names, component_meshes(model))
        ]
        self.loose = np.zeros(model.size, bool)  # the parts drawn as not held by the images (show)
        self.joints = scene.add_point_cloud(
            "/joints", np.zeros((model.size, 3), np.float32), colors=(30, 30, 30), point_size=0.03, point_shape="circle"
        )
        self.bones = scene.add_line_segments(
            "/bones", np.zeros((model.size - 1, 2, 3), np.float32), BODY, thickness=0.012
        )
        self.truth_index = None
        if truth_names is not None:
            index = {name: k for k, name in enumerate(truth_names)}
            self.truth_index = np.array([index.get(name, -1) for name in model.joint_names])
            self.truth = scene.add_line_segments(
                "/truth", np.zeros((model.size - 1, 2, 3), np.float32), TRUTH, thickness=0.008
            )
        self.trajectory: viser.LineSegmentsHandle | None = None
        self.frustums = []
        self.panels = []
        folder = server.gui.add_folder("Cameras", order=30)
        for camera in cameras:
            width, height = camera.size
            fov = 2.0 * np.arctan(0.5 * height / camera.matrix[1, 1])
            self.frustums.append(
                scene.add_camera_frustum(
                    f"/cameras/{camera.name}",
                    fov=fov,
                    aspect=width / height,
                    scale=0.25,
                    color=(60, 60, 60),
                    wxyz=_wxyz(camera.rotation.T),
                    position=camera.center,
                    image=np.zeros((FRUSTUM_WIDTH * height // width, FRUSTUM_WIDTH, 3), np.uint8),
                    format="jpeg",
                )
            )
            with folder:
                self.panels.append(
                    server.gui.add_image(
                        np.zeros((height, width, 3), np.uint8), label=camera.name, format="jpeg", jpeg_quality=70
                    )
                )
        self.status = server.gui.add_markdown("", order=10)

    def look_at_body(self, poses: np.ndarray, distance: float = 4.0) -> None:
        """Start browsers' view ``distance`` metres out towards the cameras' mean centre and 2 m up,
        looking at the body."""
        centre = poses[0, 0:3, 3]
        away = np.mean([camera.center for camera in self.cameras], axis=0) - centre
        away[2] = 0.0
        if np.linalg.norm(away) < 1e-6:
            away = self.cameras[0].center - centre
        eye = centre + distance * away / np.linalg.norm(away) + np.array([0.0, 0.0, 0.5 * distance])
        self.server.initial_camera.position = tuple(eye)
        self.server.initial_camera.look_at = tuple(centre)

    def show_trajectory(self, points: np.ndarray) -> None:
        """The root's path as a polyline (P, 3)."""
        points = np.asarray(points, np.float32)
        points = points[np.isfinite(points).all(axis=1)]
        if len(points) < 2:
            return
        segments = np.stack([points[:-1], points[1:]], 1)
        if self.trajectory is None:
            self.trajectory = self.server.scene.add_line_segments("/trajectory", segments, TRAJECTORY, thickness=0.006)
        else:
            self.trajectory.points = segments

    def show(self, frame: Frame) -> None:
        """Redraw the body, the truth, and the camera images with their overlays, as one batch."""
        joints = joint_centres(frame.poses)
        images = None
        if frame.images is not None:
            images = [
                draw(image, frame.inspection, k, robust_c=self.robust_c, colours=self.colours, held=frame.held)
                if frame.inspection is not None
                else cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
                for k, image in enumerate(frame.images)
            ]
        loose = np.zeros(self.model.size, bool) if frame.held is None else np.asarray(frame.held) != HELD
        with self.server.atomic():
            for mesh, pose in zip(self.meshes, frame.poses):
                mesh.wxyz = _wxyz(pose[0:3, 0:3])
                mesh.position = pose[0:3, 3]
            for i in np.flatnonzero(loose != self.loose):  # only the parts whose holding changed
                self.meshes[i].color = LOOSE if loose[i] else BODY
                self.meshes[i].opacity = LOOSE_OPACITY if loose[i] else None
            self.loose = loose
            self.joints.points = joints.astype(np.float32)
            self.bones.points = bones(self.model, joints).astype(np.float32)
            if self.truth_index is not None and frame.truth is not None:
                truth = np.where(self.truth_index[:, None] >= 0, frame.truth[self.truth_index], np.nan)
                segments = bones(self.model, truth)
                self.truth.points = np.nan_to_num(segments).astype(np.float32)
            if images is not None:
                for frustum, panel, image in zip(self.frustums, self.panels, images):
                    height, width = image.shape[:2]
                    frustum.image = cv2.resize(
                        image, (FRUSTUM_WIDTH, FRUSTUM_WIDTH * height // width), interpolation=cv2.INTER_AREA
                    )
                    panel.image = image
            self.status.content = frame.label
