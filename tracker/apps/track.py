"""The library form of ``tracker track``: track a recording folder and write OUT/poses.npz (:func:`track`).

``tracker track`` and ``tracker batch`` resolve their options to a :class:`Tracking` and call :func:`track`; each
prints the :class:`Outcome` with :func:`print_summary`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tracker.errors import TrackerInputError

if TYPE_CHECKING:
    import numpy as np

    from tracker.apps.smoothing import Smoothed
    from tracker.evaluate import Report
    from tracker.io.recording import Recording
    from tracker.tracking.frame_loop import Tracker
    from tracker.tracking.settings import Settings
    from tracker.viewer.review import Review

Bar = Callable[..., Callable[..., Any]]
"""Progress bars: ``bar(desc, unit, leave=False)`` gives the function that wraps an iterable in one."""


@dataclasses.dataclass(frozen=True)
class Tracking:
    """How a recording is tracked: the tracking options of ``tracker track`` (which ``tracker batch`` passes on),
    resolved for the recording."""

    settings: Settings  # the tracker's settings, its frame rate the recording's
    keypoints: int  # the keypoint detector runs on every keypoints-th frame beside the tracker; 0: off
    landmark_model: str  # the detector's landmark model: lite, full or heavy (tracker.landmarks.landmark_models)
    start: int = 0  # first frame
    frames: int | None = None  # frames to track (None: to the end)
    model: str | None = None  # body model TOML (None: the recording's model.toml, else models/human.toml fitted)
    init: str | None = None  # pose at the first frame (None: the recording's init.toml, else fitted to the keypoints)
    background: str = "none"  # none, median, or a folder of <camera>.png: the edges searched in the difference


@dataclasses.dataclass(frozen=True)
class Viewing:
    """The browser viewer following a run: where it listens, its updates a second, the session file it writes."""

    host: str
    port: int
    rate: float
    record: Path | None = None


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What a run of :func:`track` did: what its summary prints, and the viewer left to review it."""

    poses: Path  # the poses.npz written
    frames: int  # frames tracked
    views: int  # cameras tracked in
    iterations: int  # IRLS iterations per frame
    fps: float  # frames per second of the tracking loop (decoding included, start-up not)
    residual: float  # mean residual of the frames, pixels (NaN when no frame found an edge)
    counts: dict[int, int]  # frames per status (tracker.status)
    parts: tuple[str, ...]  # the model's components
    held: np.ndarray  # frames (N,) in which the images held each component (tracker.status.HELD)
    declined: int | None  # re-seeds the edges declined; None without the keypoint cue
    interrupted: bool  # stopped by Ctrl-C, SIGTERM or SIGHUP: the frames done are written
    files: tuple[tuple[Path, str], ...]  # the files the run wrote, each with what it holds
    report: Report | None  # the accuracy against the recording's truth.npz over ``span``, when it has one
    span: range  # the frames asked for (--start, --frames): the frames of the truth the report scores
    unscored: int  # the truth's frames outside ``span``, left out of the report
    smoothed: Smoothed | None = None  # what smoothing the track with the frames after each one did (--smooth)
    review: Callable[[], Review] | None = dataclasses.field(default=None, compare=False)  # view: the review to serve


def print_summary(outcome: Outcome) -> None:
    """What a finished run prints: speed, residual, status counts, what smoothing the track did, the accuracy over the
    frames asked for (and how many frames of the truth that leaves out), and the files it wrote."""
    from tracker.evaluate import format_report
    from tracker.status import LOST, RESEEDED, TRACKED, UNCERTAIN

    print(f"frames per second: {outcome.fps:.1f} ({outcome.views} views, {outcome.iterations} iterations per frame)")
    print(f"mean residual: {outcome.residual:.2f} px (how far the body's outline lies from the image edges it found)")
    counts = outcome.counts
    reseeded = ""
    if outcome.declined is not None:
        declined = f"{outcome.declined} declined by the image or the landmarks"
        reseeded = f", {counts[RESEEDED]} re-seeded from the keypoints ({declined})"
    print(f"status: {counts[TRACKED]} tracked, {counts[UNCERTAIN]} uncertain, {counts[LOST]} lost{reseeded}")
    if outcome.frames:
        print(held_summary(outcome.parts, outcome.held, outcome.frames))
    smoothed = outcome.smoothed
    if smoothed is not None and smoothed.method == "both-ways":
        print(
            f"smoothed ({smoothed.method}, {smoothed.seconds:.1f} s): tracked back from the last frame, the backward "
            f"track's pose kept in {smoothed.taken} of {smoothed.frames} frames, then the whole track smoothed"
        )
    elif smoothed is not None:
        print(f"smoothed ({smoothed.method}, {smoothed.seconds:.1f} s) over the whole recording")
    if outcome.report is not None:
        scored = f"accuracy against the recording's truth.npz over frames {outcome.span.start}..{outcome.span.stop - 1}"
        if outcome.unscored:
            print(f"{scored}, the ones asked for; its other {outcome.unscored} frames were not tracked")
            print("(--start, --frames) and are left out here, while tracker eval counts them as lost:")
        else:
            print(f"{scored}:")
        print(format_report(outcome.report))
    width = max(len(str(path)) for path, _ in outcome.files)
    print("files of this run:")
    for path, holds in outcome.files:
        print(f"  {str(path):<{width}}  {holds}")


