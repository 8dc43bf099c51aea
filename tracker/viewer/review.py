"""Reviewing a poses file in the viewer: a timeline over the recording's frames.

The timeline slider, play/pause, single steps and the playback speed pick a row of
``poses.npz``; the scene then shows that frame's poses and truth, and each camera's
image with the edge search redone at those poses by the run's tracker
(:meth:`tracker.tracking.frame_loop.Tracker.inspect`, a query that leaves it as it was), so what the panels show is what
the tracker saw.  Plots give each frame's status,
residual and, for files that record it, the tracker's speed.  Playback keeps to real
time (times the speed) by skipping frames when drawing is slower than the video.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from tracker.io.readers import FrameSeeker
from tracker.io.recording import Recording, camera_frames
from tracker.status import NAMES
from tracker.tracking.foreground import Background
from tracker.tracking.frame_loop import Tracker
from tracker.viewer.scene import Frame, Scene, add_run_plots
from tracker.viewer.timeline import Timeline

SPEEDS = ("0.25x", "0.5x", "1x", "2x", "4x")


def truth_rows(truth: dict | None, frames: np.ndarray) -> np.ndarray | None:
    """Truth joints (F, J, 3) for the given recording frames, NaN where the truth has no such frame."""
    if truth is None:
        return None
    joints = truth["joints"]
    row = {int(f): k for k, f in enumerate(truth["frame"])}
    out = np.full((len(frames),) + joints.shape[1:], np.nan)
    for k, f in enumerate(frames):
        if int(f) in row:
            out[k] = joints[row[int(f)]]
    return out


class Review(Timeline):
    """Timeline controls and plots for one poses file over its recording."""

    def __init__(
        self,
        scene: Scene,
        recording: Recording,
        tracker: Tracker,
        results: dict,
        truth: dict | None = None,
        background: Background | None = None,
    ):
        """``tracker``: one for the recording's cameras with the run's settings, which redoes each row's edge
        search (:meth:`~tracker.tracking.frame_loop.Tracker.inspect`, which never moves it); ``background``: the run's
        empty scene (``tracker track --background``), so the panels show and search the same difference images the
        tracker did; None: grey images."""
        super().__init__(scene.server, len(results["frame"]), recording.fps)
        self.scene, self.recording, self.results = scene, recording, results
        self.frames = results["frame"]
        self.truth = truth_rows(truth, self.frames)
        self.background = background
        self.seekers = [FrameSeeker(source, colour=background is not None) for source in recording.sources]
        self.tracker = tracker
        self.stopping = threading.Event()
        gui = scene.server.gui
        with gui.add_folder("Timeline", order=0):
            self.add_slider(gui)
            self.play = gui.add_checkbox("play", initial_value=False)
            self.previous = gui.add_button("previous frame")
            self.next = gui.add_button("next frame")
            self.speed = gui.add_dropdown("speed", SPEEDS, initial_value="1x")
        self.previous.on_click(lambda _: self.step(-1))
        self.next.on_click(lambda _: self.step(1))
        self._plots(gui)
        scene.look_at_body(results["poses"][0])
        scene.show_trajectory(results["poses"][:, 0, 0:3, 3])
        self.player = threading.Thread(target=self._play, name="viewer playback", daemon=True)
        self.player.start()

    def _plots(self, gui) -> None:
        unknown = np.full(len(self.frames), np.nan)
        results = self.results
        with gui.add_folder("Plots", order=20, expand_by_default=False):
            add_run_plots(
                gui,
                frames=self.frames,
                status=results.get("status", unknown),
                residual=results.get("residual", unknown),
                elapsed=results.get("elapsed", unknown),
            )

    def step(self, delta: int) -> None:
        self.play.value = False  # type: ignore[misc]  # viser's setter, which mypy does not see
        self.show(int(np.clip(self.row + delta, 0, self.count - 1)))

    def draw(self, row: int) -> None:
        """Draw row ``row`` of the poses file: its poses, truth and camera images with the edge search redone."""
        index = int(self.frames[row])
        images = [seeker.read(frame) for seeker, frame in zip(self.seekers, camera_frames(self.recording, index))]
        if self.background is not None:
            images = [self.background.difference(k, image) for k, image in enumerate(images)]
        poses = self.results["poses"][row]
        inspection = self.tracker.inspect(images, poses=poses)
        label = f"frame {index}"  # a poses file without a status or residual (a truth.npz) is shown with neither
        if "status" in self.results:
            label += f": {NAMES[int(self.results['status'][row])]}"
        if "residual" in self.results:
            label += f", residual {self.results['residual'][row]:.2f} px"
        truth = None if self.truth is None else self.truth[row]
        held = self.results["held"][row] if "held" in self.results else None  # runs before it have none
        self.scene.show(Frame(poses, images, inspection, truth, label, held))

    def _play(self) -> None:
        """While ``play`` is ticked, advance in real time times the speed, skipping frames drawing cannot keep up
        with; the clock restarts from the shown row when the speed changes or someone else moved the timeline."""
        clock, played = None, None
        while not self.stopping.is_set():
            if not self.play.value:
                clock = None
                self.stopping.wait(0.05)
                continue
            rate = self.rate * float(self.speed.value.rstrip("x"))
            if clock is None or clock[2] != rate or self.row != played:
                clock = (time.monotonic(), max(self.row, 0), rate)
            started, first, _ = clock
            row = min(first + int((time.monotonic() - started) * rate), self.count - 1)
            self.show(row)
            if row == self.count - 1:  # playback ends on the last frame, even when it skips to it
                self.play.value = False  # type: ignore[misc]  # viser's setter, which mypy does not see
                continue
            played = row
            self.stopping.wait(max(0.0, started + (row + 1 - first) / rate - time.monotonic()))

    def close(self) -> None:
        self.stopping.set()
        self.player.join()
        for seeker in self.seekers:
            seeker.close()
