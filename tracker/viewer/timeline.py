"""Frame selection over a finished run, shared by the viewers that step through one (:mod:`.review`,
:mod:`.marker_view`): a frame slider, a thread-safe ``show`` that draws one row at a time, and ``record``,
which writes every row as a .viser file.  What a row looks like is each viewer's own ``draw``."""

from __future__ import annotations

import threading
from pathlib import Path

import viser
from tqdm import tqdm

from tracker.viewer.scene import write_viser


class Timeline:
    """``count`` rows of a run on ``server``, shown one at a time, ``rate`` rows a second when recorded.

    A subclass draws row ``row`` in :meth:`draw` and places the frame slider with :meth:`add_slider`
    where its controls go.
    """

    slider: viser.GuiSliderHandle[int]

    def __init__(self, server: viser.ViserServer, count: int, rate: float):
        self.server, self.count, self.rate = server, count, rate
        self.lock = threading.RLock()  # browsers move the slider from viser's threads
        self.row = -1

    def add_slider(self, gui) -> None:
        """The frame slider over the rows; moving it shows its row."""
        self.slider = gui.add_slider("frame", min=0, max=max(self.count - 1, 1), step=1, initial_value=0)
        self.slider.on_update(lambda _: self.show(int(self.slider.value)))

    def draw(self, row: int) -> None:
        """Draw row ``row`` (called with the lock held, for a row not already shown)."""
        raise NotImplementedError

    def show(self, row: int) -> None:
        """Draw row ``row``, clamped to the rows (thread-safe; a row already shown is not redrawn)."""
        row = min(max(int(row), 0), self.count - 1)
        with self.lock:
            if row == self.row:
                return
            self.draw(row)
            self.row = row
            # viser's setter calls the slider's callback at once: its show() finds the row shown and returns
            self.slider.value = row  # type: ignore[misc]  # viser's setter, which mypy does not see

    def record(self, path: Path, progress: bool = True) -> None:
        """Write every row, ``rate`` a second, as a .viser file that viser's static client plays back."""
        serializer = self.server.get_scene_serializer()
        for row in tqdm(range(self.count), unit="frame", desc="recording the viewer", disable=not progress):
            self.show(row)
            serializer.insert_sleep(1.0 / self.rate)
        write_viser(serializer, path)
