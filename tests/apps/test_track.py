"""The library form of tracker track (tracker.apps.track): the summary's line on the parts the images held."""

import numpy as np

from tracker.apps.track import held_summary


def test_the_summary_names_the_parts_left_to_the_prior_in_half_the_frames_or_more():
    parts = ("pelvis", "torso", "shin_l", "foot_l", "hand_r")
    held = np.array([48, 48, 8, 0, 30])  # frames of 48 in which the images held each: 134 of 240, 56 %
    line = held_summary(parts, held, 48)
    assert line == (
        "parts held by the images: 56 % of 5 parts x 48 frames; by the prior only in half the frames or more: "
        "foot_l 48, shin_l 40 (frames)"
    )
    assert held_summary(parts, np.full(5, 48), 48) == "parts held by the images: 100 % of 5 parts x 48 frames"
    assert held_summary(parts, np.array([48, 48, 48, 48, 24]), 48).endswith(": hand_r 24 (frames)")  # exactly half
