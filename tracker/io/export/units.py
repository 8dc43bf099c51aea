"""Units and times shared by the marker exports."""

from __future__ import annotations

import numpy as np

MM_PER_M = 1000.0  # TRC and C3D write millimetres


def seconds(frame: np.ndarray, rate: float) -> np.ndarray:
    """Seconds from the first of the frame indices ``frame`` (F,) at ``rate`` frames per second."""
    return (frame - frame[0]) / rate
