"""The foreground cue: the edge search run on where a frame differs from the empty scene.

In a cluttered room the strongest grey-level edges near a limb are often the room's own (a
treadmill rail, a shelf, a person in the back), and skin against a light wall gives a weak one.
The cameras do not move, so each one's background ``B_k`` can be known: given as images of the
empty scene, or estimated as the per-pixel median of frames spread through the recording (right
wherever the person is absent from more than half of them; where he stands still all along, he
becomes background and his outline there is lost).  The edge search then looks at

    F_k(x) = min(255, sum_c |I_c(x) - B_k,c(x)|)      (c over the three colour channels)

whose edges are the person's silhouette: static clutter cancels, and colour tells skin from a
wall of the same grey.  Edges inside the silhouette (an arm across the chest) vanish, which the
IRLS weights and edge ownership already expect of any occluding contour.

A person who stays in one place (balancing, sitting) is in most of the frames a median is taken
over, and the median keeps him.  :func:`cleared_background` takes the median again with a
tracked run's body masked out of each frame: the model's silhouette, rendered from the tracked
poses and widened by a margin, marks the pixels where a frame shows him and not the scene.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import closing
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from tracker.atomic import atomic_path, ensure_writable_folder
from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.io.readers import FrameSeeker, read_image
from tracker.io.recording import Recording
from tracker.model import Model
from tracker.raycast import RayCaster
from tracker.tracking.settings import Settings

SAMPLES = 25  # frames per camera for the median background
CLEARED_SAMPLES = 50  # frames per camera for the median with the tracked body masked out
MARGIN = 12  # pixels (at the tracker's reference short side, 480) the tracked silhouette is widened by: loose fit, blur
COVERAGE = 0.3  # share of the samples the body must cover before a pixel's plain median is replaced
MINIMUM_FREE = 3  # samples free of the body a replaced pixel needs
MASK_SIDE = 272  # short side, pixels, the silhouettes are rendered at before being scaled up
CHUNK = 65536  # pixels whose masked median is taken at once (bounds the float copy of the stack)
_SUM = np.ones((1, 3), np.float32)  # cv2.transform: the channel sum, saturated to uint8


@dataclass(frozen=True)
class Background:
    """One BGR uint8 image (H, W, 3) of the empty scene per camera (rig order)."""

    images: tuple[np.ndarray, ...]

    def difference(self, camera: int, image: np.ndarray) -> np.ndarray:
        """F = min(255, sum_c |I_c - B_c|) of a BGR frame of camera ``camera``, uint8 (H, W)."""
        return cv2.transform(cv2.absdiff(image, self.images[camera]), _SUM)


def sample_indices(frame_count: int, samples: int = SAMPLES) -> np.ndarray:
    """``samples`` frame indices spread evenly over the recording (all of them when it is shorter)."""
    return np.unique(np.linspace(0, frame_count - 1, min(frame_count, samples)).round().astype(int))


def camera_stacks(
    recording: Recording, indices: Iterable[int], progress: Callable[[Iterable], Iterable] = iter
) -> Iterator[np.ndarray]:
    """Per camera (rig order) the BGR frames ``indices`` stacked (len(indices), H, W, 3), one camera's
    frames held at a time; ``progress`` wraps the list of (camera, frame) reads (e.g. a tqdm bar)."""
    indices = [int(index) for index in indices]
    reads = [(camera, index) for camera in range(len(recording.sources)) for index in indices]
    reading = iter(progress(reads))
    for source in recording.sources:
        with closing(FrameSeeker(source, colour=True)) as seeker:
            yield np.stack([seeker.read(index) for _, index in itertools.islice(reading, len(indices))])


def median_background(
    recording: Recording, samples: int = SAMPLES, progress: Callable[[Iterable], Iterable] = iter
) -> Background:
    """Per camera, the per-pixel median of ``samples`` frames spread over the recording; ``progress``
    wraps the list of (camera, frame) reads (e.g. a tqdm bar).  One camera's frames are held at a time."""
    stacks = camera_stacks(recording, sample_indices(recording.frame_count, samples), progress)
    return Background(tuple(np.median(stack, axis=0).round().astype(np.uint8) for stack in stacks))


def background_file(folder: Path, camera: str) -> Path:
    return folder / f"{camera}.png"


def load_background(folder: str | os.PathLike, recording: Recording) -> Background:
    """``<camera>.png`` of each camera of the recording from ``folder``, checked against its image size."""
    folder = Path(folder)
    if not folder.is_dir():
        raise TrackerInputError(
            f"{folder}: background folder not found; give a folder of <camera>.png images of "
            "the empty scene, or --background median"
        )
    images = []
    for camera in recording.cameras:
        file = background_file(folder, camera.name)
        if not file.is_file():
            raise TrackerInputError(
                f"{file}: no background image for camera {camera.name}; add it (an image of "
                "the empty scene from that camera), or use --background median"
            )
        image = read_image(file, 0)
        if image.shape[1::-1] != tuple(camera.size):
            raise TrackerInputError(
                f"{file}: background is {image.shape[1]}x{image.shape[0]} but camera "
                f"{camera.name} gives {camera.size[0]}x{camera.size[1]} frames; "
                "take it with the same camera and size"
            )
        images.append(image)
    return Background(tuple(images))