def held_summary(parts: Sequence[str], held: np.ndarray, frames: int) -> str:
    """One line on the parts the images held over a run of ``frames`` frames, given the frames (N,) in which they
    held each of ``parts``: their share of all the parts' frames, and the parts left to the prior and the joints
    in half the frames or more, the most often first, each with its frames."""
    share = float(held.sum()) / (len(parts) * frames) if parts else 0.0
    line = f"parts held by the images: {100.0 * share:.0f} % of {len(parts)} parts x {frames} frames"
    left = [(frames - int(count), name) for name, count in zip(parts, held) if 2 * (frames - count) >= frames]
    if not left:
        return line
    left.sort(key=lambda item: -item[0])
    named = ", ".join(f"{name} {count}" for count, name in left)
    return f"{line}; by the prior only in half the frames or more: {named} (frames)"


def track(
    rec: Recording,
    tracking: Tracking,
    *,
    out: Path,
    overlay: str | None = None,
    view: Viewing | None = None,
    bar: Bar | None = None,
) -> Outcome:
    """Track ``rec`` as ``tracking`` says and write OUT/poses.npz (``out``, with the model, keypoints and background
    made on the way); after Ctrl-C, SIGTERM or SIGHUP (:mod:`tracker.stop_signals`), the frames done are written and
    the outcome says it was interrupted.

    ``overlay``: also write a video of every camera with the tracked outlines and edge searches; ``view``: show
    the run in the browser viewer, which then reviews it (:attr:`Outcome.review`); ``bar(desc, unit, leave=)``
    gives the progress bars (default none)."""
    import numpy as np

    from tracker.apps.keypoint_stream import beside, tracked_frames
    from tracker.apps.loop import Tracked, track_frames
    from tracker.atomic import ensure_writable_folder
    from tracker.evaluate import evaluate, truth_within
    from tracker.io.posefile import starting_pose_file
    from tracker.io.poses import load_poses
    from tracker.io.readers import split_kept
    from tracker.io.recording import capture_times
    from tracker.status import HELD, LOST, RESEEDED, TRACKED, UNCERTAIN
    from tracker.tracking.edge_cue import reductions
    from tracker.tracking.frame_loop import Tracker

    bar = bar or _no_bar
    start, settings, step = tracking.start, tracking.settings, tracking.keypoints
    if not 0 <= start < rec.frame_count:
        raise TrackerInputError(
            f"{rec.path}: --start {start} is outside its frames 0..{rec.frame_count - 1}; pick a frame inside them"
        )
    stop = rec.frame_count if tracking.frames is None else min(rec.frame_count, start + tracking.frames)
    asked = range(start, stop)
    pose_file = starting_pose_file(start, tracking.init, rec.init_path, by_itself=bool(step))
    model = _model(tracking.model, rec, out, step, bar, tracking.landmark_model)
    background = _background(tracking.background, rec, out, bar)
    init, begin, back_to = _first_pose(pose_file, start, rec, model, stop, out, settings, step, tracking.landmark_model)
    ensure_writable_folder(out)  # a folder that cannot be written fails now, not at the first save
    print(
        f"tracking {rec.path} frames {back_to}..{stop - 1} with {len(rec.cameras)} camera(s) "
        f"({', '.join(c.name for c in rec.cameras)}), model {model.name!r} ({model.size} components)",
        file=sys.stderr,
    )
    times = capture_times(rec)  # a live recording's capture times: its frames' time and time steps
    timed = None if times is None else lambda index: float(times[index])
    pairing = rec.pairing  # cameras not frame-locked: each view's frame and how late it was captured
    late = None if pairing is None else lambda index: pairing.late[index]
    measured: dict[int, np.ndarray] = {}  # each frame's information about its poses (Tracker.measured), by frame
    back = TrackedBack(None, 0, False)
    if back_to < begin:
        from tracker.seeding.first_pose import FRAMES

        back = _tracked_back(
            rec,
            tracking,
            model,
            init,
            span=(back_to, begin, min(stop, begin + 2 * FRAMES)),
            out=out,
            background=background,
            times=timed,
            late=late,
            bar=bar,
            measured=measured,
        )
    before = back.rows
    if back.mended is not None:  # the forward pass starts from the first pose as the settling mended it
        init = back.mended
    if back.interrupted:  # Ctrl-C while tracking back: the frames tracked back are written, and no others
        stop = begin
    # the detector starts up while the kernels load; fed the tracker's own images unless they are differences
    stream = _keypoints(
        rec,
        begin,
        stop,
        out,
        step if stop > begin else 0,
        None if background is not None else reductions(settings, rec.cameras),
        tracking.landmark_model,
    )
    video = None
    with contextlib.ExitStack() as closing:  # each closed however the run ends, the stream keeping what was detected
        recovery = None
        if stream is not None:
            closing.callback(stream.close)
            from tracker.seeding.recovery import Recovery

            recovery = Recovery(model, rec.cameras)
        print("preparing the numba kernels (compiled once, then cached)...", file=sys.stderr, flush=True)
        tracker = Tracker(model, rec.cameras, init, settings)
        tracker.measuring = settings.smoothing.method != "none"  # the smoother weighs each frame by it
        tracker.warm_up()
        truth = load_poses(rec.truth_path) if rec.truth_path is not None else None
        live = _live_view(view, rec, tracker, truth) if view is not None else None
        if live is not None:
            closing.callback(live.close)
        if overlay:
            from tracker.viewer.overlay import OverlayVideo

            video = OverlayVideo(Path(overlay), rec.cameras, rec.fps, model.size, settings.solve.robust_c)
            closing.callback(video.close)
        # the overlay and the viewer draw on the frames as they are, not on what the edge search reads (smoothed,
        # reduced at HD, or colour differences)
        shows = video is not None or live is not None
        prepare = _preparer(tracker, background, keep=shows)
        counts = {TRACKED: 0, UNCERTAIN: 0, LOST: 0, RESEEDED: 0}
        held = np.zeros(model.size, np.int64)
        residuals = []
        if before is not None:
            for status in before["status"]:
                counts[int(status)] += 1
            held += (before["held"] == HELD).sum(axis=0)
            residuals.extend(before["residual"])
        grey: Sequence[np.ndarray] = ()  # the frame in hand as recorded, for the overlay and the viewer

        def searched(read):
            """The frames as the edge search reads them, the frames as recorded kept aside in ``grey``."""
            nonlocal grey
            for index, images in read:
                if shows:
                    grey, images = zip(*(split_kept(image) for image in images))
                yield index, images

        def counted_and_shown(frame: Tracked) -> None:
            """Count the frame's status and residual, and draw it in the overlay and the viewer."""
            images = grey if shows else frame.images
            if live is not None:
                live.offer(frame.index, images, frame.result, elapsed=frame.spent)
            if video is not None:
                video.write(images, tracker.inspect(), frame.result.held)
            counts[frame.result.status] += 1
            held[:] += frame.result.held == HELD
            residuals.append(frame.result.residual)
            if frame.result.information is not None:
                measured[frame.index] = frame.result.information.astype(np.float32)

        progress = bar(None, "frame", leave=True)
        read = tracked_frames(
            stream,
            rec,
            start=begin,
            stop=stop,
            prepare=prepare,
            colour=background is not None,
            chroma=tracker.bin_colours if settings.region.on and background is None else False,
        )
        run = track_frames(
            tracker,
            progress(searched(read), total=stop - begin),
            out / "poses.npz",
            fps=rec.fps,
            keypoints=None if stream is None else beside(stream, tracker),
            check=recovery,
            times=timed,
            late=late,
            each=counted_and_shown,
            before=before,
        )
    done = run.frames + (0 if before is None else len(before["frame"]))
    poses = out / "poses.npz"
    smoothed = None
    if settings.smoothing.method != "none" and not run.interrupted and not back.interrupted and done > 1:
        smoothed = _smoothed(
            rec,
            tracking,
            model,
            span=(begin, stop),
            out=out,
            background=background,
            measured=measured,
            times=timed,
            late=late,
            bar=bar,
        )
    interrupted = run.interrupted or back.interrupted or (smoothed is not None and smoothed.interrupted)
    if smoothed is not None and not smoothed.interrupted:  # the frames as written: some from the backward track
        written = load_poses(poses)
        counts = {status: int((written["status"] == status).sum()) for status in counts}
        residuals = list(written["residual"])
    results = load_poses(poses) if not interrupted and (truth is not None or live is not None) else None
    scored = None if truth is None else truth_within(truth, asked.start, asked.stop)
    report = evaluate(results, scored) if results is not None and scored is not None else None
    review: Callable[[], Review] | None = None
    if live is not None and results is not None and done > 0:
        from tracker.viewer.review import Review

        def shown_review() -> Review:
            shown = Review(live.scene, rec, tracker, results, truth)
            shown.show(done - 1)
            return shown

        review = shown_review

    return Outcome(
        poses=poses,
        frames=done,
        views=len(rec.cameras),
        iterations=settings.solve.iterations,
        fps=run.frames / run.seconds if run.seconds > 0 else float("inf"),
        residual=float(np.nanmean(residuals)) if np.isfinite(residuals).any() else float("nan"),
        counts=counts,
        parts=model.names,
        held=held,
        declined=None if recovery is None else recovery.declined + back.declined,
        interrupted=interrupted,
        files=_files(rec, tracking, out, frames=done, overlay=overlay, view=view),
        report=report,
        span=asked,
        unscored=0 if truth is None or scored is None else len(truth["joints"]) - len(scored["joints"]),
        smoothed=smoothed,
        review=review,
    )


