"""The viewer of ``tracker points --view``: the fitted superquadric parts, the markers and the joints,
frame by frame, from poses.npz and shapes.npz.

Each part is drawn as its node mesh, x_i = c + R (s(q_s; u_i, v_i) + d_i) (the kinematics of
docs/method-physics.md, section 2), shaded in its own colour; the markers are
dots in their part's colour, the joints black dots.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import cast

import numpy as np
import viser
from tqdm import tqdm

from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq
from tracker.viewer.overlay import component_colours
from tracker.viewer.scene import write_viser


def node_positions(poses: np.ndarray, q_s: np.ndarray, d: np.ndarray, mesh: sq.Mesh) -> np.ndarray:
    """World node positions (P, n, 3) of one frame's parts: poses (P, 4, 4), q_s (P, 11), d (P, n, 3)."""
    return np.stack(
        [
            kin.positions(kin.Part(pose[:3, 3], pose[:3, :3], shape, nodes, mesh.u, mesh.v))
            for pose, shape, nodes in zip(poses, q_s, d)
        ]
    )


class PointsView:
    """A frame slider over one ``tracker points`` run: ``results`` (poses.npz arrays), ``shapes``
    (shapes.npz arrays) and ``markers`` (F, M, 3) the fitted markers of the same frames."""

    def __init__(self, server: viser.ViserServer, results: dict, shapes: dict, markers: np.ndarray, rate: float):
        self.server, self.results, self.shapes, self.markers, self.rate = server, results, shapes, markers, rate
        self.mesh = sq.mesh(*(int(n) for n in shapes["mesh"]))
        names = [str(name) for name in shapes["part_names"]]
        colours = np.array(component_colours(len(names)))
        scene = server.scene
        scene.add_grid("/ground", width=4.0, height=4.0, plane="xy", cell_size=0.25)
        first = node_positions(results["poses"][0], shapes["q_s"][0], shapes["d"][0], self.mesh)
        self.parts = [
            scene.add_mesh_simple(
                f"/parts/{name}",
                nodes.astype(np.float32),
                self.mesh.triangles.astype(np.uint32),
                color=cast(tuple[int, int, int], tuple(int(c) for c in colour)),  # RGB
                flat_shading=False,
                opacity=0.6,
            )
            for name, nodes, colour in zip(names, first, colours)
        ]
        self.marker_colours = colours[shapes["marker_part"]].astype(np.uint8)
        self.dots = scene.add_point_cloud(
            "/markers",
            np.zeros((markers.shape[1], 3), np.float32),
            colors=self.marker_colours,
            point_size=0.012,
            point_shape="circle",
        )
        self.joints = scene.add_point_cloud(
            "/joints",
            np.zeros((results["joints"].shape[1], 3), np.float32),
            colors=(20, 20, 20),
            point_size=0.025,
            point_shape="circle",
        )
        self.lock = threading.Lock()  # browsers move the slider from viser's threads
        self.row = -1
        self.status = server.gui.add_markdown("")
        self.slider = server.gui.add_slider(
            "frame", min=0, max=max(len(results["frame"]) - 1, 1), step=1, initial_value=0
        )
        self.slider.on_update(lambda _: self.show(int(self.slider.value)))
        centre = first.reshape(-1, 3).mean(axis=0)
        server.initial_camera.look_at = tuple(centre)
        server.initial_camera.position = tuple(centre + np.array([2.0, -2.0, 1.0]))

    def show(self, row: int) -> None:
        """Draw row ``row`` of the run (clamped to its rows; a row already shown is not redrawn)."""
        row = min(max(int(row), 0), len(self.results["frame"]) - 1)
        with self.lock:
            if row == self.row:
                return
            nodes = node_positions(
                self.results["poses"][row], self.shapes["q_s"][row], self.shapes["d"][row], self.mesh
            )
            with self.server.atomic():
                for handle, part_nodes in zip(self.parts, nodes):
                    handle.vertices = part_nodes.astype(np.float32)
                seen = np.isfinite(self.markers[row]).all(axis=1)  # markers not seen this frame are not drawn
                self.dots.points = self.markers[row][seen].astype(np.float32)
                self.dots.colors = self.marker_colours[seen]
                self.joints.points = self.results["joints"][row].astype(np.float32)
                self.status.content = (
                    f"frame {int(self.results['frame'][row])}: RMS marker-to-node distance "
                    f"{self.results['residual'][row]:.1f} mm"
                )
            self.row = row
        self.slider.value = row  # type: ignore[misc]  # viser's setter; its callback finds the row shown and returns

    def record(self, path: Path, progress: bool = True) -> None:
        """Write every frame, at the marker file's rate, as a .viser file for viser's static client."""
        serializer = self.server.get_scene_serializer()
        for row in tqdm(
            range(len(self.results["frame"])), unit="frame", desc="recording the viewer", disable=not progress
        ):
            self.show(row)
            serializer.insert_sleep(1.0 / self.rate)
        write_viser(serializer, path)
