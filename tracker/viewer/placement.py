"""Placing the first pose by hand (``tracker init``), the paper's coarse manual start.

The viewer opens on the first frame (frame 0, or the one ``--start`` names) with a
transform gizmo on the root (move and turn the whole body) and a rotation gizmo on
every joint (turn that component and everything hanging from it).  After each drag
the joints are coerced exact and within their limits, so a hinge follows only the
part of a turn about its axis.  "Snap to the images" runs tracking iterations on
that frame from the current placement (no motion model), pulling a rough placement
onto the edges;
"Save" writes ``init.toml`` (formats.md), the pose at that frame, which
``tracker track --init`` takes when it starts there.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import viser.transforms as vtf

from tracker.geometry.se3 import inverse
from tracker.io.posefile import save_pose_file
from tracker.io.readers import FrameSeeker
from tracker.io.recording import Recording, camera_frames
from tracker.model import Model, with_descendants
from tracker.seeding.first_pose import snap_to_edges
from tracker.tracking.frame_loop import Tracker
from tracker.tracking.settings import Settings
from tracker.viewer.scene import Frame, Scene


def subtree(parent: np.ndarray, root: int) -> np.ndarray:
    """Indices of ``root`` and all its descendants (components in breadth-first order, parent[i] < i)."""
    return np.flatnonzero(with_descendants(parent, np.arange(len(parent)) == root))


def in_view(cameras, height: float = 1.0) -> np.ndarray:
    """A root pose where the cameras look: the point nearest to all their optical axes (least squares),
    raised to ``height`` metres; 3 m in front of a single camera."""
    centres = np.array([camera.center for camera in cameras])
    axes = np.array([camera.rotation[2] for camera in cameras])  # optical axes in world
    if len(cameras) == 1:
        point = centres[0] + 3.0 * axes[0]
    else:
        normal = np.sum([np.eye(3) - np.outer(a, a) for a in axes], axis=0)
        rhs = np.sum([(np.eye(3) - np.outer(a, a)) @ c for a, c in zip(axes, centres)], axis=0)
        point = np.linalg.lstsq(normal, rhs, rcond=None)[0]
    pose = np.eye(4)
    pose[0:3, 3] = [point[0], point[1], height]
    return pose


class Placement:
    """Gizmos, snap and save for the first tracked frame, ``frame``, of a recording."""

    def __init__(
        self,
        scene: Scene,
        recording: Recording,
        model: Model,
        poses: np.ndarray,
        out: Path,
        snap_iterations: int = 10,
        frame: int = 0,
    ):
        self.scene, self.recording, self.model, self.out, self.frame = scene, recording, model, Path(out), frame
        seekers = [FrameSeeker(source) for source in recording.sources]
        self.images = [seeker.read(shown) for seeker, shown in zip(seekers, camera_frames(recording, frame))]
        for seeker in seekers:
            seeker.close()
        self.settings = Settings().but(motion=dict(dynamics="none"), solve=dict(iterations=snap_iterations))
        self.tracker = Tracker(model, recording.cameras, poses, self.settings)  # redraws the frame's edge search
        self.smoothed = [self.tracker.smooth(image) for image in self.images]  # the frame never changes:
        self.tracker.load_images(self.smoothed, smoothed=True)  # smoothed and loaded once for every redraw
        self.poses = model.coerce(poses)
        self.lock = threading.RLock()
        self.saved = threading.Event()
        server = scene.server
        self.gizmos = []
        for i, name in enumerate(model.names):
            root = model.parent[i] < 0
            gizmo = server.scene.add_transform_controls(
                f"/gizmos/{name}",
                scale=0.3 if root else 0.12,
                disable_axes=not root,
                disable_sliders=not root,
                depth_test=False,
            )
            gizmo.on_update(lambda _, i=i: self.moved(i))  # type: ignore[misc]  # mypy cannot type the default i=i
            self.gizmos.append(gizmo)
        with server.gui.add_folder("Initial pose", order=0):
            self.snap_button = server.gui.add_button("Snap to the images")
            self.save_button = server.gui.add_button(f"Save {self.out.name}")
            self.message = server.gui.add_markdown("Drag the gizmos onto the person, snap, then save.")
        self.snap_button.on_click(lambda _: self.snap())
        self.save_button.on_click(lambda _: self.save())
        scene.look_at_body(self.poses, distance=2.2)
        self.refresh()

    def moved(self, i: int) -> None:
        """Gizmo ``i`` was dragged: move component i and its subtree rigidly to it, then coerce the joints."""
        with self.lock:
            gizmo = self.gizmos[i]
            target = np.eye(4)
            target[0:3, 0:3] = vtf.SO3(np.asarray(gizmo.wxyz)).as_matrix()
            target[0:3, 3] = gizmo.position if self.model.parent[i] < 0 else self.poses[i, 0:3, 3]
            motion = target @ inverse(self.poses[i])
            poses = self.poses.copy()
            for j in subtree(self.model.parent, i):
                poses[j] = motion @ poses[j]
            self.poses = self.model.coerce(poses)
            self.refresh()

    def snap(self, rounds: int = 3) -> None:
        """Track the frame from the current placement, ``rounds`` times ``snap_iterations`` IRLS iterations
        without a motion model; each round re-centres the prior on where the last one ended."""
        with self.lock:
            result = snap_to_edges(
                self.model,
                self.recording.cameras,
                self.poses,
                images=self.smoothed,
                settings=self.settings,
                rounds=rounds,
                smoothed=True,
            )
            self.poses = result.poses
            self.message.content = (
                f"Snapped: residual {result.residual:.2f} px, {100 * result.share:.0f} % of the samples found an edge."
            )
            self.refresh()

    def save(self) -> None:
        with self.lock:
            save_pose_file(self.out, self.model, self.poses, frame=self.frame)
            self.message.content = f"Saved {self.out}."
            self.saved.set()

    def refresh(self) -> None:
        """Put every gizmo on its component and redraw the body and the edge search at the current poses."""
        for gizmo, pose in zip(self.gizmos, self.poses):
            gizmo.wxyz = vtf.SO3.from_matrix(pose[0:3, 0:3]).wxyz
            gizmo.position = pose[0:3, 3]
        inspection = self.tracker.inspect(poses=self.poses)
        self.scene.show(Frame(self.poses, self.images, inspection, label=f"frame {self.frame}"))