def save_background(background: Background, recording: Recording, folder: str | os.PathLike) -> Path:
    """Write ``<camera>.png`` per camera into ``folder`` (each atomically), for reuse with --background."""
    folder = ensure_writable_folder(folder)
    for camera, image in zip(recording.cameras, background.images):
        with atomic_path(background_file(folder, camera.name)) as temp:
            if not cv2.imwrite(str(temp), image, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
                raise TrackerInputError(f"{temp}: could not write the background image; check the disk")
    return folder


def preparers(
    background: Background, smooth: Callable[[np.ndarray], np.ndarray]
) -> list[Callable[[np.ndarray], np.ndarray]]:
    """Per camera, what its reader thread makes of a BGR frame for the edge search: ``smooth(F_k)``."""

    def prepare(camera: int, frame: np.ndarray) -> np.ndarray:
        return smooth(background.difference(camera, frame))

    return [partial(prepare, camera) for camera in range(len(background.images))]


@dataclass(frozen=True)
class Cleared:
    """A background estimated with the tracked body masked out, and per camera how much it changed:
    ``replaced`` the share of pixels whose plain median was replaced (the body covered at least
    :data:`COVERAGE` of the samples there), ``hidden`` the share the body covered in almost every
    sample (fewer than :data:`MINIMUM_FREE` free), which keep the plain median."""

    background: Background
    frames: np.ndarray
    replaced: tuple[float, ...]
    hidden: tuple[float, ...]


def reduced_camera(camera: Camera, factor: float) -> Camera:
    """The camera imaging the same rays onto pixels ``factor`` times larger (pixel centres kept:
    u' = (u + 1/2) / factor - 1/2), its size rounded up."""
    matrix = np.array(camera.matrix)
    matrix[0:2, 0:2] /= factor
    matrix[0:2, 2] = (matrix[0:2, 2] + 0.5) / factor - 0.5
    size = (int(np.ceil(camera.size[0] / factor)), int(np.ceil(camera.size[1] / factor)))
    return dataclasses.replace(camera, matrix=matrix, size=size)


def silhouettes(
    caster: RayCaster, size: tuple[int, int], *, factor: float, margin: int
) -> Callable[[np.ndarray], np.ndarray]:
    """The function from poses to the pixels (H, W) bool of a ``size`` = (W, H) image that the body
    covers, widened by a disc of radius ``margin`` pixels: ray cast by a caster of the camera reduced
    by ``factor`` (:func:`reduced_camera`), each pixel u taking the reduced pixel nearest
    (u + 1/2) / factor - 1/2."""
    width, height = caster.camera.size
    cols = np.clip(np.rint((np.arange(size[0]) + 0.5) / factor - 0.5), 0, width - 1).astype(int)
    rows = np.clip(np.rint((np.arange(size[1]) + 0.5) / factor - 0.5), 0, height - 1).astype(int)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))

    def silhouette(poses: np.ndarray) -> np.ndarray:
        mask = (caster.cast(poses)[0] >= 0).astype(np.uint8)[rows[:, None], cols[None, :]]
        return cv2.dilate(mask, disc).astype(bool)

    return silhouette


def cleared_background(
    recording: Recording,
    model: Model,
    *,
    frames: np.ndarray,
    poses: np.ndarray,
    samples: int = CLEARED_SAMPLES,
    margin: float = MARGIN,
    progress: Callable[[Iterable], Iterable] = iter,
) -> Cleared:
    """The empty scene from a recording and a track of the person in it.

    ``frames`` (F,) are recording frame indices and ``poses`` (F, N, 4, 4) the model's tracked poses
    there (lost frames left out by the caller).  Per camera, from ``samples`` of those frames spread
    evenly, with S(x) the samples whose widened silhouette misses pixel x,

        B(x) = median over S(x) of I_s(x)    where the body covers >= COVERAGE of the samples at x
                                             and |S(x)| >= MINIMUM_FREE,
        B(x) = median over all samples       elsewhere (the plain median, right where he is absent
                                             from most samples; a poor track there cannot spoil it).

    ``margin`` is in pixels at the tracker's reference short side (``Settings().images.reference_size``) and grows
    with the image like the tracker's pixel settings.  ``progress`` wraps the list of (camera, frame) reads.
    """
    chosen = sample_indices(len(frames), samples)
    sampled = np.asarray(frames)[chosen]
    images, replaced, hidden = [], [], []
    for camera, stack in zip(recording.cameras, camera_stacks(recording, sampled, progress)):
        short = min(camera.size)
        factor = max(1.0, short / MASK_SIDE)
        silhouette = silhouettes(
            RayCaster(model, reduced_camera(camera, factor)),
            camera.size,
            factor=factor,
            margin=round(margin * max(1.0, short / Settings().images.reference_size)),
        )
        masks = np.stack([silhouette(poses[i]) for i in chosen])
        covered = masks.sum(axis=0)
        free = len(chosen) - covered
        image = np.median(stack, axis=0)
        swap = (covered >= COVERAGE * len(chosen)) & (free >= MINIMUM_FREE)
        rows, cols = np.nonzero(swap)
        for part in range(0, len(rows), CHUNK):
            r, c = rows[part : part + CHUNK], cols[part : part + CHUNK]
            values = stack[:, r, c].astype(np.float32)
            values[masks[:, r, c]] = np.nan
            image[r, c] = np.nanmedian(values, axis=0)
        images.append(image.round().astype(np.uint8))
        replaced.append(float(swap.mean()))
        hidden.append(float((free < MINIMUM_FREE).mean()))
    return Cleared(Background(tuple(images)), sampled, tuple(replaced), tuple(hidden))