def _files(
    rec, tracking: Tracking, out: Path, *, frames: int, overlay: str | None, view: Viewing | None
) -> tuple[tuple[Path, str], ...]:
    """The files a run of ``tracking`` on ``rec`` wrote (in ``out``, and ``overlay`` and ``view``'s recording when
    asked for), each with what it holds for the user."""
    from tracker.landmarks.detect_recording import cache_file

    files = [(out / "poses.npz", f"the pose of each of the {frames} frames: tracker view, eval and export read it")]
    if _fitted(tracking.model, rec):
        files.append((out / "model.toml", "the body model fitted to the person: pass it with --model to reuse it"))
    keypoints = cache_file(out, rec, tracking.landmark_model)
    if tracking.keypoints and keypoints.is_file():
        files.append((keypoints, "the keypoint detector's landmarks, reused when this recording is tracked again"))
    if tracking.background == "median":
        files.append((out / "background", "the empty scene: pass it with --background to reuse it"))
    if overlay:
        files.append((Path(overlay), "the tracked outlines drawn over every camera's video"))
    if view is not None and view.record is not None:
        files.append((view.record, "the viewer session: it plays in a browser without the tracker"))
    return tuple(files)


BACK_CHUNK = 30
"""Frames read at a time, then tracked last to first, when tracking back from the first pose (:func:`_tracked_back`)
or from the last frame (:func:`_tracked_from_the_end`, which reads the next chunk while one is tracked): they are held
in memory, as smoothed images, until tracked."""


