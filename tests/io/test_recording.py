"""Recording folders: opening, validation and frame reading on tiny MJPG videos."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import SHARED_DATA, needs_shared

from tracker.camera import Camera, load_calibration, save_calibration
from tracker.errors import TrackerInputError
from tracker.io.recording import frames, open_recording

WIDTH, HEIGHT, COUNT, FPS = 64, 48, 10, 25.0


def content(camera: int, index: int) -> np.ndarray:
    """A grey test image: a flat level per frame and camera, with a bright square that moves."""
    image = np.full((HEIGHT, WIDTH), 20 + 15 * index + 5 * camera, np.uint8)
    image[10:26, 4 + 3 * index : 20 + 3 * index] = 240
    return image


def write_video(path: Path, camera: int, count: int = COUNT, size: tuple[int, int] = (WIDTH, HEIGHT)) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, size)
    assert writer.isOpened()
    for index in range(count):
        writer.write(cv2.cvtColor(cv2.resize(content(camera, index), size), cv2.COLOR_GRAY2BGR))
    writer.release()


def make_recording(
    folder: Path, videos: tuple[str, ...] = ("cam0", "cam1"), size: tuple[int, int] = (WIDTH, HEIGHT)
) -> Path:
    """A recording whose calibration has cam0, cam1, cam2 (all ``size``) and MJPG videos for ``videos``."""
    folder.mkdir()
    K = np.array([[50.0, 0.0, 32.0], [0.0, 50.0, 24.0], [0.0, 0.0, 1.0]])
    cameras = [Camera(f"cam{i}", size, K, np.zeros(4), np.eye(3), np.array([i, 0.0, 3.0])) for i in range(3)]
    save_calibration(cameras, folder / "calibration.toml")
    for name in videos:
        write_video(folder / f"{name}.avi", int(name[-1]))
    return folder


def test_happy_path_yields_grey_frames(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    (folder / "model.toml").write_text('name = "x"\n')
    with pytest.warns(UserWarning) as caught:
        recording = open_recording(folder)
    assert [c.name for c in recording.cameras] == ["cam0", "cam1"]  # cam2 has no video: a warning names it
    assert [str(warning.message) for warning in caught] == [
        f"{folder}: camera cam2 has no video, leaving cam0, cam1 of calibration.toml; add <name>.mp4|.avi|.mkv or a "
        "folder <name>/ of numbered images, or pick the cameras with --cameras to say so"
    ]
    assert (recording.frame_count, recording.fps) == (COUNT, FPS)
    assert (
        recording.model_path == folder / "model.toml" and recording.init_path is None and recording.truth_path is None
    )
    seen = []
    for index, images in frames(recording):
        seen.append(index)
        assert len(images) == 2
        for camera, image in enumerate(images):
            assert image.dtype == np.uint8 and image.shape == (HEIGHT, WIDTH)
            assert np.abs(image.astype(float) - content(camera, index)).mean() < 4.0  # MJPG is lossy
    assert seen == list(range(COUNT))


def test_frame_range_and_camera_choice(tmp_path: Path) -> None:
    recording = open_recording(make_recording(tmp_path / "rec"), cameras=["cam1"])
    assert [c.name for c in recording.cameras] == ["cam1"]
    got = list(frames(recording, start=6, stop=8))
    assert [index for index, _ in got] == [6, 7]
    assert np.abs(got[0][1][0].astype(float) - content(1, 6)).mean() < 4.0
    with pytest.raises(TrackerInputError, match="outside"):
        frames(recording, start=5, stop=11)


def test_every_step_th_frame_decodes_as_reading_them_all(tmp_path: Path) -> None:
    """``step`` skips frames (undecoded) in videos and image folders; the frames it gives are the same."""
    folder = make_recording(tmp_path / "rec", videos=("cam0",))
    (folder / "cam1").mkdir()
    for index in range(COUNT):
        cv2.imwrite(str(folder / "cam1" / f"{index:06d}.png"), content(1, index))
    recording = open_recording(folder)
    every = dict(frames(recording, 1, 9))
    stepped = list(frames(recording, 1, 9, step=3, colour=False))
    assert [index for index, _ in stepped] == [1, 4, 7]
    for index, images in stepped:
        for image, same in zip(images, every[index]):
            np.testing.assert_array_equal(image, same)


def test_image_folder_source(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec", videos=())
    (folder / "cam2").mkdir()
    for index in range(4):
        cv2.imwrite(str(folder / "cam2" / f"{index:06d}.png"), content(2, index))
    recording = open_recording(folder)
    assert [c.name for c in recording.cameras] == ["cam2"] and recording.frame_count == 4
    for index, (image,) in frames(recording):
        np.testing.assert_array_equal(image, content(2, index))


def expect_error(folder: Path, *fragments: str, cameras: list[str] | None = None) -> str:
    with pytest.raises(TrackerInputError) as error:
        open_recording(folder, cameras=cameras)
    message = str(error.value)
    for fragment in fragments:
        assert fragment in message
    assert "\n" not in message
    return message


def test_missing_folder(tmp_path: Path) -> None:
    expect_error(tmp_path / "nope", "nope")


def test_missing_calibration(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    (folder / "calibration.toml").unlink()
    expect_error(folder, "calibration.toml")


def test_missing_video(tmp_path: Path) -> None:
    expect_error(make_recording(tmp_path / "rec", videos=()), "rec", "no camera", "cam0")
    expect_error(make_recording(tmp_path / "rec2"), "cam2", "cam0, cam1", cameras=["cam2"])


def test_every_camera_with_a_video_is_used_and_those_without_are_named(tmp_path: Path) -> None:
    """Picked by name (each with a video), there is no warning; by default two cameras without a video are named in
    one warning."""
    folder = make_recording(tmp_path / "rec", videos=("cam1",))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [camera.name for camera in open_recording(folder, cameras=["cam1"]).cameras] == ["cam1"]
    with pytest.warns(UserWarning, match="^.*: cameras cam0, cam2 have no video, leaving cam1 of calibration.toml; "):
        assert [camera.name for camera in open_recording(folder).cameras] == ["cam1"]


def test_an_empty_camera_list_is_an_error(tmp_path: Path) -> None:
    message = expect_error(make_recording(tmp_path / "rec"), cameras=[])
    assert message == (
        f"{tmp_path / 'rec'}: the list of cameras names none; pick cameras with a video from: cam0, cam1, or leave "
        "--cameras out to track them all"
    )


def test_unknown_camera_name(tmp_path: Path) -> None:
    expect_error(make_recording(tmp_path / "rec"), "calibration.toml", "'cam7'", "cam0, cam1", cameras=["cam7"])


def test_different_frame_counts(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    write_video(folder / "cam1.avi", 1, count=8)
    expect_error(folder, "cam0.avi", "cam1.avi", "10", "8")


def test_corrupt_video(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    (folder / "cam0.avi").write_bytes(np.random.default_rng(0).bytes(5000))
    expect_error(folder, "cam0.avi", "corrupt or unsupported video")


def test_size_mismatch(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec", size=(80, 60))
    expect_error(folder, "cam0.avi", "64x48", "80x60")


def test_codec_crop_keeps_the_intrinsics_and_takes_the_decoded_size(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    write_video(folder / "cam0.avi", 0, size=(WIDTH, HEIGHT - 8))  # 8 padding rows cropped by the container
    with pytest.warns(UserWarning, match="codec padding"):
        rec = open_recording(folder)
    assert rec.cameras[0].size == (WIDTH, HEIGHT - 8) and rec.cameras[1].size == (WIDTH, HEIGHT)
    calibrated = load_calibration(folder / "calibration.toml")[0]
    np.testing.assert_array_equal(rec.cameras[0].matrix, calibrated.matrix)


@needs_shared("pose2sim-balancing")
def test_real_videos_one_row_block_short_of_their_calibration() -> None:
    """pose2sim-balancing: cam01 and cam02 decode as 1080x1920 where the calibration says 1088x1920."""
    folder = SHARED_DATA / "pose2sim-balancing"
    with pytest.warns(UserWarning) as caught:
        rec = open_recording(folder)
    assert sorted(str(w.message).split(":")[0].rsplit("/", 1)[1] for w in caught) == ["cam01.mp4", "cam02.mp4"]
    assert [c.size for c in rec.cameras] == [(1080, 1920), (1080, 1920), (1088, 1920), (1088, 1920)]
    assert rec.frame_count == 100 and rec.fps == 60.0


def test_two_sources_for_one_camera(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    write_video(folder / "cam0.mkv", 0)
    expect_error(folder, "cam0.avi", "cam0.mkv")


def test_truncated_video_fails_mid_run_naming_file_and_frame(tmp_path: Path) -> None:
    folder = make_recording(tmp_path / "rec")
    video = folder / "cam1.avi"
    video.write_bytes(video.read_bytes()[: video.stat().st_size * 4 // 5])  # the last frames are cut
    recording = open_recording(folder)
    with pytest.raises(TrackerInputError, match=r"cam1\.avi: frame \d+ failed to decode"):
        for _ in frames(recording):
            pass


def test_readers_apply_prepare_and_stop_when_the_consumer_stops(tmp_path: Path) -> None:
    import threading

    recording = open_recording(make_recording(tmp_path / "rec"))
    stream = frames(recording, prepare=lambda image: 255 - image)
    index, images = next(stream)
    assert index == 0
    assert np.abs((255 - images[0]).astype(float) - content(0, 0)).mean() < 4.0
    stream.close()  # the consumer gives up early: every reader thread ends
    assert not [t for t in threading.enumerate() if t.name.startswith("reader ")]


def test_seeking_decodes_exactly_as_the_readers() -> None:
    """The viewer's random access (FrameSeeker) gives the tracker's grey frames, in any order."""
    import itertools

    from tracker.io.readers import FrameSeeker, grey_frames

    video = Path(__file__).resolve().parents[2] / "recordings" / "demo" / "cam1.avi"
    sequence = list(itertools.islice(grey_frames(video), 12))
    seeker = FrameSeeker(video)
    try:
        for index in (10, 3, 4, 11, 0):
            np.testing.assert_array_equal(seeker.read(index), sequence[index])
    finally:
        seeker.close()


def test_other_codecs_give_their_luma_and_seek_exactly(tmp_path: Path) -> None:
    """A video in another codec (MPEG-4 part 2 here) is decoded by PyAV: its grey frames are the luma in full
    range (what OpenCV's colour frame made grey gives, to a level or two), colour frames are BGR, and random
    access across key frames gives the sequence's frames exactly."""
    import itertools

    import av

    from tracker.io.readers import FrameSeeker, grey_frames

    video, count, size = tmp_path / "cam0.mp4", 40, (96, 64)
    with av.open(str(video), "w") as container:  # a key frame every 10, B-frames between
        stream = container.add_stream("mpeg4", rate=int(FPS), options={"g": "10", "bf": "2"})
        stream.width, stream.height, stream.pix_fmt, stream.bit_rate = *size, "yuv420p", 4_000_000
        for index in range(count):
            bgr = cv2.cvtColor(cv2.resize(content(0, index % 12), size), cv2.COLOR_GRAY2BGR)
            container.mux(stream.encode(av.VideoFrame.from_ndarray(bgr, format="bgr24")))
        container.mux(stream.encode())
    with av.open(str(video)) as container:
        packets = [packet for packet in container.demux(container.streams.video[0]) if packet.size]
        assert len(packets) == count and 3 <= sum(packet.is_keyframe for packet in packets) < count
    sequence = list(itertools.islice(grey_frames(video), count))
    capture = cv2.VideoCapture(str(video))
    for index, image in enumerate(sequence):
        assert image.shape == size[::-1] and image.dtype == np.uint8
        ok, bgr = capture.read()
        assert ok and np.abs(image.astype(float) - cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)).mean() < 2.0
        assert np.abs(image.astype(float) - cv2.resize(content(0, index % 12), size)).mean() < 4.0
    capture.release()
    colour = next(grey_frames(video, [5], colour=True))
    assert colour.shape == (*size[::-1], 3) and np.abs(colour.astype(float).mean(axis=2) - sequence[5]).mean() < 3.0
    seeker = FrameSeeker(video)
    try:
        for index in (30, 3, 4, 39, 0, 17, 18):
            np.testing.assert_array_equal(seeker.read(index), sequence[index])
    finally:
        seeker.close()
    assert [len(list(grey_frames(video, range(start, start + 12, 3)))) for start in (0, 7)] == [4, 4]
    np.testing.assert_array_equal(next(grey_frames(video, range(7, 40, 3))), sequence[7])
    # frames named again are given again, those passed over skipped, as a time pairing of cameras reads them
    paired = list(grey_frames(video, [0, 0, 0, 1, 4, 4, 9]))
    for image, index in zip(paired, [0, 0, 0, 1, 4, 4, 9]):
        np.testing.assert_array_equal(image, sequence[index])


