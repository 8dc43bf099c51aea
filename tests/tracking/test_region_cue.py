"""The region cue's kernels against a brute-force posterior, and its colour learning."""

from __future__ import annotations

import numpy as np
import pytest

from tracker.tracking.colours import (
    BINS,
    COLOURS,
    FACTOR,
    RESCALE,
    Counts,
    Histograms,
    colour_bins,
    colour_grids,
    colour_reduction,
    part_table,
)
from tracker.tracking.region_lines import learn_kernel, line_profiles, log_table, region_kernel
from tracker.tracking.settings import Settings

MARGIN = Settings().region.margin
PART = (200, 40, 40)  # a colour of the part, as the chroma image holds it
ROOM = (40, 200, 40)


def bin_of(colour) -> int:
    step = 256 // BINS
    c = [int(value) for value in colour]
    return (c[0] // step) * BINS * BINS + (c[1] // step) * BINS + c[2] // step


def split_image(edge: float, width: int = 80, height: int = 40, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """A half-size colour image: the part's colour left of column ``edge``, the room's right of it; with ``noise``,
    that share of pixels swapped at random."""
    chroma = np.empty((1, height, width, 3), np.uint8)
    columns = np.arange(width)
    part = columns < edge
    rng = np.random.default_rng(seed)
    for v in range(height):
        swapped = part ^ (rng.random(width) < noise)
        chroma[0, v] = np.where(swapped[:, None], PART, ROOM)
    return chroma


def histograms(components: int = 2) -> Histograms:
    h = Histograms.empty(1, components)
    h.foreground[0, :, bin_of(PART)] = 0.9
    h.foreground[0, :, bin_of(ROOM)] = 0.1
    h.background[0, :, bin_of(ROOM)] = 0.8
    h.background[0, :, bin_of(PART)] = 0.2
    h.seen[:] = True
    h.seen_background[:] = True
    return h


def bins_of(chroma):
    out = np.zeros(chroma.shape[:3], np.int16)
    for k in range(len(chroma)):
        colour_bins(chroma[k], out[k])
    return out


def arrays_of(h):
    """The arguments of :func:`part_table` that ``h`` holds."""
    colours = h.own, h.own_size, h.backed, h.newly_backed, h.newly_backed_size
    return (h.foreground, h.background, h.scale, h.seen, h.seen_background, *colours)


def table_of(h):
    """(p_f table, distinctness) of histograms ``h``."""
    out, distinct = np.full(h.foreground.shape, np.nan), np.zeros(h.seen.shape)
    h.gather_colours()
    part_table(*arrays_of(h), out, distinct)
    return out, distinct


NO_PERSON = (np.zeros((1, 1, 1), np.uint8), np.zeros(1))
"""No person's mask: the region cue reads the colours alone."""


def run(
    chroma,
    pixel,
    *,
    outside=-1,
    depth=41,
    lo=-20,
    hi=20,
    jacobian=None,
    twist=None,
    h=None,
    person=NO_PERSON,
    factor=FACTOR,
    **options,
):
    """The kernels on one sample in camera 0 of component 0 with normal +x, its line profiled where it was sampled
    (``margin`` half-size pixels beyond its candidates, the default's unless given) and read after the component
    moved by ``twist``, with ``person`` (the camera's person mask and its trust), ``chroma`` a colour image of
    ``factor`` full-size pixels a pixel; returns (mean, variance, C, eta, used)."""
    h = histograms() if h is None else h
    jac = np.array([jacobian if jacobian is not None else [1.0, 0.2, 0.0, 0.0, 0.3, -0.1]])
    information, eta = np.zeros((2, 6, 6)), np.zeros((2, 6))
    mean, variance = np.zeros(1), np.zeros(1)
    settings = dict(amplitude=0.43, slope=0.5, weight=2.0, min_variance=1.0, margin=MARGIN, afresh=False) | options
    bins, size = bins_of(chroma), np.array([[chroma.shape[2], chroma.shape[1], factor, 0]])
    table, distinct = table_of(h)
    logs = log_table(settings["amplitude"], settings["slope"])[None]
    line = (np.zeros(1, np.int64), np.zeros(1, np.int64), np.array([pixel], float), np.array([[1.0, 0.0]]))
    limits = (np.array([outside]), np.array([depth]))
    search = (np.array([lo]), np.array([hi]))
    profiles = line_profiles(
        bins, size, 1, *line, *limits, *search, 1, table, *person, logs, np.array([settings["margin"]])
    )
    used = region_kernel(
        bins,
        size,
        1,
        *line,
        jac,
        *limits,
        np.zeros((2, 6)) if twist is None else twist,
        *search,
        1,
        table,
        *person,
        distinct,
        logs,
        settings["weight"],
        settings["min_variance"],
        *profiles,
        settings["afresh"],
        mean,
        variance,
        information,
        eta,
    )
    return mean[0], variance[0], information, eta, used


def brute_force(chroma, pixel, lo, hi, h, amplitude=0.43, slope=0.5, person=NO_PERSON):
    """The posterior's mean and variance (full-size pixels) by the product over every pixel of the line, the step
    flat beyond one pixel as the kernel takes it; each pixel's p_f joined by the person's mask (``person``: the
    camera's mask and trust), bilinear like p_f, as independent odds."""
    x0 = (pixel[0] + 0.5) / FACTOR - 0.5
    y0 = round((pixel[1] + 0.5) / FACTOR - 0.5)  # the tests' rows lie on pixel centres
    candidates = np.arange(-(-lo // FACTOR), hi // FACTOR + 1)
    pixels = np.arange(candidates[0] - 1, candidates[-1] + 2)

    def step(x):
        if x <= -2:
            return 0.5 + amplitude
        if x >= 2:
            return 0.5 - amplitude
        return 0.5 - amplitude * np.tanh(x / (2 * slope))

    log_likelihood = []
    for d in candidates:
        total = 0.0
        for t in pixels:
            x = x0 + t
            u = int(np.floor(x))
            p = sum(
                weight
                * (lambda b: h.foreground[0, 0, b] / (h.foreground[0, 0, b] + h.background[0, 0, b]))(
                    bin_of(chroma[0, y0, column])
                )
                for column, weight in ((u, 1 - (x - u)), (u + 1, x - u))
            )
            if person[1][0] > 0:
                mask = person[0][0, y0].astype(float)
                m = 0.5 + person[1][0] * ((mask[u] * (1 - (x - u)) + mask[u + 1] * (x - u)) / 255 - 0.5)
                p = p * m / (p * m + (1 - p) * (1 - m))
            total += np.log(step(t - d) * p + (1 - step(t - d)) * (1 - p))
        log_likelihood.append(total)
    posterior = np.exp(np.array(log_likelihood) - max(log_likelihood))
    posterior /= posterior.sum()
    mean = (posterior * candidates).sum()
    return FACTOR * mean, FACTOR**2 * (posterior * (candidates - mean) ** 2).sum()


@pytest.mark.parametrize("noise", [0.0, 0.2])
@pytest.mark.parametrize("edge", [30.0, 33.0, 36.0, 40.0])
def test_the_posterior_equals_the_brute_force_product(edge, noise):
    chroma = split_image(edge, noise=noise, seed=int(edge))
    pixel = (65.3, 40.5)  # half-size (32.4, 20.0)
    mean, variance, *_ = run(chroma, pixel, lo=-14, hi=17)
    expected_mean, expected_variance = brute_force(chroma, pixel, -14, 17, histograms())
    assert mean == pytest.approx(expected_mean, abs=1e-4)  # the likelihood terms are tabulated (region.log_table)
    assert variance == pytest.approx(expected_variance, abs=1e-4)


def person_left_of(column: int, trust: float, width: int = 80, height: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A camera's person mask that says "person" (0.9) left of half-size ``column`` and not (0.1) from it on."""
    mask = np.where(np.arange(width) < column, 230, 25).astype(np.uint8)
    return np.ascontiguousarray(np.broadcast_to(mask, (1, height, width))), np.array([trust])


@pytest.mark.parametrize("trust", [0.3, 0.6, 1.0])
@pytest.mark.parametrize("column", [30, 36])
def test_the_persons_mask_joins_each_pixels_colour_as_the_brute_force_product(trust, column):
    chroma = split_image(33.0, noise=0.2, seed=5)
    pixel = (65.3, 40.5)
    person = person_left_of(column, trust)
    mean, variance, *_ = run(chroma, pixel, lo=-14, hi=17, person=person)
    expected_mean, expected_variance = brute_force(chroma, pixel, -14, 17, histograms(), person=person)
    assert mean == pytest.approx(expected_mean, abs=1e-4) and variance == pytest.approx(expected_variance, abs=1e-4)


def test_where_the_colours_cannot_tell_the_mask_places_the_outline():
    """The part's colours and the room's equally likely on either side: alone the line knows nothing (its mean at
    the middle of its candidates, its variance theirs); with a mask that ends at half-size column 36 (full-size x
    71.5), the outline goes there."""
    chroma = split_image(32.0, noise=0.5, seed=2)
    h = histograms()
    h.foreground[0, :, bin_of(PART)] = h.foreground[0, :, bin_of(ROOM)] = 0.5
    h.background[0, :, bin_of(PART)] = h.background[0, :, bin_of(ROOM)] = 0.5
    blind_mean, blind_variance, *_ = run(chroma, (63.5, 40.5), h=h)
    assert blind_mean == pytest.approx(0.0, abs=0.5) and blind_variance > 100.0
    mean, variance, *_ = run(chroma, (63.5, 40.5), h=h, person=person_left_of(36, 0.6))
    assert 63.5 + mean == pytest.approx(71.5, abs=0.5) and variance < blind_variance / 8


@pytest.mark.parametrize("factor", [FACTOR, 2 * FACTOR])
@pytest.mark.parametrize("shift", [-6, -2, 0, 4, 8])
def test_the_mean_finds_the_boundary_along_the_outward_normal(shift, factor):
    """The part lies at x < edge: a sample at the boundary's full-size place gives an offset near 0; moved by
    ``shift`` pixels along its normal (+x), the offset brings it back, to within a quarter of the colour pixel, on
    the half-size colour image and on a quarter-size one (a view the edge search reads reduced)."""
    edge = 64 // factor  # column where the room begins: the boundary at full-size x 63.5 (half-size x 31.5)
    chroma = split_image(edge, width=160 // factor, height=80 // factor, noise=0.05)
    mean, variance, *_ = run(chroma, (63.5 + shift, 40.5), factor=factor)
    assert mean == pytest.approx(-shift, abs=factor / 4)
    assert variance < (1.5 * factor) ** 2  # a standard deviation under 1.5 colour pixels, with this weak contrast


def test_each_camera_reads_its_colour_at_the_edge_searchs_scale():
    """Half size, reduced further by the factor that keeps the half-size short side at least half of work_side (the
    edge search's reduction for the view); the grid's width and height are the half-size image's whole blocks."""
    size = np.array([[1920, 1080], [640, 480], [1280, 720], [1280, 960], [3840, 2160], [1923, 1081]])
    np.testing.assert_array_equal(
        colour_grids(size, 480),
        [[480, 270, 4], [320, 240, 2], [640, 360, 2], [320, 240, 4], [480, 270, 8], [480, 270, 4]],
    )
    np.testing.assert_array_equal(colour_grids(size, 0)[:, 2], 2)
    assert [colour_reduction(half, 480) for half in (120, 239, 240, 479, 480, 540, 1080)] == [1, 1, 1, 1, 2, 2, 4]


def test_a_line_adds_its_weighted_row_to_the_information():
    chroma = split_image(32.0, noise=0.1, seed=3)
    jacobian = np.array([1.0, 0.2, 0.0, 0.0, 0.3, -0.1])
    mean, variance, information, eta, used = run(chroma, (60.0, 40.5), jacobian=jacobian, weight=2.0, min_variance=0.5)
    distinct = 1.0 - 2 * np.sqrt(0.9 * 0.2) / 2 - 2 * np.sqrt(0.1 * 0.8) / 2  # 1 - Bhattacharyya coefficient
    w = 2.0 * distinct / max(variance, 0.5)
    assert used == 1
    np.testing.assert_allclose(information[0], w * np.outer(jacobian, jacobian), rtol=1e-12)
    np.testing.assert_allclose(eta[0], w * jacobian * mean, rtol=1e-12)
    assert not information[1].any() and not eta[1].any()


def moved_by(pixels: float) -> tuple[np.ndarray, np.ndarray]:
    """A Jacobian along the normal and a twist that moves component 0 by ``pixels`` (full-size) along it."""
    twist = np.zeros((2, 6))
    twist[0, 0] = pixels
    return np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]), twist


@pytest.mark.parametrize("pixels", [-6.0, 4.0, 10.0])
@pytest.mark.parametrize("margin", [0, MARGIN])
def test_the_predicted_motion_moves_the_line(margin, pixels):
    """With the component moved by a twist since sampling, the line starts at p + (L . twist) n: read from the
    line's profile while the move is within its margin, scored afresh beyond."""
    chroma = split_image(32.0, noise=0.1, seed=5)
    jacobian, twist = moved_by(pixels)
    moved, *_ = run(chroma, (60.0, 40.5), jacobian=jacobian, twist=twist, margin=margin)
    direct, *_ = run(chroma, (60.0 + pixels, 40.5), jacobian=jacobian)
    assert moved == pytest.approx(direct, abs=1e-12)


@pytest.mark.parametrize("pixels", [-3.3, -0.7, 1.4, 2.9])
def test_a_move_between_pixels_read_from_the_profile_finds_the_boundary_as_a_fresh_line_does(pixels):
    """The profile's candidates lie on the whole half-size pixels from the sampled place, a fresh line's on those
    from the moved place: the two posteriors differ by that phase only."""
    chroma = split_image(32.0, noise=0.05, seed=2)
    jacobian, twist = moved_by(pixels)
    profiled, profiled_variance, *_ = run(chroma, (60.0, 40.5), jacobian=jacobian, twist=twist)
    fresh, fresh_variance, *_ = run(chroma, (60.0, 40.5), jacobian=jacobian, twist=twist, margin=0)
    still, *_ = run(chroma, (60.0, 40.5), jacobian=jacobian)
    assert 60.0 + pixels + profiled == pytest.approx(60.0 + still, abs=0.25)  # the same boundary from anywhere
    assert profiled == pytest.approx(fresh, abs=0.5)
    assert profiled_variance == pytest.approx(fresh_variance, abs=0.5)


@pytest.mark.parametrize("pixels", [-1.3, 0.7, 2.9])
def test_a_line_scored_afresh_takes_its_candidates_from_the_moved_place(pixels):
    """The frame's last iteration scores every line afresh: the same posterior as a line sampled where the part
    moved to, whatever the profile holds."""
    chroma = split_image(32.0, noise=0.05, seed=2)
    jacobian, twist = moved_by(pixels)
    afresh, afresh_variance, *_ = run(chroma, (60.0, 40.5), jacobian=jacobian, twist=twist, afresh=True)
    direct, direct_variance, *_ = run(chroma, (60.0 + pixels, 40.5), jacobian=jacobian)
    assert afresh == pytest.approx(direct, abs=1e-12) and afresh_variance == pytest.approx(direct_variance, abs=1e-12)


def test_a_line_whose_margin_leaves_the_image_is_profiled_without_it():
    """Near the image's edge the line is profiled on its own candidates, so it still counts where it was sampled,
    and moved out of them it is scored afresh."""
    chroma = split_image(62.0, noise=0.05, seed=4)  # the boundary at full-size x 123.5; the image is 160 wide
    lo, hi = -20, 34  # the line reaches half-size x 78.75 of 79: the margin's pixels would leave it
    bins, size = bins_of(chroma), np.array([[80, 40, FACTOR, 0]])
    line = (np.zeros(1, np.int64), np.zeros(1, np.int64), np.array([[122.0, 40.5]]), np.array([[1.0, 0.0]]))
    limits = (np.array([-1]), np.array([41]), np.array([lo]), np.array([hi]))
    logs = log_table(0.43, 0.5)[None]
    for x, (first, length) in ((122.0, (-10, 28)), (100.0, (-10 - MARGIN, 28 + 2 * MARGIN))):
        line[2][0, 0] = x
        _, _, profiled_first, profiled_length = line_profiles(
            bins, size, 1, *line, *limits, 1, table_of(histograms())[0], *NO_PERSON, logs, np.array([MARGIN])
        )
        assert (profiled_first[0], profiled_length[0]) == (first, length)
    still, *_ = run(chroma, (122.0, 40.5), lo=lo, hi=hi)
    assert 122.0 + still == pytest.approx(123.5, abs=1.0)
    jacobian, twist = moved_by(-2.0)
    moved, *_ = run(chroma, (122.0, 40.5), lo=lo, hi=hi, jacobian=jacobian, twist=twist)
    direct, *_ = run(chroma, (120.0, 40.5), lo=lo, hi=hi, jacobian=jacobian)
    assert moved == pytest.approx(direct, abs=1e-12)


def test_lines_that_cannot_tell_are_left_out():
    chroma = split_image(32.0)
    assert np.isnan(run(chroma, (63.5, 40.5), outside=1)[0])  # another part outside: no background there
    assert np.isnan(run(chroma, (63.5, 40.5), lo=-2, hi=1)[0])  # too short a line
    assert np.isnan(run(chroma, (158.0, 40.5))[0])  # reaches beyond the image
    unseen = histograms()
    unseen.seen[0, 0] = False
    assert np.isnan(run(chroma, (63.5, 40.5), h=unseen)[0])


def test_a_thin_part_keeps_its_offsets_within_half_its_width():
    """A part 6 half-size pixels wide between two stretches of room: the candidates stop half way across it, so
    the room on its far side cannot pull the outline in."""
    chroma = split_image(32.0)
    chroma[0, :, :26] = ROOM
    near, *_ = run(chroma, (63.5, 40.5), depth=12, lo=-20)
    assert abs(near) <= 0.5
    far, *_ = run(chroma, (63.5, 40.5), depth=41, lo=-20)
    assert far < -5.0  # without the width, the far side pulls the outline in: the reason the width is there


def learn(chroma, seen, mean, counts, person=NO_PERSON):
    """learn_kernel on two lines of camera 0 at half-size row 20 and 10: component 0 with the room outside,
    component 1 with another part outside; their last offsets ``mean``; ``person`` as :func:`run`'s."""
    learn_kernel(
        bins_of(chroma),
        np.array([[80, 40, FACTOR, 0]]),
        2,
        np.zeros(2, np.int64),
        np.array([0, 1]),
        np.array([[63.5, 40.5], [63.5, 20.5]]),
        np.array([[1.0, 0.0], [1.0, 0.0]]),
        np.zeros((2, 6)),
        np.array([-1, 0]),
        np.array([41, 41]),
        np.zeros((2, 6)),
        np.array([-20, -20]),
        np.array([20, 20]),
        np.asarray(mean, float),
        seen.seen,
        2.0,
        np.array([2]),
        np.array([5]),
        *person,
        *counts.arrays(),
    )


def test_known_colours_are_learnt_only_where_the_line_agrees_with_the_outline():
    chroma = split_image(32.0)
    seen = Histograms.empty(1, 2)
    seen.seen[:] = True
    counts = Counts.empty(1, 2)
    learn(chroma, seen, [1.5, 3.0], counts)  # the first line agrees within 2 pixels, the second does not
    assert counts.colours[0, 0, 0].sum() == 2 and counts.colours[0, 0, 1].sum() == 0
    learn(chroma, seen, [np.nan, -2.0], counts)  # a line the cue did not measure teaches nothing
    assert counts.colours[0, 0, 0].sum() == 2 and counts.colours[0, 0, 1].sum() == 2
    assert counts.touched_count[0, 0].tolist() == [1, 1] and counts.touched[0, 0, :, 0].tolist() == [bin_of(PART)] * 2


def test_with_a_mask_colours_are_learnt_only_where_it_agrees():
    """The mask says "person" everywhere: the part's pixels count and its background's do not; "not the person"
    everywhere: the reverse (a leg hidden behind a table does not learn the table's colours as its own)."""
    chroma = split_image(32.0)
    for column, part, background in ((80, 2, 0), (0, 0, 4)):
        counts = Counts.empty(1, 2)
        learn(chroma, Histograms.empty(1, 2), [np.nan, np.nan], counts, person=person_left_of(column, 0.6))
        assert counts.colours[0, 0, 0].sum() == part and counts.colours[1, 0, 0].sum() == background


def test_learning_counts_inside_and_outside_then_blends():
    chroma = split_image(32.0)
    seen = Histograms.empty(1, 2)
    counts = Counts.empty(1, 2)
    learn(chroma, seen, [np.nan, np.nan], counts)
    fg, bg = counts.colours
    assert fg[0, 0, bin_of(PART)] == 2 and fg[0, 1, bin_of(PART)] == 2 and fg.sum() == 4
    assert bg[0, 0, bin_of(ROOM)] == 4 and bg.sum() == 4  # 2..5 out of the first line; the second has a part outside
    seen.learn(counts, rate=0.2)
    assert seen.seen.all() and seen.seen_background.tolist() == [[True, False]] and seen.ready
    assert not counts.colours.any() and not counts.touched_count.any()  # the counts are used up
    foreground, background = seen.frequencies()
    assert foreground[0, 0].sum() == pytest.approx(1.0) and background[0, 0].sum() == pytest.approx(1.0)
    fg[0, 0, 0] = 1.0
    counts.touched[0, 0, 0, 0], counts.touched_count[0, 0, 0] = 0, 1
    seen.learn(counts, rate=0.2)
    foreground, after = seen.frequencies()
    assert foreground[0, 0, 0] == pytest.approx(0.2)
    assert foreground[0, 0, bin_of(PART)] == pytest.approx(0.8)
    np.testing.assert_array_equal(after, background)
    table, distinct = table_of(seen)
    assert distinct[0, 0] == pytest.approx(1.0) and distinct[0, 1] == pytest.approx(1.0)  # no colour shared
    assert table[0, 1, bin_of(ROOM)] == 0.0  # the second part, with no background of its own, takes the camera's
    assert table[0, 0, bin_of(PART)] == pytest.approx(0.8 / (0.8 + 0.0)) and table[0, 0, 1] == 0.5
    assert table[0, 0, bin_of(ROOM)] == 0.0
    assert COLOURS == BINS**3


def test_learning_only_the_colours_counted_is_the_whole_blend():
    """The decay kept in each histogram's scale, through enough frames for the scale to be taken in
    (``RESCALE``): the same frequencies and the same table as blending every bin each frame."""
    rng = np.random.default_rng(7)
    h, counts = Histograms.empty(2, 3), Counts.empty(2, 3)
    dense = np.zeros((2, 2, 3, COLOURS))
    learnt = np.zeros((2, 2, 3), bool)
    frames = int(1.5 * np.log(RESCALE) / np.log(0.5))  # each histogram learns in four frames of five
    for _ in range(frames):
        for which, k, i in np.ndindex(2, 2, 3):
            if rng.random() < 0.2:  # nothing counted this frame: the histogram keeps its colours
                continue
            for b in rng.choice(COLOURS, size=rng.integers(1, 30), replace=False):
                counts.colours[which, k, i, b] = rng.integers(1, 5)
                counts.touched[which, k, i, counts.touched_count[which, k, i]] = b
                counts.touched_count[which, k, i] += 1
            new = counts.colours[which, k, i] / counts.colours[which, k, i].sum()
            dense[which, k, i] = 0.5 * dense[which, k, i] + 0.5 * new if learnt[which, k, i] else new
            learnt[which, k, i] = True
        h.learn(counts, rate=0.5)
    assert (h.scale > RESCALE).all()  # 0.5 ** (4 / 5 * frames) is not: every scale was taken in on the way
    for lazy, whole in zip(h.frequencies(), dense):
        np.testing.assert_allclose(lazy, whole, rtol=1e-9, atol=1e-300)
    reference = Histograms(dense[0], dense[1], np.ones((2, 2, 3)), learnt[0], learnt[1])
    np.testing.assert_allclose(table_of(h)[0], table_of(reference)[0], rtol=1e-9)


def brute_table(h):
    """p_f of every colour by its definition (module docstring of region_cue), bin by bin."""
    part, background = h.frequencies()
    out = np.full(part.shape, np.nan)
    for k in range(len(part)):
        learnt = np.flatnonzero(h.seen_background[k])
        if not len(learnt):
            continue
        around = np.zeros(COLOURS)
        for j in learnt:
            around += background[k, j]
        around /= len(learnt)
        for i in np.flatnonzero(h.seen[k]):
            g = (0.5 * background[k, i] + 0.5 * around) if h.seen_background[k, i] else around
            f = part[k, i]
            with np.errstate(invalid="ignore", divide="ignore"):
                out[k, i] = np.where(f > 0, f / (f + g), np.where(g > 0, 0.0, 0.5))
    return out


def test_the_table_kept_from_frame_to_frame_is_the_table_of_every_colour():
    """Frames of colours learnt, parts and backgrounds first seen at different frames, a camera whose parts have no
    background for a while: the table kept from frame to frame at each part's own colours and the newly backed
    ones is, to the last bit, the table made afresh, and within rounding the table of every colour by its
    definition; the parts' own colours are those their histograms hold, ascending."""
    rng = np.random.default_rng(11)
    h, counts = Histograms.empty(2, 4), Counts.empty(2, 4)
    kept, kept_distinct = np.full(h.foreground.shape, np.nan), np.zeros(h.seen.shape)
    unlearnt = []  # per frame, the rows not learnt yet
    for frame in range(40):
        for which, k, i in np.ndindex(2, 2, 4):
            if rng.random() < 0.5 or (which == 1 and k == 1 and frame < 10) or frame < 2 * i:
                continue
            for b in rng.choice(COLOURS, size=rng.integers(1, 40), replace=False) // 8:
                if counts.colours[which, k, i, b] == 0:
                    counts.touched[which, k, i, counts.touched_count[which, k, i]] = b
                    counts.touched_count[which, k, i] += 1
                counts.colours[which, k, i, b] += rng.integers(1, 5)
        h.learn(counts, rate=0.3)
        part_table(*arrays_of(h), kept, kept_distinct)
        afresh = Histograms(h.foreground, h.background, h.scale, h.seen, h.seen_background)
        table, distinct = table_of(afresh)
        np.testing.assert_array_equal(kept, table)
        np.testing.assert_array_equal(kept_distinct, distinct)
        np.testing.assert_allclose(kept, brute_table(h), rtol=1e-12)
        unlearnt.append(int(np.isnan(kept[..., 0]).sum()))
    for k, i in np.ndindex(2, 4):
        np.testing.assert_array_equal(h.own[k, i, : h.own_size[k, i]], np.flatnonzero(h.foreground[k, i]))
    assert unlearnt[0] > unlearnt[5] > unlearnt[-1] == 0 and (kept == 0.5).any() and (kept == 0.0).any()


def test_the_table_of_likelihood_terms_is_the_logarithm():
    p = np.linspace(0.0, 1.0, 1001)
    table = log_table(0.43, 0.5)
    steps = np.linspace(0.0, 1.0, table.shape[1])
    h_one = 0.43 * np.tanh(1.0)
    for row, h in enumerate((0.93, 0.07, 0.5 + h_one, 0.5 - h_one)):
        exact = np.log(h * p + (1 - h) * (1 - p))
        np.testing.assert_allclose(np.interp(p, steps, table[row]), exact, atol=1e-4)


def test_a_part_coloured_like_its_background_does_not_vote():
    """Skin before a beige wall: when the part's histogram is the background's, the lines weigh nothing."""
    same = histograms()
    same.foreground[0, :] = same.background[0, 0]
    mean, variance, information, eta, used = run(split_image(32.0), (63.5, 40.5), h=same)
    assert used == 1 and not information.any() and not eta.any()


def test_a_parts_background_is_the_mean_of_its_own_and_the_cameras():
    """The legs before the floor, the arms before the wall: each part's p_f takes the mean of the background just
    outside it and the camera's (the mean of its parts' backgrounds), brute force over three parts."""
    rng = np.random.default_rng(3)
    h = Histograms.empty(1, 3)
    h.foreground[0] = rng.random((3, COLOURS)) ** 4
    h.background[0] = rng.random((3, COLOURS)) ** 4
    h.foreground[0] /= h.foreground[0].sum(axis=1, keepdims=True)
    h.background[0] /= h.background[0].sum(axis=1, keepdims=True)
    h.seen[:] = True
    h.seen_background[0] = [True, True, False]
    table, distinct = table_of(h)
    camera = h.background[0, :2].mean(axis=0)
    for i, g in enumerate((0.5 * (h.background[0, 0] + camera), 0.5 * (h.background[0, 1] + camera), camera)):
        np.testing.assert_allclose(table[0, i], h.foreground[0, i] / (h.foreground[0, i] + g), rtol=1e-12)
        assert distinct[0, i] == pytest.approx(1.0 - np.sqrt(h.foreground[0, i] * g).sum(), rel=1e-12)


def test_with_every_second_line_only_the_even_samples_lines_are_read():
    """``every`` = 2 (the default, ``Settings.region_every``): of two samples, the first's line is profiled and adds
    exactly the row it adds alone, the second's is left out, in both the profiles and the information."""
    chroma, h = split_image(32.0, noise=0.05, seed=3), histograms()
    bins, size = bins_of(chroma), np.array([[chroma.shape[2], chroma.shape[1], FACTOR, 0]])
    table, distinct = table_of(h)
    logs = log_table(0.43, 0.5)[None]
    pixels, normals = np.array([[60.0, 30.0], [60.0, 50.0]]), np.tile([1.0, 0.0], (2, 1))
    jac = np.tile([1.0, 0.2, 0.0, 0.0, 0.3, -0.1], (2, 1))

    def read(count: int, every: int):
        line = (np.zeros(count, np.int64), np.zeros(count, np.int64), pixels[:count], normals[:count])
        limits, search = (np.full(count, -1), np.full(count, 41)), (np.full(count, -20), np.full(count, 20))
        profiles = line_profiles(
            bins, size, count, *line, *limits, *search, every, table, *NO_PERSON, logs, np.array([MARGIN])
        )
        information, eta, mean, variance = np.zeros((2, 6, 6)), np.zeros((2, 6)), np.zeros(count), np.zeros(count)
        used = region_kernel(
            bins, size, count, *line, jac[:count], *limits, np.zeros((2, 6)), *search, every, table, *NO_PERSON,
            distinct, logs, 2.0, 1.0, *profiles, False, mean, variance, information, eta,
        )  # fmt: skip
        return used, profiles[3], mean, information, eta

    assert read(2, 1)[0] == 2
    used, length, mean, information, eta = read(2, 2)
    alone = read(1, 1)
    assert used == 1 and length[0] > 0 and length[1] == 0 and np.isnan(mean[1])
    assert mean[0] == alone[2][0]
    np.testing.assert_array_equal(information, alone[3])
    np.testing.assert_array_equal(eta, alone[4])


def test_learning_at_a_rate_of_one_replaces_what_was_learnt():
    """A fit teaches its frames' mean (``rate`` 1 / (k + 1)) in a tracker that may have learnt before: at a rate of
    1 the frame's colours replace the histogram, scale and all."""
    h, counts = Histograms.empty(1, 1), Counts.empty(1, 1)
    for colour, rate in ((3, 0.2), (5, 0.5), (9, 1.0)):
        counts.colours[0, 0, 0, colour] = 2.0
        counts.touched[0, 0, 0, 0], counts.touched_count[0, 0, 0] = colour, 1
        h.learn(counts, rate=rate)
    foreground, _ = h.frequencies()
    assert foreground[0, 0, 9] == 1.0 and foreground[0, 0].sum() == 1.0 and h.scale[0, 0, 0] == 1.0