@dataclasses.dataclass(frozen=True)
class TrackedBack:
    """What :func:`_tracked_back` did: the rows tracked back, of a poses.npz in frame order (None if none was), the
    re-seeds its recovery declined, whether Ctrl-C stopped it, and the poses it passed the first pose's frame with
    (None if it did not): the first pose as the settling mended it."""

    rows: dict[str, Any] | None
    declined: int
    interrupted: bool
    mended: np.ndarray | None = None


def nearer_landmarks(
    tracker: Tracker, mended: np.ndarray, *, fitted: np.ndarray, keypoints: tuple[np.ndarray, np.ndarray]
) -> np.ndarray | None:
    """``mended``, the first pose as the settling before tracking back left it, unless the first frame's landmarks
    ``keypoints`` (pixels, confidence) lie nearer the ``fitted`` first pose (:meth:`tracker.tracking.keypoint_cue.
    KeypointCue.misfit`): then None, and the forward pass starts from the fitted pose.  The settling can stray, a limb
    taken off to clutter while the trunk holds (docs/keypoints.md, "Automatic first pose")."""
    misfit = tracker.landmarks.misfit
    if misfit(tracker, mended, keypoints) > misfit(tracker, fitted, keypoints):
        return None
    return mended


def _tracked_back(
    rec,
    tracking: Tracking,
    model,
    init,
    *,
    span: tuple[int, int, int],
    out: Path,
    background,
    times,
    late,
    bar,
    measured: dict[int, np.ndarray],
) -> TrackedBack:
    """The frames ``span`` = (first, begin, settled) before the first pose ``init`` (at frame ``begin``) tracked
    backwards: the tracker settles on the first pose over the frames from ``begin`` to ``settled`` - 1 (the first
    pose's own :data:`tracker.seeding.first_pose.FRAMES` frames and as many again, so that a limb the fit left off
    is mended), turns round, its motion dropped, and tracks back to ``first``, the last frame first, with its own
    detections and recovery, reading :data:`BACK_CHUNK` frames at a time.  Time runs backwards there: the loop is
    given the capture times ``times(index)`` (a live recording's) negated, so that its steps are forward in that
    time, and the rows get them back; so is each view's lateness ``late(index)`` there (a camera late is early in
    that time).  The rows are written to OUT/poses.npz at once, so that Ctrl-C from here on
    keeps them; so does a stop (Ctrl-C, SIGTERM, SIGHUP) between the backward run and that write, while the
    detector's landmarks of the first pose's frame are waited for or the detector is closed.  With smoothing
    (``Settings.smoothing``), each frame tracked back leaves its information in ``measured`` by frame."""
    import tempfile

    import numpy as np

    from tracker.apps.keypoint_stream import beside, tracked_frames
    from tracker.apps.loop import track_frames
    from tracker.io.poses import load_poses
    from tracker.tracking.frame_loop import Tracker

    first, begin, settled = span
    settings = tracking.settings

    def read(start: int, stop: int) -> list:
        return list(
            tracked_frames(
                None, rec, start=start, stop=stop, prepare=prepare, colour=background is not None, chroma=chroma
            )
        )

    def settling():
        yield from read(begin, settled)

    def backwards():
        for stop in range(settled - 1, first, -BACK_CHUNK):
            yield from reversed(read(max(first, stop - BACK_CHUNK), stop))

    def tracked(frames, path: Path, total: int, way: int):
        return track_frames(
            tracker,
            bar(f"back to frame {first}", "frame")(frames, total=total),
            path,
            fps=rec.fps,
            keypoints=None if stream is None else beside(stream, tracker),
            check=recovery,
            times=None if times is None else lambda index: -times(index),
            late=None if late is None else lambda index: way * late(index),
            each=measuring,
        )

    def measuring(frame) -> None:
        if frame.result.information is not None and frame.index < begin:
            measured[frame.index] = frame.result.information.astype(np.float32)

    print(f"tracking back from frame {begin} to frame {first}", file=sys.stderr)
    recovery, judged = None, None
    with tempfile.TemporaryDirectory(prefix="tracked-back-") as folder:
        path = Path(folder) / "poses.npz"
        stream = _keypoints(rec, first, settled, out, tracking.keypoints, None, tracking.landmark_model)
        try:
            with contextlib.ExitStack() as closing:
                if stream is not None:
                    closing.callback(stream.close)
                    from tracker.seeding.recovery import Recovery

                    recovery = Recovery(model, rec.cameras)
                tracker = Tracker(model, rec.cameras, init, settings)
                tracker.measuring = settings.smoothing.method != "none"
                tracker.warm_up()
                prepare = _preparer(tracker, background, keep=False)
                chroma = tracker.bin_colours if settings.region.on and background is None else False
                run = tracked(settling(), Path(folder) / "settled.npz", settled - begin, 1)
                if not run.interrupted:
                    tracker.restart(tracker.poses)  # the motion so far points the other way
                    run = tracked(backwards(), path, settled - 1 - first, -1)
                interrupted = run.interrupted
                if stream is not None and not interrupted:
                    judged = stream.get(begin)
        except KeyboardInterrupt:  # a stop once tracked back (waiting for the detector, closing it): the frames kept
            if not path.is_file():
                raise
            interrupted = True
        found = load_poses(path) if path.is_file() else None
    declined = 0 if recovery is None else recovery.declined
    if found is None or not (found["frame"] < begin).any():
        return TrackedBack(None, declined, interrupted)
    at = np.flatnonzero(found["frame"] == begin)
    mended = found["poses"][at[0]] if len(at) else None
    if mended is not None and judged is not None:
        mended = nearer_landmarks(tracker, mended, fitted=init, keypoints=judged)
    kept = np.flatnonzero(found["frame"] < begin)
    kept = kept[np.argsort(found["frame"][kept])]
    keys = ("frame", "poses", "joints", "status", "held", "residual", "elapsed", "time")
    rows = {key: found[key][kept] for key in keys}
    rows["time"] = -rows["time"]
    track_frames(tracker, (), out / "poses.npz", fps=rec.fps, times=times, before=rows)
    return TrackedBack(rows, declined, interrupted, mended)