def test_readers_give_the_named_frames_also_in_reduced_colour(tmp_path: Path) -> None:
    """ColourCopies: the frames named come as WithColour, ``prepare`` applied to the grey image and the colour
    image (BGR) reduced by the factor, from videos and image folders alike; the other frames as before."""
    from tracker.io.readers import ColourCopies, WithColour, read_frames

    folder = make_recording(tmp_path / "rec")
    images = folder / "cam1"
    images.mkdir()
    for index in range(COUNT):
        cv2.imwrite(str(images / f"{index:06d}.png"), content(1, index))
    sources = [folder / "cam0.avi", images]
    copies = [ColourCopies(frozenset({2, 5}), 2), ColourCopies(frozenset({2, 5}), 1)]
    for index, frame in read_frames(sources, 1, 7, prepare=lambda image: image + 1, copies=copies):
        for camera, item in enumerate(frame):
            if index in (2, 5):
                assert isinstance(item, WithColour)
                grey, colour = item.image, item.colour
                assert colour.shape == ((HEIGHT // 2, WIDTH // 2, 3) if camera == 0 else (HEIGHT, WIDTH, 3))
                expected = content(camera, index)[:: 2 - camera, :: 2 - camera]
                assert np.abs(colour.mean(axis=2) - expected).mean() < 6.0
            else:
                grey = item
            assert grey.shape == (HEIGHT, WIDTH) and np.abs(grey.astype(float) - 1 - content(camera, index)).mean() < 4


def test_ten_bit_video_gives_its_grey_levels(tmp_path: Path) -> None:
    """A 10-bit video (two bytes a luma sample) is converted, not read as bytes: flat frames keep their level."""
    import av

    from tracker.io.readers import grey_frames

    video = tmp_path / "ten.mkv"
    with av.open(str(video), "w") as container:
        stream = container.add_stream("ffv1", rate=25)
        stream.width, stream.height, stream.pix_fmt = 96, 64, "yuv420p10le"
        for level in (20, 100, 180):
            frame = av.VideoFrame.from_ndarray(np.full((64, 96, 3), level, np.uint8), format="bgr24")
            container.mux(stream.encode(frame))
        container.mux(stream.encode())
    levels = [float(image.mean()) for image in itertools.islice(grey_frames(video), 3)]
    assert all(image_shape == (64, 96) for image_shape in [next(grey_frames(video)).shape])
    np.testing.assert_allclose(levels, [20, 100, 180], atol=2.0)


def coloured(index: int, size: tuple[int, int]) -> np.ndarray:
    """A BGR test image: a red left half and a blue right half (the boundary moving with ``index``)."""
    image = np.zeros((size[1], size[0], 3), np.uint8)
    edge = 20 + 2 * index
    image[:, :edge] = (40, 40, 220)
    image[:, edge:] = (220, 60, 40)
    return image


def test_readers_give_every_frame_with_its_half_size_colour(tmp_path: Path) -> None:
    """WithChroma: from MJPG (libjpeg at half scale), 4:2:0 video (PyAV's planes) and image folders alike, each frame
    comes with its colour at half size, (H // 2, W // 2, 3), the grey frame unchanged and ``prepare`` applied to it;
    each source's colours tell its two halves apart, at their places; with ColourCopies too the named frames also
    bring their reduced BGR."""
    import av

    from tracker.io.readers import ColourCopies, WithChroma, WithColour, grey_frames, read_frames

    size = (96, 64)
    mjpg, mp4, folder = tmp_path / "cam0.avi", tmp_path / "cam1.mp4", tmp_path / "cam2"
    writer = cv2.VideoWriter(str(mjpg), cv2.VideoWriter_fourcc(*"MJPG"), FPS, size)
    folder.mkdir()
    with av.open(str(mp4), "w") as container:
        stream = container.add_stream("mpeg4", rate=int(FPS))
        stream.width, stream.height, stream.pix_fmt, stream.bit_rate = *size, "yuv420p", 4_000_000
        for index in range(4):
            writer.write(coloured(index, size))
            cv2.imwrite(str(folder / f"{index:06d}.png"), coloured(index, size))
            container.mux(stream.encode(av.VideoFrame.from_ndarray(coloured(index, size), format="bgr24")))
        container.mux(stream.encode())
    writer.release()
    sources = [mjpg, mp4, folder]
    plain = [list(itertools.islice(grey_frames(source), 4)) for source in sources]
    copies = [ColourCopies(frozenset({2}), 2)] * 3
    for index, frame in read_frames(sources, 0, 4, prepare=lambda image: image // 2, chroma=True, copies=copies):
        for camera, item in enumerate(frame):
            if index == 2:
                assert isinstance(item, WithColour) and item.colour.shape == (32, 48, 3)
                item = item.image
            assert isinstance(item, WithChroma)
            np.testing.assert_array_equal(item.image, plain[camera][index] // 2)
            half = item.chroma.astype(float)
            assert half.shape == (32, 48, 3) and item.chroma.dtype == np.uint8
            edge = (20 + 2 * index) // 2
            left, right = half[:, : edge - 2].mean(axis=(0, 1)), half[:, edge + 2 :].mean(axis=(0, 1))
            assert np.abs(left - right).max() > 60  # the two colours are told apart
            assert np.abs(half[:, : edge - 2] - left).mean() < 8 and np.abs(half[:, edge + 2 :] - right).mean() < 8
    binned = read_frames(sources, 0, 4, chroma=lambda half: half[..., 0] // 2, copies=copies)
    for (_, frame), (_, again) in zip(binned, read_frames(sources, 0, 4, chroma=True, copies=copies)):
        for item, colour in zip(frame, again):  # a callable chroma is what it makes of the colour image
            if isinstance(item, WithColour):
                item, colour = item.image, colour.image
            np.testing.assert_array_equal(item.chroma, colour.chroma[..., 0] // 2)
            np.testing.assert_array_equal(item.image, colour.image)
