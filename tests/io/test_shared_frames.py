"""Frame sets in shared memory: what the writer puts in a slot is what an attached reader sees there, slot by slot,
and the writer's close releases the memory."""

from __future__ import annotations

import numpy as np
import pytest

from tracker.io.shared_frames import SharedFrames


def test_an_attached_reader_sees_each_slots_frame_set_in_place_until_the_writer_releases_it():
    shapes = [(3, 4, 3), (5, 2, 3)]
    rng = np.random.default_rng(0)
    sets = [[rng.integers(0, 256, shape, np.uint8) for shape in shapes] for _ in range(3)]
    writer = SharedFrames(shapes, 2)
    reader = SharedFrames.attach(writer.spec)
    try:
        assert writer.fits(sets[0]) and not writer.fits(sets[0][::-1]) and not writer.fits(sets[0][:1])
        assert not writer.fits([image.astype(np.int16) for image in sets[0]])
        writer.write(0, sets[0])
        writer.write(1, sets[1])
        seen = reader.images(1)
        for image, expected in zip(seen, sets[1]):
            np.testing.assert_array_equal(image, expected)
        writer.write(1, sets[2])  # written again: the reader's images change with it, slot 0's do not
        for slot, expected_set in ((0, sets[0]), (1, sets[2])):
            for image, expected in zip(reader.images(slot), expected_set):
                np.testing.assert_array_equal(image, expected)
        for image, expected in zip(seen, sets[2]):
            np.testing.assert_array_equal(image, expected)
        del seen
    finally:
        reader.close()
        writer.close()
    with pytest.raises(FileNotFoundError):
        SharedFrames.attach(writer.spec)