def _smoothed(
    rec, tracking: Tracking, model, *, span: tuple[int, int], out: Path, background, measured, times, late, bar
) -> Smoothed:
    """The track in OUT/poses.npz judged with the frames after each one, as ``Settings.smoothing.method`` says
    (:mod:`tracker.apps.smoothing`), and the file replaced by the result; ``measured``: each frame's information
    (:meth:`tracker.tracking.frame_loop.Tracker.measured`) by frame.  With ``both-ways`` the frames ``span`` =
    (begin, stop), the forward run's, are tracked back from the last, reading :data:`BACK_CHUNK` frames at a time;
    the frames before them, tracked back from the first pose already, stay as they are.  A stop (Ctrl-C, SIGTERM,
    SIGHUP) leaves the file as the forward run wrote it."""
    import os
    import tempfile
    import time

    import numpy as np

    from tracker import stop_signals
    from tracker.apps.smoothing import Smoothed, Track, smoothing_input
    from tracker.io.poses import PosesWriter, load_poses
    from tracker.model import joint_centres
    from tracker.tracking.smoother import smoothed_track

    settings = tracking.settings
    method = settings.smoothing.method
    begin, stop = span
    path = out / "poses.npz"
    rows = load_poses(path)
    empty = np.zeros((model.size, 2, 3, 3))
    track = Track(
        rows["frame"],
        rows["poses"],
        rows["status"],
        rows["residual"],
        rows["elapsed"],
        np.stack([measured.get(int(frame), empty) for frame in rows["frame"]]),
        rows.get("held"),
    )
    starts, taken, started = track.restarts(), 0, time.perf_counter()
    try:
        if method == "both-ways":
            back = _tracked_from_the_end(
                rec, tracking, model, track, span=span, out=out, background=background, times=times, late=late, bar=bar
            )
            if back.interrupted:
                return Smoothed(method, time.perf_counter() - started, len(back.taken), int(back.taken.sum()), True)
            within = slice(int(np.searchsorted(track.frame, begin)), int(np.searchsorted(track.frame, stop)))
            keys = ("frame", "poses", "status", "residual", "elapsed", "information")
            track = dataclasses.replace(
                track,
                **{
                    key: np.concatenate([getattr(track, key)[: within.start], getattr(back.track, key)])
                    for key in keys + (("held",) if track.held is not None and back.track.held is not None else ())
                },
            )
            starts = np.concatenate([starts[: within.start], back.starts])
            taken = int(back.taken.sum())
        poses = smoothed_track(
            model,
            track.poses,
            smoothing_input(track),
            times=rows["time"],
            starts=starts,
            motion=settings.motion,
            scale=settings.smoothing.noise_scale,
        )
        with tempfile.TemporaryDirectory(prefix="smoothed-", dir=path.parent) as folder:
            smoothed = Path(folder) / "poses.npz"
            with PosesWriter(smoothed, list(model.names), list(model.joint_names), rec.fps) as writer:
                for row, frame in enumerate(track.frame):
                    writer.append(
                        int(frame),
                        poses[row],
                        joint_centres(poses[row]),
                        status=int(track.status[row]),
                        residual=float(track.residual[row]),
                        elapsed=float(track.elapsed[row]),
                        time=None if times is None else float(rows["time"][row]),
                        held=None if track.held is None else track.held[row],
                    )
            os.replace(smoothed, path)
    except (KeyboardInterrupt, SystemError) as error:  # a stop while smoothing or writing: the forward track stays
        if not stop_signals.stopped_within(error):
            raise
        return Smoothed(method, time.perf_counter() - started, len(track.frame), taken, True)
    return Smoothed(method, time.perf_counter() - started, len(track.frame), taken, False)


