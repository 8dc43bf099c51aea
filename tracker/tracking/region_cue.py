"""The region cue: where along each sample's line the colours change from the part's own to the room's
(docs/region.md).

The edge search takes the nearest grey-level edge, which in a furnished room or on patterned clothes is often
not the body's outline.  The region cue reads the same lines in colour instead, in the half-size colour image the
readers decode beside the grey one (:class:`tracker.io.readers.WithChroma`), reduced further by the factor the edge
search reduces the view's grey image by (:func:`colour_reduction`), and asks which offset ``d`` of the outline along
the line best splits it into the part's colours inside and the background's outside.  Each camera's colour image is
``grid[k, 2]`` full-size pixels to one of its own, the *colour pixels*, and ``grid[k, :2]`` of them wide and high.

Colour statistics: each colour (16 bins per channel, 4096 bins) has a frequency ``h_f`` among the pixels of
component ``i`` in camera ``k`` and ``h_b`` among the background pixels just outside that part's outline in camera
``k``, learnt online from the tracked poses (:func:`learn_kernel`, ``h <- (1 - a) h + a h_new``).  A pixel of
colour ``y`` is the part's with probability ``p_f = h_f / (h_f + g)`` (0.5 for a colour seen in neither), where
``g`` is the mean of the part's own background ``h_b`` and the camera's, the mean of all its parts' ``h_b``: the
legs are seen against the floor, the arms and the head against the walls, and a part's own background alone, learnt
from its few lines, is too sparse to be fair to a printed costume (:func:`part_table`).  Between pixel centres,
``p_f`` is interpolated bilinearly, so that the line's points lie where the line is.

Along the line ``x_t = p + t n`` (``t`` in colour pixels, ``n`` the outward normal), with a smoothed step
``H(x) = 1/2 - a tanh(x / (2 s))`` (taken flat, ``1/2 -+ a``, beyond one pixel) for the chance that a pixel
``x`` from the outline is the part's, the likelihood of the outline at ``d`` is

    L(d) = prod_t [ H(t - d) p_f(x_t) + (1 - H(t - d)) (1 - p_f(x_t)) ],

the posterior over the candidate offsets ``d`` (integers within the search interval) is ``L`` normalised, and its
mean ``mu`` and variance ``sigma^2`` (in full-size pixels) enter the component's information like an edge
measurement with offset ``mu`` and weight ``lambda / max(sigma^2, sigma_min^2)``:

    C_i += w L^T L,   eta_i += w L^T mu.

``a`` < 1/2 keeps a share of every pixel for misclassification (the step never reaches 0 or 1), so one odd pixel
cannot veto an offset.  The pixels further than one from ``d`` lie on the step's flat parts; their terms are the
same for every ``d`` on their side and are summed once per line (prefix sums), and the four terms a pixel can
take are read from a table over ``p_f`` (:func:`log_table`), so a line costs a few table reads per pixel.  Each
line is scored once per sampling of the outlines (:func:`line_profiles`) and read in the iterations between, while
its part moves little along it (:func:`region_kernel`).

A line whose outside is another part (an arm across the trunk, perhaps in the same shirt) is left out: the colours
there do not tell the part from the background.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from tracker.status import LOST
from tracker.tracking.colours import COLOURS, FACTOR, Counts, Histograms, colour_bins, colour_grids, part_table
from tracker.tracking.cue import Frame, Iteration
from tracker.tracking.motion_model import motion_since
from tracker.tracking.region_lines import learn_kernel, line_profiles, log_table, region_kernel

if TYPE_CHECKING:
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.workspace import Workspace


class RegionCue:
    """The colour regions either side of the outline as a cue of the solve (:class:`~tracker.tracking.cue.Cue`), in
    the frames that come with their colour (:class:`tracker.io.readers.WithChroma`): each camera's colour grid
    ``grid`` (C, 4: width, height, full-size pixels to one of its own, its row of ``logs``, the likelihood terms'
    tables, one per pixel size), what it learnt of each part's colours (``histograms``; ``part_table`` (C, N,
    COLOURS), p_f of every colour, and ``distinct`` (C, N), how distinct each part's colours are from its
    background's) and a frame's counts before they are learnt (``counts``)."""

    name = "region"
    stage = "region"
    places = True

    def __init__(self, tracker: Tracker):
        model, settings = tracker.model, tracker.settings
        st = self.settings = settings.region
        grids = colour_grids(tracker.rig.size, settings.images.work_side)
        sizes, row = np.unique(grids[:, 2], return_inverse=True)
        self.grid = np.column_stack([grids, row])
        self.logs = np.stack([log_table(st.amplitude, st.slope / f) for f in sizes])
        factor = grids[:, 2]
        self.size = cameras, n = len(grids), model.size
        self.counts = Counts.empty(cameras, n)
        self.margin = np.array([round(st.margin * FACTOR / f) for f in factor], np.int64)
        self.inside = np.array([max(1, round(st.inside / f)) for f in factor], np.int64)
        self.outside = np.array([max(2, round(st.outside / f)) for f in factor], np.int64)
        self.restart()

    def restart(self) -> None:
        """No colours known: those learnt on the way that led astray are the room's as often as the body's; the cue
        learns them again from the next frame."""
        cameras, n = self.size
        self.histograms = Histograms.empty(cameras, n)
        self.part_table = np.full((cameras, n, COLOURS), np.nan)
        self.distinct = np.zeros((cameras, n))

    def prepare(self, tracker: Tracker, frame: Frame) -> None:
        return None

    def warm_up(self, tracker: Tracker) -> None:
        """Run the kernels once into spare histograms, then put the learnt ones back."""
        if not self.settings.on:
            return
        learnt = self.histograms, self.part_table.copy(), self.distinct.copy()
        self.histograms = Histograms.empty(*self.histograms.seen.shape)
        colour_bins(np.zeros((2, 2, 3), np.uint8), np.zeros((2, 2), np.int16))
        self.profile_lines(tracker, tracker.work)
        self.add_lines(tracker, tracker.work, tracker.still)
        self.learn_colours(tracker)
        self.histograms, self.part_table, self.distinct = learnt

    def active(self, work: Workspace) -> bool:
        """Whether the cue takes part in a search in ``work``: it is on, the frame came in colour, and colours have
        been learnt."""
        return self.settings.on and work.coloured and self.histograms.ready

    def add(self, tracker: Tracker, work: Workspace, iteration: Iteration) -> None:
        """Add the lines' information, scored afresh where the outlines were just sampled (:meth:`profile_lines`) and
        read from their scores in the iterations between, except the frame's last."""
        if not self.active(work):
            return
        if iteration.resampled:
            self.profile_lines(tracker, work)
        self.add_lines(tracker, work, iteration.twist, afresh=iteration.last and not iteration.resampled)

    def learn(self, tracker: Tracker, status: int, *, kept: bool) -> None:
        """Learn the colours along the lines of a frame that was not lost and kept the poses its cues found."""
        if self.settings.on and tracker.work.coloured and status != LOST and kept:
            self.learn_colours(tracker)

    def evidence(self, tracker: Tracker, work: Workspace, added: np.ndarray) -> np.ndarray:
        return added

    def inspect(self, tracker: Tracker, work: Workspace) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's line as read in place of its edge: the posterior mean of the outline's offset and lambda /
        max(sigma^2, sigma_min^2) as its weight (:func:`region_kernel`); NaN and 0 where no line was read (between
        every ``every``-th sample, where the line's outside is another part, in a view of one colour) and everywhere
        until colours are learnt."""
        s, n, st = work.samples, work.samples.count, self.settings
        offset, weight = np.full(n, np.nan), np.zeros(n)
        if self.active(work):
            self.read_afresh(tracker, work)
            offset = work.region_mean[:n].copy()
            read = np.isfinite(offset)
            variance = np.maximum(work.region_variance[:n][read], st.sigma**2)
            weight[read] = st.weight * self.distinct[s.camera[:n][read], s.component[:n][read]] / variance
        return offset, weight

    def teach(
        self, tracker: Tracker, images, *, poses: np.ndarray, rate: float, search_range: int | None = None
    ) -> None:
        """Learn the colours of one frame whose ``poses`` are known (a model fit's frames, docs/fit-model.md), mixed
        in at ``rate`` (:meth:`learn_colours`); the tracker is left at ``poses``.  ``images``: one grey image per
        camera with its colour (:class:`tracker.io.readers.WithChroma`); a frame without colour teaches nothing."""
        work = tracker.work
        tracker.load_images(images)
        tracker.poses = tracker.sampled_poses = tracker.model.coerce(poses)
        if not work.coloured:
            return
        tracker.sample(work, tracker.poses, tracker.search_range(0) if search_range is None else search_range)
        work.region_mean[: work.samples.count] = np.nan
        if self.active(work):  # once colours are known, only the lines that agree with the outline teach
            self.read_afresh(tracker, work)
        self.learn_colours(tracker, rate)

    def read_afresh(self, tracker: Tracker, work: Workspace) -> None:
        """Score the lines of the samples just placed in ``work`` and read each one's mean and variance from them
        (:meth:`profile_lines`, :meth:`add_lines` afresh, at the poses sampled)."""
        self.profile_lines(tracker, work)
        self.add_lines(tracker, work, tracker.still, afresh=True)

    def profile_lines(self, tracker: Tracker, work: Workspace) -> None:
        """Score the lines at the places just sampled, for this and the next iterations (:func:`line_profiles`)."""
        s, person = work.samples, tracker.person
        lo, hi, outside, depth = work.limits()
        work.profiles = line_profiles(
            work.bins,
            self.grid,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            outside,
            depth,
            lo,
            hi,
            max(self.settings.every, 1),
            self.part_table,
            person.mask,
            person.trust,
            self.logs,
            self.margin,
        )

    def add_lines(self, tracker: Tracker, work: Workspace, twist: np.ndarray, *, afresh: bool = False) -> int:
        """Add the lines to C_i, eta_i (:func:`region_kernel`), read from their profiles (:meth:`profile_lines`)
        where the parts moved little since, unless ``afresh``; returns the number of lines used."""
        s, st, person = work.samples, self.settings, tracker.person
        lo, hi, outside, depth = work.limits()
        assert work.profiles is not None  # set by profile_lines()
        likelihood, start, first, length = work.profiles
        return region_kernel(
            work.bins,
            self.grid,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            s.jacobian,
            outside,
            depth,
            twist,
            lo,
            hi,
            max(st.every, 1),
            self.part_table,
            person.mask,
            person.trust,
            self.distinct,
            self.logs,
            st.weight,
            st.sigma**2,
            likelihood,
            start,
            first,
            length,
            afresh,
            work.region_mean,
            work.region_variance,
            work.information,
            work.eta,
        )

    def learn_colours(self, tracker: Tracker, rate: float | None = None) -> None:
        """Count the colours along the lines at the tracker's current poses into the histograms (:func:`learn_kernel`)
        and blend them in at ``rate`` (default ``learning_rate``)."""
        st, work, person = self.settings, tracker.work, tracker.person
        s = work.samples
        lo, hi, outside, depth = work.limits()
        started = time.perf_counter()
        learn_kernel(
            work.bins,
            self.grid,
            s.count,
            s.camera,
            s.component,
            s.pixel,
            s.normal,
            s.jacobian,
            outside,
            depth,
            motion_since(tracker.sampled_poses, tracker.poses),
            lo,
            hi,
            work.region_mean,
            self.histograms.seen,
            st.agree,
            self.inside,
            self.outside,
            person.mask,
            person.trust,
            *self.counts.arrays(),
        )
        h = self.histograms
        h.learn(self.counts, rate=st.learning_rate if rate is None else rate)
        part_table(
            h.foreground,
            h.background,
            h.scale,
            h.seen,
            h.seen_background,
            h.own,
            h.own_size,
            h.backed,
            h.newly_backed,
            h.newly_backed_size,
            self.part_table,
            self.distinct,
        )
        work.times.add("region", started)
