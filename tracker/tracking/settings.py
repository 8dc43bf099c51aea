"""The tracker's settings, one small frozen dataclass per group: the solve, the outline samples, the edge search,
the image sizes, the motion model, the frame's status, the keypoints, the colour regions and the smoothing of a
recorded folder's track.

Each field carries its help in its metadata, says whether it is in pixels (``pixels``: "grows" with the image,
"shrinks" with it as a grey-level derivative per pixel does, or "fixed"), and, when a command offers it, its flag
(``flag``) and the kind of value it takes (``kind``: count, positive, whole, share or on/off).  :func:`scaled_to`
scales by the ``pixels`` metadata, and :mod:`tracker.commands.options` builds the tuning flags, their help and their
defaults from the same fields, so that each default is written once, here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

DYNAMICS = ("none", "constant-velocity", "kalman")
SMOOTHING = ("none", "rts", "both-ways")


def setting(
    default: Any,
    help: str,
    *,
    pixels: str | None = None,
    least: int = 0,
    flag: str | None = None,
    kind: str | None = None,
    choices: tuple[str, ...] | None = None,
    renamed: str | None = None,
    recorded: bool = False,
) -> Any:
    """A settings field: its ``default``, its ``help``, how it scales with the image (``pixels``: "grows", "shrinks"
    or "fixed"; an integer that grows is rounded and kept at ``least`` or more), and the ``flag``, ``kind`` (count,
    positive, whole, share or on-off) and ``choices`` of the command-line option that sets it, if any, with the
    flag's old name, ``renamed``, still taken; ``recorded``: only for a recorded folder (tracker live leaves it out)."""
    if pixels not in (None, "grows", "shrinks", "fixed"):
        raise ValueError(f"pixels must be grows, shrinks or fixed, got {pixels!r}")
    metadata = dict(
        help=help, pixels=pixels, least=least, flag=flag, kind=kind, choices=choices, renamed=renamed, recorded=recorded
    )
    return field(default=default, metadata=metadata)


@dataclass(frozen=True)
class SolveSettings:
    """the solve: iterations per frame, the robust weights and the prior about the predicted pose"""

    iterations: int = setting(6, "solves per frame", flag="--iterations", kind="count")
    robust_c: float = setting(
        2.0, "c of the robust weight 1 / (c + |offset|) of an edge sample or a landmark", pixels="fixed"
    )
    prior_translation: float = setting(1e3, "the prior about the predicted pose, per m^2 of translation")
    prior_rotation: float = setting(10.0, "... and per rad^2 of rotation")
    max_turn: float = setting(
        float("inf"),
        "largest rotation (rad) of any part in one solve; a larger step is scaled down whole, which keeps a body from "
        "flipping on clutter but slows it in fast motion",
        flag="--max-turn",
        kind="positive",
    )
    trunk_hold: float = setting(
        100.0,
        "per rad^2: the pelvis pulled back where the trunk's joint turns beyond body_landmarks.TRUNK_TURN "
        "(docs/keypoints.md, 'The trunk held near rest'); 0: never",
    )


@dataclass(frozen=True)
class OutlineSettings:
    """the outline: where its samples lie and how far each one searches"""

    spacing: float = setting(4.0, "pixels between outline samples", pixels="grows", flag="--spacing", kind="positive")
    search_range: int = setting(
        20,
        "pixels searched either side of the outline in a frame's first solve",
        pixels="grows",
        flag="--search-range",
        kind="count",
    )
    final_search_range: int = setting(
        6, "pixels searched in the last solve, narrowing from search_range; 0: always search_range", pixels="grows"
    )
    resample_every: int = setting(
        3,
        "place the outline samples afresh every N-th solve, and slide them with their parts between (1: every solve)",
        flag="--resample-every",
        kind="count",
    )
    ownership: bool = setting(True, "cut each search half way to the next predicted edge of another part")
    capacity: int = setting(40000, "outline samples of all cameras together, at most")


@dataclass(frozen=True)
class EdgeSettings:
    """the edge search"""

    threshold: float = setting(6.0, "least grey-level derivative of an edge, per pixel", pixels="shrinks")
    blur_sigma: float = setting(1.0, "Gaussian smoothing of the images before the search, pixels", pixels="grows")


@dataclass(frozen=True)
class ImageSettings:
    """the image sizes the pixel settings are for"""

    reference_size: int = setting(
        480, "the pixel settings are for images this many pixels on their short side; larger images scale them"
    )
    work_side: int = setting(
        480,
        "search larger images reduced by the largest whole factor that keeps their short side at least this long "
        "(1080p is searched at half size; 0: always at full size)",
        flag="--work-side",
        kind="whole",
    )


