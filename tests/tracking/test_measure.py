"""Edge search and IRLS information (tracker.tracking.measure) against docs/method-tracking.md, section 3."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracker.tracking.measure import component_misfits, edge_offset, measure_kernel, support

W, H = 80, 60
LO, HI = 40.0, 200.0
SIGMA = 1.5
RANGE = 10
PROFILE = np.empty(2 * RANGE + 3)


def vertical_step(x0, sigma=SIGMA, width=W, height=H):
    """Dark left of x = x0, bright right of it (exact pixel-area coverage), then cv2.GaussianBlur."""
    coverage = np.clip(np.arange(width) + 0.5 - x0, 0.0, 1.0)
    image = np.tile(LO + (HI - LO) * coverage, (height, 1))
    return cv2.GaussianBlur(image, (0, 0), sigma)


def oblique_step(u, c, sigma=SIGMA, ss=16):
    """Bright where X.u > c (u unit), by ss x ss supersampled pixel coverage, then cv2.GaussianBlur."""
    offsets = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(W)[:, None] + offsets).ravel()
    ys = (np.arange(H)[:, None] + offsets).ravel()
    inside = (xs[None, :] * u[0] + ys[:, None] * u[1]) > c
    coverage = inside.reshape(H, ss, W, ss).mean(axis=(1, 3))
    return cv2.GaussianBlur(LO + (HI - LO) * coverage, (0, 0), sigma)


def offset(image, p, n, search_range=RANGE, threshold=5.0):
    profile = np.empty(2 * search_range + 5)
    h, w = image.shape
    return edge_offset(
        image, w, h, float(p[0]), float(p[1]), float(n[0]), float(n[1]), search_range, threshold, profile
    )


def test_vertical_edge_with_normals_both_ways():
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(40):
        x0 = rng.uniform(35.0, 45.0)
        image = vertical_step(x0)
        for _ in range(5):
            p = np.array([x0 + rng.uniform(-7.0, 7.0), rng.uniform(15.0, 45.0)])
            for n in ([1.0, 0.0], [-1.0, 0.0]):
                m = offset(image, p, n)
                expected = (x0 - p[0]) / n[0]  # signed, positive along +n
                worst = max(worst, abs(m - expected))
    assert worst < 0.1


def test_vertical_edge_with_diagonal_normals():
    """A normal at 45 degrees to the edge normal: the offset is the distance along n, (x0 - px) / nx."""
    rng = np.random.default_rng(1)
    worst = 0.0
    c = np.sqrt(0.5)
    for _ in range(30):
        x0 = rng.uniform(35.0, 45.0)
        image = vertical_step(x0)
        p = np.array([x0 + rng.uniform(-5.0, 5.0), rng.uniform(20.0, 40.0)])
        for n in ([c, c], [c, -c], [-c, c], [-c, -c]):
            m = offset(image, p, n, search_range=12)
            worst = max(worst, abs(m - (x0 - p[0]) / n[0]))
    assert worst < 0.1


@pytest.mark.parametrize("degrees", [15, 30, 45, 135, 200, 315])
def test_oblique_edges_with_their_normals(degrees):
    rng = np.random.default_rng(degrees)
    a = np.radians(degrees)
    u = np.array([np.cos(a), np.sin(a)])
    along = np.array([-u[1], u[0]])
    worst = 0.0
    for _ in range(2):
        centre = np.array([W / 2, H / 2]) + rng.uniform(-2.0, 2.0, 2)
        image = oblique_step(u, centre @ u)
        for _ in range(10):
            s0 = rng.uniform(-6.0, 6.0)  # the edge is s0 along +u from p
            p = centre - s0 * u + rng.uniform(-8.0, 8.0) * along
            for sign in (1.0, -1.0):
                worst = max(worst, abs(offset(image, p, sign * u) - sign * s0))
    assert worst < 0.1


def test_no_edge_gives_nan():
    image = vertical_step(40.3)
    # edge farther than the search range, either way
    assert np.isnan(offset(image, [40.3 - 15.0, 30.0], [1.0, 0.0]))
    assert np.isnan(offset(image, [40.3 + 15.0, 30.0], [-1.0, 0.0]))
    # searching along the edge: no contrast along n
    assert np.isnan(offset(image, [40.3 + 4.0, 30.0], [0.0, 1.0]))
    # a flat image
    assert np.isnan(offset(np.full((H, W), 123.0), [40.0, 30.0], [1.0, 0.0]))
    # the search leaves the image
    assert np.isnan(offset(image, [-30.0, 30.0], [1.0, 0.0]))


def test_threshold():
    image = vertical_step(40.3)
    peak = np.abs(np.diff(image[30])).max()  # about (HI - LO) / (sqrt(2 pi) sigma)
    assert abs(offset(image, [37.0, 30.0], [1.0, 0.0], threshold=0.8 * peak) - 3.3) < 0.1
    assert np.isnan(offset(image, [37.0, 30.0], [1.0, 0.0], threshold=1.2 * peak))


def test_edge_just_inside_the_range_is_found():
    image = vertical_step(40.0)
    for s in (5.0, 8.6, 9.2):
        assert abs(offset(image, [40.0 - s, 30.0], [1.0, 0.0]) - s) < 0.1
        assert abs(offset(image, [40.0 + s, 30.0], [1.0, 0.0]) + s) < 0.1


def test_edge_near_the_end_of_the_range_is_found():
    image = vertical_step(40.0)
    for s in (9.6, 9.8):
        assert abs(offset(image, [40.0 - s, 30.0], [1.0, 0.0]) - s) < 0.1


def two_edges(x0, x1):
    """A bright bar between x0 and x1."""
    coverage = np.clip(np.arange(W) + 0.5 - x0, 0.0, 1.0) - np.clip(np.arange(W) + 0.5 - x1, 0.0, 1.0)
    return cv2.GaussianBlur(np.tile(LO + (HI - LO) * coverage, (H, 1)), (0, 0), SIGMA)


@pytest.mark.parametrize("nx", [1.0, -1.0])
def test_nearest_of_two_edges(nx):
    x0, x1 = 30.3, 41.7
    image = two_edges(x0, x1)
    n = [nx, 0.0]
    # between the edges, nearer the right one, and nearer the left one
    for px, nearest in ((38.2, x1), (33.1, x0), (36.4, x1), (35.4, x0)):
        m = offset(image, [px, 30.0], n)
        assert abs(m - (nearest - px) / nx) < 0.1, (px, m)
    # outside the bar, both edges on one side: the nearer
    assert abs(offset(image, [26.0, 30.0], n) - (x0 - 26.0) / nx) < 0.1
    assert abs(offset(image, [46.2, 30.0], n) - (x1 - 46.2) / nx) < 0.1


def test_search_limits_lo_hi():
    """[lo, hi] keeps the search off the nearer edge beyond a limit: the farther one inside is found, and with
    no edge inside, none.  The full range is the default."""
    x0, x1 = 30.3, 41.7
    image = two_edges(x0, x1)
    h, w = image.shape
    profile = np.empty(2 * RANGE + 5)
    px = 38.2  # nearer x1 (+3.5) than x0 (-7.9)
    full = edge_offset(image, w, h, px, 30.0, 1.0, 0.0, RANGE, 5.0, profile)
    assert abs(full - (x1 - px)) < 0.1
    m = edge_offset(image, w, h, px, 30.0, 1.0, 0.0, RANGE, 5.0, profile, -RANGE, 1)
    assert abs(m - (x0 - px)) < 0.1
    assert np.isnan(edge_offset(image, w, h, px, 30.0, 1.0, 0.0, RANGE, 5.0, profile, -2, 1))
    assert edge_offset(image, w, h, px, 30.0, 1.0, 0.0, RANGE, 5.0, profile, -100, 100) == full


# ---------------------------------------------------------------- measure_kernel


def test_measure_kernel_information_matches_numpy():
    rng = np.random.default_rng(42)
    x0, y0 = 40.3, 30.6
    vertical = vertical_step(x0)
    horizontal = cv2.GaussianBlur(
        np.tile((LO + (HI - LO) * np.clip(np.arange(H) + 0.5 - y0, 0.0, 1.0))[:, None], (1, W)), (0, 0), SIGMA
    )
    images = np.stack([vertical, horizontal])
    cam_size = np.array([[W, H], [W, H]], dtype=np.int64)
    count, n_components, robust_c = 120, 4, 2.5
    s_cam = rng.integers(0, 2, count).astype(np.int64)
    s_comp = rng.integers(0, 3, count).astype(np.int64)  # component 3 gets no samples
    s_pixel = np.empty((count, 2))
    s_normal = np.empty((count, 2))
    expected = np.empty(count)
    for s in range(count):
        sign = rng.choice([-1.0, 1.0])
        far = rng.random() < 0.2  # no edge within range
        distance = rng.uniform(-7.0, 7.0) if not far else rng.choice([-1.0, 1.0]) * rng.uniform(14.0, 18.0)
        if s_cam[s] == 0:
            s_pixel[s] = [x0 - distance, rng.uniform(10.0, 50.0)]
            s_normal[s] = [sign, 0.0]
        else:
            s_pixel[s] = [rng.uniform(10.0, 70.0), y0 - distance]
            s_normal[s] = [0.0, sign]
        expected[s] = np.nan if far else sign * distance
    s_jac = rng.normal(size=(count, 6)) * [100, 100, 100, 30, 30, 30]
    o_offset = np.full(count + 5, -7.0)
    o_weight = np.full(count + 5, -7.0)
    information = rng.normal(size=(n_components, 6, 6))  # garbage: the kernel must reset it
    eta = rng.normal(size=(n_components, 6))
    visible, found, sum_wm, sum_w = measure_kernel(
        images,
        cam_size,
        np.ones(len(cam_size), np.int64),
        count,
        s_cam,
        s_comp,
        s_pixel,
        s_normal,
        s_jac,
        np.zeros((n_components, 6)),
        RANGE,
        5.0,
        robust_c,
        n_components,
        o_offset,
        o_weight,
        information,
        eta,
    )

    m = o_offset[:count]
    valid = ~np.isnan(m)
    assert visible == count and found == valid.sum()
    np.testing.assert_array_equal(valid, ~np.isnan(expected))
    assert np.abs(m[valid] - expected[valid]).max() < 0.1
    for s in range(count):  # the kernel's offsets are edge_offset's
        alone = offset(images[s_cam[s]], s_pixel[s], s_normal[s])
        assert (np.isnan(alone) and np.isnan(m[s])) or alone == m[s]
    w = np.where(valid, 1.0 / (robust_c + np.abs(np.nan_to_num(m))), 0.0)
    np.testing.assert_allclose(o_weight[:count], w, rtol=1e-15)
    assert np.all(o_offset[count:] == -7.0) and np.all(o_weight[count:] == -7.0)  # only `count` rows written

    ref_info = np.zeros((n_components, 6, 6))
    ref_eta = np.zeros((n_components, 6))
    for i in range(n_components):
        sel = valid & (s_comp == i)
        L = s_jac[sel]
        ref_info[i] = (L * w[sel, None]).T @ L
        ref_eta[i] = L.T @ (w[sel] * m[sel])
    np.testing.assert_allclose(information, ref_info, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(eta, ref_eta, rtol=1e-12, atol=1e-9)
    assert np.all(information[3] == 0.0) and np.all(eta[3] == 0.0)
    np.testing.assert_array_equal(information, np.transpose(information, (0, 2, 1)))
    np.testing.assert_allclose(sum_w, w.sum(), rtol=1e-13)
    np.testing.assert_allclose(sum_wm, (w[valid] * np.abs(m[valid])).sum(), rtol=1e-13)


def test_measure_kernel_hand_made_offsets():
    """Two samples per component at known offsets: C = sum w L^T L, eta = sum w L^T m exactly as written."""
    x0 = 40.25
    images = vertical_step(x0)[None]
    cam_size = np.array([[W, H]], dtype=np.int64)
    offsets = np.array([2.0, -3.5, 0.75, 5.0])
    normals = np.array([[1.0, 0.0], [-1.0, 0.0], [1.0, 0.0], [-1.0, 0.0]])
    pixels = np.stack([x0 - offsets * normals[:, 0], np.full(4, 30.0)], 1)
    s_comp = np.array([0, 0, 1, 1], dtype=np.int64)
    s_jac = np.array([[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 2, 0], [0, 0, 3, 1, 0, 0], [1, 1, 1, 1, 1, 1]], float)
    o_offset, o_weight = np.empty(4), np.empty(4)
    information, eta = np.empty((2, 6, 6)), np.empty((2, 6))
    c = 1.0
    measure_kernel(
        images,
        cam_size,
        np.ones(len(cam_size), np.int64),
        4,
        np.zeros(4, np.int64),
        s_comp,
        pixels,
        normals,
        s_jac,
        np.zeros((2, 6)),
        RANGE,
        5.0,
        c,
        2,
        o_offset,
        o_weight,
        information,
        eta,
    )
    np.testing.assert_allclose(o_offset, offsets, atol=0.1)
    m = o_offset
    w = 1.0 / (c + np.abs(m))
    for i, rows in enumerate(([0, 1], [2, 3])):
        ref_c = sum(w[k] * np.outer(s_jac[k], s_jac[k]) for k in rows)
        ref_eta = sum(w[k] * s_jac[k] * m[k] for k in rows)
        np.testing.assert_allclose(information[i], ref_c, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(eta[i], ref_eta, rtol=1e-14, atol=1e-15)


def test_measure_kernel_searches_from_the_linearly_moved_sample():
    """With a twist, each search starts at p + (L . twist) n and its offset is measured from there."""
    x0 = 40.25
    images = vertical_step(x0)[None]
    cam_size = np.array([[W, H]], dtype=np.int64)
    pixels = np.array([[x0 - 9.0, 20.0], [x0 + 4.0, 30.0]])
    normals = np.array([[1.0, 0.0], [-1.0, 0.0]])
    s_comp = np.array([0, 1], dtype=np.int64)
    s_jac = np.array([[2.0, 0, 0, 0, 0, 1.0], [0, 0, 0, 0, 3.0, 0]])
    twist = np.array([[1.5, 7.0, 7.0, 7.0, 0.0, 2.5], [9.0, 9.0, 9.0, 9.0, 0.5, 0.0]])  # moves 5.5 and 1.5 px
    o_offset, o_weight = np.empty(2), np.empty(2)
    information, eta = np.empty((2, 6, 6)), np.empty((2, 6))
    measure_kernel(
        images,
        cam_size,
        np.ones(len(cam_size), np.int64),
        2,
        np.zeros(2, np.int64),
        s_comp,
        pixels,
        normals,
        s_jac,
        twist,
        RANGE,
        5.0,
        1.0,
        2,
        o_offset,
        o_weight,
        information,
        eta,
    )
    np.testing.assert_allclose(o_offset, [9.0 - 5.5, 4.0 - 1.5], atol=0.1)
    for s, start in enumerate((x0 - 3.5, x0 + 2.5)):  # the same as a fresh sample at the moved position
        alone = offset(images[0], np.array([start, pixels[s, 1]]), normals[s])
        assert alone == o_offset[s]


def test_component_misfits_are_the_median_offset_of_each_components_found_samples():
    rng = np.random.default_rng(3)
    count, components = 500, 4
    component = rng.integers(0, components - 1, size=count + 20)  # the last component has no sample
    offset = rng.normal(scale=2.0, size=count + 20)
    offset[rng.random(count + 20) < 0.2] = np.nan  # searches that found nothing
    component[:5], offset[:5] = 2, np.nan  # ... and all of component 2's first ones
    got = component_misfits(offset, component, count, components)
    for i in range(components - 1):
        found = offset[:count][(component[:count] == i) & ~np.isnan(offset[:count])]
        assert got[i] == np.median(np.abs(found))  # rows past count are not read
    assert got[components - 1] == np.inf


def test_support_is_the_mean_scaled_weight_of_the_chosen_components_samples():
    offset = np.array([0.0, 2.0, np.nan, -6.0, 1.0, 9.0])
    component = np.array([0, 0, 0, 1, 2, 2])
    chosen = np.array([True, False, True])
    c = 2.0
    by_hand = (1.0 + 0.5 + 0.0 + 2 / 3 + 2 / 11) / 5  # samples of components 0 and 2; the NaN found no edge
    assert support(offset, component, count=6, chosen=chosen, robust_c=c) == pytest.approx(by_hand)
    assert support(offset, component, count=3, chosen=chosen, robust_c=c) == pytest.approx(
        0.5
    )  # only the first count samples
    assert support(offset, component, count=6, chosen=np.array([False, False, False]), robust_c=c) == 0.0


@pytest.mark.parametrize("factor", [2, 3])
def test_a_reduced_image_gives_the_full_size_offsets(factor):
    """The search reads an image reduced by ``factor`` (tracker.tracking.frame_loop.smooth) from the samples' full-size
    places: the offsets of samples on straight and oblique edges, in full-size pixels, are those found in the
    full image, to the reduced image's sub-pixel precision."""
    from tracker.tracking.edge_cue import smooth

    size = 240
    raw = np.zeros((size, size), np.uint8)
    cv2.fillPoly(raw, [np.array([[60, 20], [200, 50], [170, 220], [30, 190]]) * 16], 200, cv2.LINE_AA, shift=4)
    raw[raw == 0] = 40
    full, reduced = smooth(raw, 2.25), smooth(raw, 2.25, work_side=size // factor)
    assert reduced.shape == (size // factor, size // factor)
    corners = np.array([[60, 20], [200, 50], [170, 220], [30, 190]], float)
    pixels, normals = [], []
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        along = (b - a) / np.linalg.norm(b - a)
        outward = np.array([along[1], -along[0]])
        for share in (0.3, 0.5, 0.7):
            for miss in (-6.0, 2.5, 7.0):
                pixels.append(a + share * (b - a) + miss * outward)
                normals.append(outward)
    pixels, normals = np.array(pixels), np.array(normals)
    count = len(pixels)
    found = []
    for image, scale in ((full, 1), (reduced, factor)):
        offsets = np.empty(count)
        measure_kernel(
            image[None],
            np.array([image.shape[::-1]], np.int64),
            np.array([scale]),
            count,
            np.zeros(count, np.int64),
            np.zeros(count, np.int64),
            pixels,
            normals,
            np.zeros((count, 6)),
            np.zeros((1, 6)),
            RANGE,
            2.0,
            1.0,
            1,
            offsets,
            np.empty(count),
            np.empty((1, 6, 6)),
            np.empty((1, 6)),
        )
        found.append(offsets)
    assert not np.isnan(found[0]).any() and not np.isnan(found[1]).any()
    assert np.abs(found[1] - found[0]).max() < 0.13 * factor  # sub-pixel precision of a reduced pixel
