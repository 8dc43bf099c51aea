"""The viewer of ``tracker points --view``: the fitted superquadric parts, the markers and the joints,
frame by frame, from poses.npz and shapes.npz.

Each part is drawn as its node mesh, x_i = c + R (s(q_s; u_i, v_i) + d_i) (the kinematics of
docs/method-physics.md, section 2), shaded in its own colour; the markers are
dots in their part's colour, the joints black dots.
"""

from __future__ import annotations

from typing import cast

import numpy as np
import viser

from tracker.physics import kinematics as kin
from tracker.physics import superquadric as sq
from tracker.viewer.overlay import component_colours
from tracker.viewer.timeline import Timeline


def node_positions(poses: np.ndarray, q_s: np.ndarray, d: np.ndarray, *, mesh: sq.Mesh) -> np.ndarray:
    """World node positions (P, n, 3) of one frame's parts: poses (P, 4, 4), q_s (P, 11), d (P, n, 3)."""
    return np.stack(
        [
            kin.positions(kin.Part(pose[:3, 3], pose[:3, :3], shape, nodes, mesh.u, mesh.v))
            for pose, shape, nodes in zip(poses, q_s, d)
        ]
    )


class PointsView(Timeline):
    """A frame slider over one ``tracker points`` run: ``results`` (poses.npz arrays), ``shapes``
    (shapes.npz arrays) and ``markers`` (F, M, 3) the fitted markers of the same frames, recorded at
    ``rate`` frames a second."""

    def __init__(self, server: viser.ViserServer, results: dict, shapes: dict, markers: np.ndarray, rate: float):
        super().__init__(server, len(results["frame"]), rate)
        self.results, self.shapes, self.markers = results, shapes, markers
        self.mesh = sq.mesh(*(int(n) for n in shapes["mesh"]))
        names = [str(name) for name in shapes["part_names"]]
        colours = np.array(component_colours(len(names)))
        scene = server.scene
        scene.add_grid("/ground", width=4.0, height=4.0, plane="xy", cell_size=0.25)
        first = node_positions(results["poses"][0], shapes["q_s"][0], shapes["d"][0], mesh=self.mesh)
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
        self.status = server.gui.add_markdown("")
        self.add_slider(server.gui)
        centre = first.reshape(-1, 3).mean(axis=0)
        server.initial_camera.look_at = tuple(centre)
        server.initial_camera.position = tuple(centre + np.array([2.0, -2.0, 1.0]))

    def draw(self, row: int) -> None:
        """Draw row ``row`` of the run: its parts, the markers seen and the joints."""
        nodes = node_positions(
            self.results["poses"][row], self.shapes["q_s"][row], self.shapes["d"][row], mesh=self.mesh
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