@dataclass(frozen=True)
class MotionSettings:
    """the motion model that predicts each frame's pose (docs/motion-models.md)"""

    dynamics: str = setting(
        "constant-velocity",
        "how each frame's pose is predicted: none (the last pose), constant-velocity (the last motion carried on) or "
        "kalman (a Kalman filter per part, whose uncertainty also sets how firmly the prediction holds)",
        flag="--dynamics",
        choices=DYNAMICS,
        renamed="--motion",  # the rendered clip's option in `tracker synth`
    )
    damping: float = setting(
        1.0,
        "share of the last frame's motion carried into the prediction (constant-velocity; 0.5 steadies a single "
        "camera)",
        flag="--damping",
        kind="share",
    )
    check_prediction: bool = setting(
        True,
        "constant-velocity: where the frame's landmarks lie nearer the last pose than the predicted one, the last "
        "motion is not carried on (off live, whose landmarks moved with them)",
    )
    frame_rate: float = setting(
        60.0, "frames per second of the recording: the Kalman filter's time step is its inverse"
    )
    q_translation: float = setting(3.0, "kalman: spectral density of the white-noise acceleration, m^2/s^3")
    q_rotation: float = setting(100.0, "kalman: ... of the angular acceleration, rad^2/s^3")
    noise_scale: float = setting(1.0, "kalman: s, the measurement noise V = s' C_i^-1 of a part's information C_i")
    residual_variance: bool = setting(True, "kalman: s' = s times the variance of the part's residuals; off: s' = s")
    decay: float = setting(3.0, "kalman: velocity decay rate, 1/s (docs/method-physics.md, section 3)")


@dataclass(frozen=True)
class StatusSettings:
    """the frame's status: which parts the images hold, and when a frame is tracked, uncertain or lost"""

    held_within: float = setting(
        1.0,
        "a part is held by the images when the edges and colours along its outline place it within this many pixels "
        "in its least-seen direction (tracking.held); the others are left to the prior and do not judge the frame",
        pixels="grows",
    )
    uncertain_share: float = setting(
        0.6, "share of the held parts' outline samples that found an edge below which a frame is uncertain"
    )
    lost_share: float = setting(0.3, "... and lost")
    uncertain_residual: float = setting(
        3.0, "robust mean offset of the held parts' edges above which a frame is uncertain, pixels", pixels="grows"
    )
    lost_residual: float = setting(6.0, "... and lost, pixels", pixels="grows")
    uncertain_held: float = setting(0.5, "share of the parts held by the images below which a frame is uncertain")
    lost_held: float = setting(0.2, "... and lost")


@dataclass(frozen=True)
class KeypointSettings:
    """the keypoint detector's landmarks (docs/keypoints.md)"""

    weight: float = setting(3.0, "a landmark's weight against an edge sample's")
    confidence: float = setting(0.3, "landmarks less confident are not used (below 0.5 they are used unchecked)")
    tolerance: float = setting(0.015, "detector noise, a share of the body's image size: closer landmarks do not pull")
    noise_multiple: float = setting(1.5, "each landmark's zone grows to this many times its median misfit (0: fixed)")
    tolerance_max: float = setting(0.15, "... but no further: a body that far off is pulled back")
    reach: float = setting(0.1, "a landmark's pull fades beyond this share of the body's size past its zone")
    edge_misfit: float = setting(
        0.8,
        "where a part's edges fit worse (median offset), the landmarks it places pull from the least zone with no "
        "fade, pixels",
        pixels="grows",
    )
    lead: float = setting(
        0.06,
        "share of the body's image size: where the landmarks at a limb's end lie this far beyond their zone, they "
        "alone move the limb and the frame is tracked again, kept if the limb's edges fit better (tracking.lead); "
        "0: never",
    )
    lead_off_mask: bool = setting(
        True, "an arm off a view's person mask where the trunk is on it, or a leg off every view's, is led too"
    )
    hide_guessed: bool = setting(
        True,
        "legs whose landmarks triangulate to bones under half the model's are guessed by the detector: their "
        "landmarks are dropped and their parts hidden in that frame (landmarks.guessed)",
    )
    drag: float = setting(
        0.05,
        "share of the body's image size: where the frame's landmarks lie off its tracked pose by this much more than "
        "off the pose it was tracked from, the frame keeps that pose; 0: never",
    )