def _tracked_from_the_end(
    rec, tracking: Tracking, model, forward, *, span: tuple[int, int], out: Path, background, times, late, bar
):
    """The frames ``span`` = (begin, stop) of the ``forward`` track (:class:`tracker.apps.smoothing.Track`) tracked
    back from its pose at the last, with the forward run's detections (cached in OUT) and a recovery of their own
    (:func:`tracker.apps.smoothing.track_backwards`)."""
    import numpy as np

    from tracker.apps.keypoint_stream import beside, tracked_frames
    from tracker.apps.smoothing import track_backwards
    from tracker.tracking.frame_loop import Tracker

    begin, stop = span
    settings = tracking.settings
    stream = _keypoints(rec, begin, stop, out, tracking.keypoints, None, tracking.landmark_model)
    with contextlib.ExitStack() as closing:
        recovery = None
        if stream is not None:
            closing.callback(stream.close)
            from tracker.seeding.recovery import Recovery

            recovery = Recovery(model, rec.cameras)
        last = int(np.flatnonzero(forward.frame == stop - 1)[0])
        tracker = Tracker(model, rec.cameras, forward.poses[last], settings)
        tracker.measuring = True
        tracker.warm_up()
        prepare = _preparer(tracker, background, keep=False)
        chroma = tracker.bin_colours if settings.region.on and background is None else False

        def read(start: int, end: int) -> list:
            return list(
                tracked_frames(
                    None, rec, start=start, stop=end, prepare=prepare, colour=background is not None, chroma=chroma
                )
            )

        def backwards():
            """The frames last to first, :data:`BACK_CHUNK` at a time, the next chunk read while one is tracked."""
            from concurrent.futures import ThreadPoolExecutor

            ends = list(range(stop, begin, -BACK_CHUNK))
            with ThreadPoolExecutor(1) as reader:
                ahead = reader.submit(read, max(begin, ends[0] - BACK_CHUNK), ends[0])
                for k in range(len(ends)):
                    chunk = ahead.result()
                    if k + 1 < len(ends):
                        ahead = reader.submit(read, max(begin, ends[k + 1] - BACK_CHUNK), ends[k + 1])
                    yield from reversed(chunk)

        print(f"smoothing: tracking back from frame {stop - 1} to frame {begin}", file=sys.stderr)
        return track_backwards(
            tracker,
            bar("tracking back from the last frame", "frame")(backwards(), total=stop - begin),
            forward=forward,
            keypoints=None if stream is None else beside(stream, tracker),
            check=recovery,
            times=times,
            late=late,
        )


