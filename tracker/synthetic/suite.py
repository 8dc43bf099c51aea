"""The hard suite: renders that do not flatter the tracker, and their scores (docs/suite.md).

:data:`SUITE` lists the renders as data: a rig of ``calib/``, a motion (a CMU clip, the procedural
turn or the athletic hops, kicks and spins) at some frame rate, and a :class:`tracker.synthetic.synth.Staging`
combining a few hardships: clothing textures, capsule bodies of perturbed sizes, tables hiding the
legs, bodies cut by the image border or far away, motion blur, low frame rates. Every body has a
face; every render but one stands in an empty furnished room (:mod:`tracker.synthetic.room`), and that one
over the background photos, whose people are larger than the body (bystanders). :func:`make` renders
them into OUT/<name>/ as normal recording folders without an ``init.toml`` (the true first pose is
``truth_init.toml``), and :func:`score` reads RESULTS/<name>/poses.npz against each truth.npz.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from tracker.camera import load_calibration
from tracker.errors import TrackerInputError
from tracker.evaluate import Report, evaluate
from tracker.io.poses import load_poses
from tracker.landmarks.detect_recording import cache_name
from tracker.landmarks.landmark_models import RECORDED
from tracker.landmarks.store import load_keypoints
from tracker.model import load_model
from tracker.synthetic.detector_baseline import Baseline, baseline
from tracker.synthetic.synth import Staging, synthesize

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "human.toml"
"""The tracking model every render plays (and every recording's model.toml)."""
CALIB = ROOT / "calib"
"""The rigs, ``calib/<rig>.toml``."""

CLIPS = ("131_01.bvh", "131_02.bvh")
"""The CMU clips the suite reads from the folder given to :func:`make` (subject 131, start-walk-stop)."""


@dataclass(frozen=True)
class Render:
    """One render of the suite: ``name`` (its folder), ``hard`` (what is hard, for people), ``rig`` (a
    ``calib/`` stem), ``motion`` (a clip of :data:`CLIPS`, ``procedural`` or ``athletic``), ``frames``,
    the clip's ``start`` and ``stride`` (120 Hz / stride = fps) or the procedural ``fps``, ``seed``
    and ``staging``."""

    name: str
    hard: str
    rig: str
    motion: str
    frames: int
    start: int = 0
    stride: int = 2
    fps: float = 60.0
    seed: int = 0
    staging: Staging = Staging()

    @property
    def rate(self) -> float:
        """Frames per second of the render (CMU clips are 120 Hz)."""
        return 120.0 / self.stride if self.motion in CLIPS else self.fps


SUITE = (
    Render(
        "walk-capsules-stripes",
        "capsule body (+-10 %) in stripes, 30 fps walk",
        "demo3",
        "131_02.bvh",
        120,
        start=200,
        stride=4,
        seed=1,
        staging=Staging(texture="stripes", body="capsules", backdrop="room", face=True),
    ),
    Render(
        "dance-print-bystanders",
        "crouching dance in a printed costume at 30 fps over photos of people larger than the body",
        "ring4",
        "131_01.bvh",
        120,
        start=300,
        stride=4,
        seed=2,
        staging=Staging(texture="print", face=True),
    ),
    Render(
        "table-booth",
        "tables before every camera hide the legs; high corner cameras; mottled clothes",
        "corner3",
        "procedural",
        120,
        fps=30.0,
        seed=3,
        staging=Staging(texture="noise", tables=("all",), backdrop="room", face=True),
    ),
    Render(
        "far-walk",
        "cameras 2.5 times as far (the body about 70 px tall), capsule body",
        "demo3",
        "131_02.bvh",
        120,
        start=500,
        stride=2,
        seed=4,
        staging=Staging(body="capsules", distance=2.5, backdrop="room", face=True),
    ),
    Render(
        "webcam-8fps",
        "8 fps with webcam motion blur, mottled clothes, high corner cameras",
        "corner3",
        "131_01.bvh",
        60,
        start=40,
        stride=15,
        seed=5,
        staging=Staging(texture="noise", motion_blur=6, shutter=0.5, backdrop="room", face=True),
    ),
    Render(
        "border-cut",
        "zoomed 2.8 times: every view cuts the body, and at times the feet leave them all; stripes; 30 fps",
        "ring4",
        "131_02.bvh",
        120,
        start=560,
        stride=4,
        seed=6,
        staging=Staging(texture="stripes", zoom=2.8, backdrop="room", face=True),
    ),
    Render(
        "kick-spin-blur",
        "hops, kicks and jump spins at 30 fps with motion blur, printed costume",
        "demo3",
        "athletic",
        120,
        fps=30.0,
        seed=7,
        staging=Staging(texture="print", motion_blur=8, shutter=0.5, backdrop="room", face=True),
    ),
    Render(
        "athletic-capsules",
        "hops, kicks and spins at 30 fps by a capsule body in mixed patterns, high corner cameras",
        "corner3",
        "athletic",
        120,
        fps=30.0,
        seed=8,
        staging=Staging(texture="mixed", body="capsules", backdrop="room", face=True),
    ),
    Render(
        "athletic-10fps",
        "hops, kicks and spins at 10 fps, stripes",
        "ring4",
        "athletic",
        90,
        fps=10.0,
        seed=9,
        staging=Staging(texture="stripes", backdrop="room", face=True),
    ),
    Render(
        "turn-6fps-table",
        "the procedural turn at 6 fps, a table before cam0, mixed patterns",
        "ring4",
        "procedural",
        72,
        fps=6.0,
        seed=10,
        staging=Staging(texture="mixed", tables=("cam0",), backdrop="room", face=True),
    ),
)
"""The suite, in the order it is made and scored."""


def select(names: list[str] | None) -> list[Render]:
    """The renders named (all when None), in suite order; an unknown name, or none, is a TrackerInputError."""
    if names is None:
        return list(SUITE)
    known = {render.name for render in SUITE}
    if not names:
        raise TrackerInputError(f"the list of renders names none; pick from {', '.join(sorted(known))}")
    unknown = [name for name in names if name not in known]
    if unknown:
        raise TrackerInputError(f"no render {unknown[0]!r} in the suite; pick from {', '.join(sorted(known))}")
    return [render for render in SUITE if render.name in names]


def make(
    out: str | os.PathLike,
    renders: list[Render],
    *,
    clips: str | os.PathLike | None = None,
    frames: int | None = None,
    progress: bool = True,
) -> list[dict]:
    """Render ``renders`` into ``out``/<name>/ (no init.toml; truth_init.toml holds the first true pose), each
    replacing the suite's render of that name made before.

    ``clips``: the folder holding :data:`CLIPS` (needed by the renders of CMU motion); ``frames``:
    render only the first ``frames`` of each (a quick look). Returns :func:`tracker.synthetic.synth.synthesize`'s
    summary per render.
    """
    needed = sorted({render.motion for render in renders if render.motion in CLIPS})
    absent = [clip for clip in needed if clips is None or not (Path(clips) / clip).is_file()]
    if absent:
        where = "no clips folder was given" if clips is None else f"{Path(clips) / absent[0]} is missing"
        raise TrackerInputError(
            f"the suite's CMU renders need {', '.join(needed)} but {where}; "
            "pass --clips DIR with the CMU clips (or --only renders of procedural motion)"
        )
    summaries = []
    for render in renders:
        motion = f"bvh:{Path(clips or '.') / render.motion}" if render.motion in CLIPS else render.motion
        summaries.append(
            synthesize(
                MODEL,
                CALIB / f"{render.rig}.toml",
                Path(out) / render.name,
                motion=motion,
                frames=render.frames if frames is None else min(frames, render.frames),
                start=render.start,
                stride=render.stride,
                fps=render.fps,
                seed=render.seed,
                progress=progress,
                staging=render.staging,
                write_init=False,
                replace=True,
            )
        )
    return summaries


def made(out: str | os.PathLike, names: list[str] | None) -> list[Render]:
    """The renders of the suite (those named, else all) that ``out`` holds: <name>/truth.npz exists."""
    out = Path(out)
    if not out.is_dir():
        raise TrackerInputError(f"{out}: suite folder not found; make it with tracker suite make {out}")
    chosen = select(names)
    there = [render for render in chosen if (out / render.name / "truth.npz").is_file()]
    if names is not None and len(there) < len(chosen):
        absent = next(render.name for render in chosen if render not in there)
        raise TrackerInputError(
            f"{out / absent}: no render there; make it with tracker suite make {out} --only {absent}"
        )
    if not there:
        raise TrackerInputError(f"{out}: holds no render of the suite; make them with tracker suite make {out}")
    return there


Scored = tuple[Render, Report, Baseline | None]
"""A render's report, and the detector's baseline where its results hold the landmarks (keypoints.npz)."""


def score(
    out: str | os.PathLike, results: str | os.PathLike, renders: list[Render], *, landmark_model: str = RECORDED
) -> list[Scored]:
    """Each render's report: ``results``/<name>/poses.npz against ``out``/<name>/truth.npz, and the detector's
    baseline (:mod:`tracker.synthetic.detector_baseline`) from the detections of ``landmark_model`` beside it,
    ``results``/<name>/keypoints.npz (:func:`tracker.landmarks.detect_recording.cache_name`), if there are any."""
    results = Path(results)
    if not results.is_dir():
        raise TrackerInputError(f"{results}: results folder not found; track the suite with tracker suite run")
    scores = []
    for render in renders:
        poses = results / render.name / "poses.npz"
        if not poses.is_file():
            raise TrackerInputError(
                f"{poses}: not found; track it with tracker track {Path(out) / render.name} --out {poses.parent}"
            )
        recording = Path(out) / render.name
        tracked, truth = load_poses(poses), load_poses(recording / "truth.npz")
        landmarks = results / render.name / cache_name(landmark_model)
        alone = None
        if landmarks.is_file():
            cameras = load_calibration(recording / "calibration.toml")
            model = load_model(recording / "model.toml")
            alone = baseline(load_keypoints(landmarks), truth, cameras=cameras, model=model, poses=tracked)
        scores.append((render, evaluate(tracked, truth), alone))
    return scores


def summary(scores: list[Scored]) -> dict:
    """The scores as plain data: one row per render (with the detector's baseline, the landmarks' and the
    tracker's error over the same joints and frames), the mean MPJPE over renders (mm, renders with a number)
    and the worst PCK@50mm with its render; NaN becomes None."""

    def plain(value: float) -> float | None:
        return None if math.isnan(value) else round(value, 3)

    rows = [
        {
            "name": render.name,
            "rig": render.rig,
            "fps": render.rate,
            "frames": report.frames,
            "mpjpe_mm": plain(report.mpjpe_mm),
            "pa_mpjpe_mm": plain(report.pa_mpjpe_mm),
            "pck": plain(report.pck),
            "lost_frames": report.lost_frames,
            "far_share": plain(report.far_share),
            "landmarks_mm": None if alone is None else plain(alone.landmarks_mm),
            "tracker_same_mm": None if alone is None else plain(alone.tracker_mm),
        }
        for render, report, alone in scores
    ]
    numbers = [report.mpjpe_mm for _, report, _ in scores if not math.isnan(report.mpjpe_mm)]
    worst = min(scores, key=lambda item: -1.0 if math.isnan(item[1].pck) else item[1].pck)
    return {
        "renders": rows,
        "mean_mpjpe_mm": plain(sum(numbers) / len(numbers)) if numbers else None,
        "worst_pck": plain(worst[1].pck),
        "worst_pck_render": worst[0].name,
    }


def format_summary(data: dict) -> str:
    """:func:`summary` as a text table, then the mean MPJPE and the worst PCK."""

    def number(value: float | None, scale: float = 1.0) -> str:
        return "-" if value is None else f"{scale * value:.1f}"

    width = max(len("render"), *(len(row["name"]) for row in data["renders"]))
    lines = [
        f"{'render':<{width}}  {'rig':<7}  {'fps':>4}  {'MPJPE mm':>8}  {'PA-MPJPE':>8}  {'PCK@50mm':>8}  "
        f"{'>150mm':>6}  {'lost/frames':>11}  {'landmarks':>9}  {'tracker':>7}"
    ]
    for row in data["renders"]:
        lines.append(
            f"{row['name']:<{width}}  {row['rig']:<7}  {row['fps']:>4g}  {number(row['mpjpe_mm']):>8}  "
            f"{number(row['pa_mpjpe_mm']):>8}  {number(row['pck'], 100.0):>7}%  {number(row['far_share'], 100.0):>5}%  "
            f"{str(row['lost_frames']) + '/' + str(row['frames']):>11}  {number(row['landmarks_mm']):>9}  "
            f"{number(row['tracker_same_mm']):>7}"
        )
    lines += [
        "",
        f"mean MPJPE {number(data['mean_mpjpe_mm'])} mm over the renders scored; "
        f"worst PCK@50mm {number(data['worst_pck'], 100.0)} % ({data['worst_pck_render']})",
        ">150mm: the share of frames with a joint further from its truth; landmarks: the detector's landmarks "
        "triangulated frame by frame, mean error (mm) over the joints they give; tracker: the tracker's over the same",
    ]
    return "\n".join(lines)
