"""Showing a run while it tracks, without slowing it down.

The tracking loop hands each finished frame to :meth:`LiveView.offer`, which only
keeps a reference to the newest one (a lock and an assignment: the tracker never
waits for the browser).  A thread of the viewer wakes at most ``rate`` times a
second, takes the newest frame, redoes its edge search at the tracked poses for
the panels (:meth:`~tracker.tracking.frame_loop.Tracker.inspect` of the run's tracker, a query in buffers of
its own that may run beside the tracker's steps; the numba kernels release the GIL) and sends the whole
update as one batch; frames that arrive in between are
skipped, not queued.  Plots of status, residual and speed are refreshed twice a
second over the last ``history`` frames, the camera images and their edge searches ten
times a second (encoding, sending and decoding images is most of a viewer's cost).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

from tracker.tracking.frame_loop import FrameResult, Tracker
from tracker.viewer.scene import Frame, Scene, add_run_plots, run_plot_values, write_viser

PLOT_PERIOD = 0.5  # seconds between plot refreshes
IMAGE_PERIOD = 0.1  # seconds between camera image refreshes (the body moves at the full rate)


class LiveView:
    """Throttled, non-blocking display of a running tracker; optionally recorded as a .viser file.

    ``truth``: truth joint centres by frame index (F, J, 3), NaN where unknown
    (:func:`~tracker.viewer.review.truth_rows`).
    """

    def __init__(
        self,
        scene: Scene,
        tracker: Tracker,
        *,
        rate: float = 30.0,
        truth: np.ndarray | None = None,
        record: Path | None = None,
        history: int = 600,
    ):
        """``tracker``: the run's, at its first pose; its :meth:`~tracker.tracking.frame_loop.Tracker.inspect` redoes
        the edge search of the frames offered, in every camera of its rig (a camera that stopped gets a blank
        image)."""
        self.scene, self.tracker, self.rate, self.truth_joints, self.record_path = scene, tracker, rate, truth, record
        self.serializer = scene.server.get_scene_serializer() if record is not None else None
        self.latest: tuple[int, list[np.ndarray], FrameResult] | None = None
        self.lock = threading.Lock()
        self.arrived = threading.Event()
        self.stopping = threading.Event()
        self.shown = 0
        self.history: dict[str, deque[float]] = {
            key: deque(maxlen=history) for key in ("frame", "status", "residual", "elapsed")
        }
        self.trajectory: deque[np.ndarray] = deque(maxlen=history)
        gui = scene.server.gui
        with gui.add_folder("Live", order=20):
            self.plots = add_run_plots(
                gui, frames=np.zeros(2), status=np.zeros(2), residual=np.zeros(2), elapsed=np.zeros(2)
            )
        scene.look_at_body(tracker.poses)
        self.thread = threading.Thread(target=self._run, name="viewer live", daemon=True)
        self.thread.start()

    def offer(self, index: int, images: list[np.ndarray], result: FrameResult, *, elapsed: float) -> None:
        """Hand over a tracked frame (``images`` smoothed grey, as the tracker got them); never blocks."""
        with self.lock:
            self.latest = (index, images, result)
            self.history["frame"].append(float(index))
            self.history["status"].append(float(result.status))
            self.history["residual"].append(result.residual)
            self.history["elapsed"].append(elapsed)
            self.trajectory.append(result.poses[0, 0:3, 3])
        self.arrived.set()

    def _run(self) -> None:
        last_push = last_plot = last_image = 0.0
        while not self.stopping.is_set():
            self.arrived.wait(0.1)
            wait = last_push + 1.0 / self.rate - time.monotonic()
            if wait > 0:
                self.stopping.wait(wait)
            with self.lock:
                latest, self.latest = self.latest, None
                self.arrived.clear()
            if latest is None:
                continue
            with_images = time.monotonic() - last_image >= IMAGE_PERIOD
            self._show(*latest, with_images=with_images)
            last_push = time.monotonic()
            if with_images:
                last_image = last_push
            if self.serializer is not None:
                self.serializer.insert_sleep(1.0 / self.rate)
            if last_push - last_plot > PLOT_PERIOD:
                self._plot()
                last_plot = last_push

    def _show(self, index: int, images: list[np.ndarray], result: FrameResult, with_images: bool = True) -> None:
        inspection = None
        if with_images:
            inspection = self.tracker.inspect(images, smoothed=True, poses=result.poses)
        truth = None
        if self.truth_joints is not None and 0 <= index < len(self.truth_joints):
            truth = self.truth_joints[index]
        label = f"frame {index}: residual {result.residual:.2f} px, {100 * result.share:.0f} % of samples found an edge"
        self.scene.show(Frame(result.poses, images if with_images else None, inspection, truth, label, result.held))
        self.shown += 1

    def _plot(self) -> None:
        with self.lock:
            columns = {key: np.array(values) for key, values in self.history.items()}
            trajectory = np.array(self.trajectory)
        if len(columns["frame"]) < 2:
            return
        values = run_plot_values(columns["status"], columns["residual"], columns["elapsed"])
        for key, plot in self.plots.items():
            plot.data = (columns["frame"], values[key])
        self.scene.show_trajectory(trajectory)

    def close(self) -> None:
        """Show the last frame, stop the thread and write the recording if one was asked for."""
        self.stopping.set()
        self.thread.join()
        with self.lock:
            latest, self.latest = self.latest, None
        if latest is not None:
            self._show(*latest)
        self._plot()
        if self.serializer is not None:
            write_viser(self.serializer, self.record_path)