def _preparer(tracker, background, *, keep: bool):
    """What the readers make of each frame for ``tracker``: its smoothing, of the frame itself or of its difference
    from ``background`` (:func:`tracker.tracking.foreground.preparers`), one per camera; with ``keep``, each also keeps
    the grey frame as recorded, for the overlay and the viewer (:func:`tracker.io.readers.keeping_grey`)."""
    from tracker.io.readers import keeping_grey

    if background is None:
        return keeping_grey(tracker.smooth) if keep else tracker.smooth
    from tracker.tracking.foreground import preparers

    measured = preparers(background, tracker.smooth)
    return [keeping_grey(camera) for camera in measured] if keep else list(measured)


def _fitted(given: str | None, rec) -> bool:
    """Whether a run fits the body model to the person: no ``--model`` (``given``) and no model.toml in ``rec``."""
    return not given and rec.model_path is None


def _model(given: str | None, rec, out: Path, step: int, bar: Bar, landmark_model: str):
    """The body model: ``given`` (``--model``), else the recording's model.toml, else models/human.toml fitted to the
    person (:func:`tracker.shape.model_fit.fit_and_save`, with the landmarks of ``landmark_model``), written to
    OUT/model.toml."""
    from tracker.model import load_model

    if not _fitted(given, rec):
        return load_model(given or rec.model_path)
    from tracker.atomic import ensure_writable_folder
    from tracker.landmarks.detect_recording import cache_file
    from tracker.landmarks.detector import missing
    from tracker.shape.model_fit import GENERIC, fit_and_save
    from tracker.tomlfile import read_toml

    reason = missing() if step else "--keypoints off"
    if reason is not None:
        raise TrackerInputError(
            f"{rec.path}: no model.toml in the recording folder, and fitting one needs the keypoint detector "
            f"({reason}); pass --model"
        )
    path = ensure_writable_folder(out) / "model.toml"
    print(f"model: no model.toml, fitting {GENERIC.name} to the person in {rec.path}", file=sys.stderr)
    fit_and_save(
        rec,
        read_toml(GENERIC, "model", "reinstall the tracker: models/human.toml is part of it"),
        path,
        source=str(GENERIC),
        cache=cache_file(path.parent, rec, landmark_model),
        landmark_model=landmark_model,
        progress=bar("fitting the model", "step"),
        say=lambda line: print(line, file=sys.stderr),
    )
    print(f"model: wrote {path}; pass it with --model to reuse it", file=sys.stderr)
    return load_model(path)