@dataclass(frozen=True)
class RegionSettings:
    """the colour regions either side of the outline (docs/region.md)"""

    on: bool = setting(
        True,
        "read the colours along the outline too, learnt as the run goes, to tell the body from the room (it needs "
        "the frames' colour)",
        flag="--region",
        kind="on-off",
    )
    weight: float = setting(
        0.6,
        "the colour cue's weight beside the edges', per line read (every second sample's)",
        flag="--region-weight",
        kind="positive",
    )
    sigma: float = setting(1.0, "the least standard deviation of a line's offset, pixels", pixels="grows")
    amplitude: float = setting(0.43, "a: the smoothed step 1/2 - a tanh(x / 2s) between inside and outside")
    slope: float = setting(0.5, "s of that step, pixels", pixels="grows")
    learning_rate: float = setting(0.2, "share of a frame's colours blended into what was learnt")
    every: int = setting(2, "use every N-th sample's line")
    inside: int = setting(
        4, "pixels in from the outline whose colours are learnt as the part's", pixels="grows", least=1
    )
    outside: int = setting(10, "... and out to which they are learnt as the background's", pixels="grows", least=2)
    agree: float = setting(
        2.0, "once a part's colours are known, only lines whose offset is this close teach, pixels", pixels="grows"
    )
    person: float = setting(
        0.6,
        "how far the colour cue trusts the detector's mask of the person, 0..1 (0 ignores it)",
        flag="--region-person",
        kind="share",
    )
    margin: int = setting(
        2,
        "half-size pixels a line's scores reach beyond its candidates, until the next sampling",
        pixels="grows",
    )


@dataclass(frozen=True)
class SmoothingSettings:
    """the track of a recorded folder judged with the frames after each one (docs/motion-models.md; tracker live tracks
    frame by frame)"""

    method: str = setting(
        "both-ways",
        "none: each frame from the frames before it alone, as live; rts: the track smoothed over the whole recording "
        "on the motion model (a Rauch-Tung-Striebel smoother); both-ways: the recording also tracked back from its "
        "last frame, each frame's pose taken from the track its edges, mask and landmarks back, then smoothed as rts",
        flag="--smooth",
        choices=SMOOTHING,
        recorded=True,
    )
    noise_scale: float = setting(
        10.0, "rts: each frame's information about a part's pose (Tracker.measured) is divided by this"
    )
    misfit_weight: float = setting(
        5.0,
        "both-ways: what a track's landmark misfit (a share of the body's size) costs against the shares of its "
        "outline that found an edge and of its body on the person's masks",
    )


@dataclass(frozen=True)
class Settings:
    """Tracking parameters by group; the defaults suit 640x480 views of a whole body."""

    solve: SolveSettings = SolveSettings()
    outline: OutlineSettings = OutlineSettings()
    edges: EdgeSettings = EdgeSettings()
    images: ImageSettings = ImageSettings()
    motion: MotionSettings = MotionSettings()
    status: StatusSettings = StatusSettings()
    keypoints: KeypointSettings = KeypointSettings()
    region: RegionSettings = RegionSettings()
    smoothing: SmoothingSettings = SmoothingSettings()

    def but(self, **groups: dict[str, Any]) -> Settings:
        """These settings with some fields of some groups changed: ``but(motion=dict(dynamics="none"))``."""
        return dataclasses.replace(
            self, **{name: dataclasses.replace(getattr(self, name), **changes) for name, changes in groups.items()}
        )


def scaled_to(settings: Settings, short_side: int) -> Settings:
    """The settings for images ``short_side`` pixels on their short side: the fields whose ``pixels`` metadata says
    they grow (spacing, search ranges, blur, ...) grow with the image beyond ``images.reference_size`` (an edge
    spreads over as many more pixels), those that shrink (the edge threshold, a grey-level derivative per pixel) shrink
    by the same factor; smaller images keep them."""
    k = max(1.0, short_side / settings.images.reference_size)
    if k == 1.0:
        return settings
    changes: dict[str, dict[str, Any]] = {}
    for group in dataclasses.fields(settings):
        values = getattr(settings, group.name)
        changes[group.name] = {
            f.name: _scaled(getattr(values, f.name), f, k)
            for f in dataclasses.fields(values)
            if f.metadata["pixels"] in ("grows", "shrinks")
        }
    changes["images"]["reference_size"] = short_side
    return settings.but(**changes)


def _scaled(value: float, spec: dataclasses.Field, k: float) -> float:
    """``value`` of the field ``spec`` for images ``k`` times the reference size."""
    if spec.metadata["pixels"] == "shrinks":
        return value / k
    if isinstance(value, int):
        return max(spec.metadata["least"], round(value * k))
    return value * k
