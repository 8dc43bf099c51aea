"""The person's mask as the region cue reads it: the detector's segmentation of the person (docs/region.md, "The
person's mask").

The landmarker segments the person in each view it finds them in (:class:`tracker.landmarks.detector.Detection`:
an S x S probability over a square of the image).  :func:`person_grid` takes it to the grid of the view's
colour image as the region cue reads it (0 beyond the square), where the region cue joins it to each pixel's colour
(:func:`tracker.tracking.region_lines.with_person`) and learns each part's colours only where it agrees
(:func:`tracker.tracking.region_lines.learn_kernel`).
"""

from __future__ import annotations

import cv2
import numpy as np

from tracker.landmarks.body_landmarks import cue_points
from tracker.landmarks.guessed import axis_points, hidden_parts, leg_landmarks
from tracker.model import Model
from tracker.tracking.colours import FACTOR
from tracker.tracking.settings import Settings


def person_grid(mask: np.ndarray, square: np.ndarray, size: np.ndarray, *, factor: int = FACTOR) -> np.ndarray:
    """The person's probability x 255 (uint8) on the colour grid of ``size`` (width, height) pixels of ``factor``
    full-size ones each (half size unless the region cue reduces the view further,
    :func:`tracker.tracking.colours.colour_grids`) from ``mask`` (S, S) uint8 over ``square`` (centre x, centre
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


BONE_POINTS = (0.25, 0.5, 0.75)  # where along each bone PersonMasks.on_person reads the mask


class PersonMasks:
    """Each view's mask of the person for the frame in hand, on the grid of its colour image as the region cue reads
    it (:func:`tracker.tracking.colours.colour_grids`): ``mask`` (C, H', W') uint8, how far the region cue trusts
    it, ``trust`` (C,) (0 where a view has none), where it lies, ``square`` (C, 3), and the legs it says a view hides,
    ``off_mask`` (C, N) bool (:meth:`see`)."""

    def __init__(self, model: Model, cameras, grid: np.ndarray, settings: Settings):
        self.model, self.cameras, self.grid = model, list(cameras), grid
        self.settings = settings
        height, width = int(grid[:, 1].max()), int(grid[:, 0].max())
        self.mask = np.zeros((len(self.cameras), height, width), np.uint8)
        self.trust = np.zeros(len(self.cameras))
        self.square = np.full((len(self.cameras), 3), np.nan)
        self.off_mask = np.zeros((len(self.cameras), model.size), bool)
        component, _ = cue_points(model)
        self.legs = hidden_parts(model, component, leg_landmarks())  # the parts a guessed leg hides
        self.axis = axis_points(model)  # three points along each quadric (shares)

    def see(self, masks: tuple[np.ndarray, np.ndarray] | None, poses: np.ndarray) -> None:
        """Take each camera's person mask for the frame to track, ``masks``: (C, S, S) uint8 over squares (C, 3:
        centre x, y and side, full-size pixels; NaN for a camera without one) (:func:`person_grid`), or None: none in
        any camera.

        With ``hide_guessed``, a leg part (a thigh and every part below it) that lies off the mask of a view at
        ``poses`` (under half of its axis points on it, of those within the image and the mask's square), where some
        other part lies on it, while another view's mask has it on, is hidden in that view until the view's next
        mask: a table before that camera, whose edges would hold it (docs/keypoints.md, "Legs hidden from one
        view").  Off every view's mask, a leg has strayed rather than hidden, and its edges may bring it back."""
        self.trust[:] = 0.0
        if masks is None:
            return
        for k, (view, placed) in enumerate(zip(*masks)):
            if np.isfinite(placed).all() and placed[2] > 0:
                self.trust[k] = self.settings.region.person
                w, h, f = self.grid[k, :3]
                self.mask[k, :h, :w] = person_grid(view, placed, self.grid[k, :2], factor=f)
                self.square[k] = placed
        masked = self.masked()
        if not self.settings.keypoints.hide_guessed or not masked:
            return
        shares = np.array([self.shares(camera, poses) for camera in masked])
        on = shares >= 0.5
        body = np.asarray(on[:, ~self.legs].any(axis=1))
        for row, camera in enumerate(masked):
            others = np.delete(on, row, axis=0)
            self.off_mask[camera] = self.legs & (shares[row] < 0.5) & body[row] & others.any(axis=0)

    def masked(self) -> list[int]:
        """The views with a mask in the frame in hand."""
        return np.flatnonzero(self.trust > 0).tolist()

    def shares(self, camera: int, poses: np.ndarray) -> np.ndarray:
        """Each component's share (N,) of its axis points (:func:`tracker.landmarks.guessed.axis_points`) at ``poses``
        that lie on the mask of view ``camera``, over those within the image and the mask's square; NaN where none
        is."""
        component, points = self.axis
        world = np.einsum("kij,kj->ki", poses[component, :3, :3], points) + poses[component, :3, 3]
        inside, on = self.on_mask(camera, world)
        pixels = self.cameras[camera].project(world)
        centre_x, centre_y, side = self.square[camera]
        with np.errstate(invalid="ignore"):
            inside &= (np.abs(pixels[:, 0] - centre_x) <= side / 2) & (np.abs(pixels[:, 1] - centre_y) <= side / 2)
        on &= inside
        count = np.bincount(component, weights=inside, minlength=self.model.size)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.bincount(component, weights=on, minlength=self.model.size) / count

    def on_person(self, poses: np.ndarray) -> float:
        """How much of the body at ``poses`` (N, 4, 4) lies on the frame's masks: the share of the points a quarter, a
        half and three quarters along every bone (a joint to its child's) that fall where the mask says the person,
        averaged over the cameras with a mask; 0 where none has one.  Outlines find edges on clutter, while the mask
        is read from the person alone (docs/keypoints.md, "Re-seeds judged by the person's mask")."""
        child = np.flatnonzero(self.model.parent >= 0)
        joints = poses[:, :3, 3]
        ends = joints[self.model.parent[child]], joints[child]
        points = np.concatenate([(1.0 - s) * ends[0] + s * ends[1] for s in BONE_POINTS])
        shares = [self.on_mask(k, points)[1].sum() / len(points) for k in self.masked()]
        return float(np.mean(shares)) if shares else 0.0

    def on_mask(self, camera: int, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Which of the points ``world`` (P, 3) project within view ``camera``'s colour grid, and which lie on its
        mask there (two (P,) bool)."""
        w, h, f = self.grid[camera, :3]
        grid = np.rint((self.cameras[camera].project(world) - (f - 1) / 2.0) / f)
        inside = np.isfinite(grid).all(axis=1) & (grid >= 0).all(axis=1) & (grid[:, 0] < w) & (grid[:, 1] < h)
        on = np.zeros(len(world), bool)
        u, v = grid[inside].astype(np.int64).T
        on[inside] = self.mask[camera, v, u] >= 128
        return inside, on