def _first_pose(
    pose_file: Path | None, start: int, rec, model, stop: int, out: Path, settings, step: int, landmark_model: str
):
    """The pose at the first frame, that frame (``start``, or later) and the first frame to track back to from it:
    the pose in ``pose_file`` (``--init`` or the recording's init.toml, the pose at frame ``start``:
    :func:`tracker.io.posefile.starting_pose_file`), else fitted to the keypoints of the first frames
    (:func:`tracker.seeding.first_pose.first_pose`, detections by ``landmark_model`` cached in OUT/keypoints.npz).
    When they cannot place the body, the detector tries the next frames if it saw someone in them (a body cut by the
    borders, in one view only, or in views that face each other), else a second of frames later, and tracking starts
    where the body is first placed; the frames before it back to the first of those in which someone was seen, one
    try after another, are tracked backwards from it (:func:`_tracked_back`)."""
    from tracker.io.posefile import load_pose_file

    if pose_file is not None:
        return load_pose_file(pose_file, model), start, start
    if not step:
        raise TrackerInputError(
            f"{rec.path}: no init.toml in the recording folder and --keypoints off; pass --init, or let the "
            "keypoint detector find the first pose (--keypoints every or N)"
        )
    from tracker.atomic import ensure_writable_folder
    from tracker.landmarks.detect_recording import cache_file, detect_recording
    from tracker.seeding.first_pose import FRAMES, first_pose

    cache = cache_file(ensure_writable_folder(out), rec, landmark_model)
    last_begin = max(start, stop - FRAMES)
    begin, back_to = start, None  # back_to: the first frame someone was seen in, try after try up to now
    lacking = "no init.toml" if rec.init_path is None else f"no init.toml of frame {start}"
    while True:
        last = min(stop, begin + FRAMES)
        print(
            f"first pose: {lacking}, fitting the body to the keypoints of frames {begin}..{last - 1}", file=sys.stderr
        )
        keypoints, _ = detect_recording(rec, begin, last, cache=cache, landmark_model=landmark_model)
        found = keypoints.frame[(keypoints.confidence > 0).any(axis=(1, 2))]
        seen = len(found) > 0
        if not seen:  # nobody here: nothing before to track back to
            back_to = None
        elif back_to is None:
            back_to = int(found.min())
        try:
            return first_pose(rec, model, keypoints, settings=settings), begin, begin if back_to is None else back_to
        except TrackerInputError as error:
            if len(rec.cameras) < 2 or begin == last_begin:
                raise
            begin = min(begin + FRAMES if seen else begin + max(1, round(rec.fps)), last_begin)
            when = "with the next frames, where someone was seen" if seen else "a second later"
            print(f"first pose: {error}; trying again {when}", file=sys.stderr)


def _keypoints(rec, begin: int, stop: int, out: Path, step: int, reduction, landmark_model: str):
    """The detector's stream of every ``step``-th frame (``--keypoints``) by ``landmark_model``, cached in
    OUT/keypoints.npz (:func:`tracker.landmarks.detect_recording.cache_file`), or None (off); fed the tracker's
    images, reduced by ``reduction``, unless that is None."""
    if not step:
        return None
    from tracker.apps.keypoint_stream import KeypointStream, schedule_words
    from tracker.atomic import ensure_writable_folder
    from tracker.landmarks.detect_recording import cache_file

    cache = cache_file(ensure_writable_folder(out), rec, landmark_model)
    stream = KeypointStream(rec, begin, stop, step, cache, reduction, landmark_model=landmark_model)
    every = schedule_words(step)
    source = f"reused from {stream.cache}" if stream.reused is not None else "detected beside the tracker"
    print(f"keypoints: {every}, {source} (BlazePose {landmark_model})", file=sys.stderr)
    return stream


def _background(given: str, rec, out: Path, bar: Bar):
    """The background of the run (``given``, ``--background``): None, the median of the recording (also saved
    under ``out``), or a folder."""
    if given == "none":
        return None
    from tracker.atomic import ensure_writable_folder
    from tracker.tracking.foreground import SAMPLES, load_background, median_background, sample_indices, save_background

    if given != "median":
        return load_background(given, rec)
    ensure_writable_folder(out)  # before the frames are read, not after
    background = median_background(rec, SAMPLES, bar("background", "frame"))
    folder = save_background(background, rec, out / "background")
    print(
        f"background: per-pixel median of {len(sample_indices(rec.frame_count, SAMPLES))} frames per camera, "
        f"saved in {folder} "
        f"(reuse with --background {folder})",
        file=sys.stderr,
    )
    return background


def _live_view(view: Viewing, rec, tracker, truth):
    """The viewer following the run of ``tracker`` (``--view``, ``--view-rate``, ``--record``), with the truth's
    joints."""
    import numpy as np

    from tracker.viewer.live_view import LiveView
    from tracker.viewer.review import truth_rows
    from tracker.viewer.scene import Scene, start_server

    names = None if truth is None else list(truth["joint_names"])
    return LiveView(
        Scene(start_server(view.host, view.port), tracker.model, rec.cameras, tracker.settings.solve.robust_c, names),
        tracker,
        rate=view.rate,
        truth=truth_rows(truth, np.arange(rec.frame_count)),
        record=view.record,
    )


def _no_bar(desc: str | None, unit: str, *, leave: bool = False) -> Callable[..., Any]:
    """No progress bar: a :data:`Bar` that shows nothing."""
    from tqdm import tqdm

    return functools.partial(tqdm, desc=desc, unit=unit, disable=True, leave=leave)
