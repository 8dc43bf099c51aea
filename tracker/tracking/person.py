"""The person's mask as the region cue reads it: the detector's segmentation of the person (docs/region.md, "The
person's mask").

The landmarker segments the person in each view it finds them in (:class:`tracker.keypoints.detector.Detection`:
an S x S probability over a square of the image).  :func:`person_grid` takes it to the grid of the view's
colour image as the region cue reads it (0 beyond the square), where the region cue joins it to each pixel's colour
(:func:`tracker.tracking.region_cue.with_person`) and learns each part's colours only where it agrees
(:func:`tracker.tracking.region_cue.learn_kernel`).
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.tracking.region_cue import FACTOR


def person_grid(mask: np.ndarray, square: np.ndarray, size: np.ndarray, *, factor: int = FACTOR) -> np.ndarray:
    """The person's probability x 255 (uint8) on the colour grid of ``size`` (width, height) pixels of ``factor``
    full-size ones each (half size unless the region cue reduces the view further,
    :func:`tracker.tracking.region_cue.colour_grids`) from ``mask`` (S, S) uint8 over ``square`` (centre x, centre
    y, side; full-size pixels): bilinear, 0 beyond the square.  A grid pixel ``(u, v)`` is the full-size point
    ``(f u + (f - 1) / 2, f v + (f - 1) / 2)``, and a full-size point ``x`` the mask's ``S / side (x - centre) + S /
    2``."""
    scale = mask.shape[0] / square[2]
    warp = np.array(
        [
            [scale * factor, 0.0, scale * ((factor - 1) / 2.0 - square[0]) + mask.shape[0] / 2.0],
            [0.0, scale * factor, scale * ((factor - 1) / 2.0 - square[1]) + mask.shape[0] / 2.0],
        ]
    )
    return cv2.warpAffine(
        mask,
        warp,
        (int(size[0]), int(size[1])),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
