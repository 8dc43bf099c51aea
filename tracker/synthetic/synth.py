"""Rendering recordings with ground truth, for tests, demos and benchmarks.

Pipeline of :func:`synthesize`::

    motion (BVH clip | procedural | athletic | seated) -> model poses (F, N, 4, 4)        (tracker.synthetic.clips)
    staging: the body that plays them         -> the model itself, or capsules  (tracker.synthetic.actor)
    per camera, once                          -> the backdrop: photos, or a room (tracker.synthetic.room)
    per frame and camera                      -> ray-cast body over the backdrop, props, texture,
                                                 face, motion blur               (tracker.synthetic.render)
    writers -> <cam>.avi (MJPG), calibration.toml, model.toml, init.toml, truth.npz

and the camera rigs of ``calib/``. :class:`Staging` holds what makes a render unlike the tracking
model (docs/suite.md); its defaults give the plain render of the model itself.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from tracker.atomic import atomic_write, ensure_writable_folder
from tracker.camera import Camera, load_calibration, look_at_camera, save_calibration
from tracker.errors import TrackerInputError
from tracker.geometry import se3
from tracker.io.avi import MjpegAviWriter
from tracker.io.bvh_clip import load_bvh
from tracker.io.posefile import save_pose_file
from tracker.io.recording import recording_files
from tracker.model import Model, joint_centres, load_model, model_from_dict, save_model
from tracker.overwrite import keep_inputs
from tracker.synthetic import texture as textures
from tracker.synthetic.actor import actor_poses, capsule_body, stretched_body
from tracker.synthetic.clips import (
    athletic_motion,
    exposure_poses,
    poses_at,
    procedural_motion,
    retarget,
    seated_motion,
    surface_samples,
)
from tracker.synthetic.face import HAIR, Face
from tracker.synthetic.props import Box, box_corners, cast_boxes
from tracker.synthetic.render import Renderer, albedos, load_backgrounds
from tracker.synthetic.room import make_room, room_backdrop
from tracker.tomlfile import read_toml

# ---------------------------------------------------------------------------------------------
# Cameras


def demo3_rig() -> list[Camera]:
    """calib/demo3.toml: three 640x480 cameras around the CMU 131_01 walk (along -y through the origin).

    cam0 frontal-oblique (the subject walks towards it), cam1 from the body's left side,
    cam2 from behind on the other side; fx = fy = 560, mild barrel distortion.
    """
    dist = (-0.08, 0.02, 0.0, 0.0)
    return [
        look_at_camera("cam0", (1.7, -3.7, 1.55), (0.0, 0.0, 0.85), focal=560.0, distortions=dist),
        look_at_camera("cam1", (4.1, 0.4, 1.25), (0.0, 0.0, 0.9), focal=565.0, distortions=(-0.075, 0.018, 0.0, 0.0)),
        look_at_camera("cam2", (-2.7, 3.0, 1.95), (0.0, 0.0, 0.8), focal=555.0, distortions=(-0.085, 0.022, 0.0, 0.0)),
    ]


def ring4_rig() -> list[Camera]:
    """calib/ring4.toml: four undistorted 640x480 cameras at other heights and angles, one wide (f = 420)."""
    return [
        look_at_camera("cam0", (0.4, -4.3, 1.0), (0.0, 0.0, 0.9), focal=560.0),
        look_at_camera("cam1", (3.0, 3.0, 2.5), (0.0, 0.0, 0.8), focal=600.0),
        look_at_camera("cam2", (-3.4, -0.6, 1.6), (0.0, 0.0, 0.9), focal=420.0),
        look_at_camera("cam3", (-1.8, 3.9, 0.7), (0.0, 0.0, 1.0), focal=540.0),
    ]


def corner3_rig() -> list[Camera]:
    """calib/corner3.toml: three 800x600 cameras mounted high (2.4-2.7 m) in the corners of a room, looking
    down at the body; wider lenses (f = 470-520) with stronger barrel distortion."""
    return [
        look_at_camera(
            "cam0",
            (-3.2, -3.4, 2.6),
            (0.0, 0.0, 0.8),
            size=(800, 600),
            focal=500.0,
            distortions=(-0.14, 0.035, 0.0, 0.0),
        ),
        look_at_camera(
            "cam1", (3.5, -2.9, 2.4), (0.0, 0.0, 0.8), size=(800, 600), focal=470.0, distortions=(-0.12, 0.03, 0.0, 0.0)
        ),
        look_at_camera(
            "cam2", (0.6, 4.1, 2.7), (0.0, 0.0, 0.8), size=(800, 600), focal=520.0, distortions=(-0.15, 0.04, 0.0, 0.0)
        ),
    ]


RIGS = {"demo3": demo3_rig, "ring4": ring4_rig, "corner3": corner3_rig}
"""The rigs of ``calib/``: file stem -> the function that makes it."""


def write_rigs(folder: str | os.PathLike = Path(__file__).resolve().parents[2] / "calib") -> list[Path]:
    """Write calib/<name>.toml for every rig of :data:`RIGS` (demo3, ring4, corner3)."""
    folder = Path(folder)
    paths = []
    for name, rig in RIGS.items():
        paths.append(folder / f"{name}.toml")
        save_calibration(rig(), paths[-1])
    return paths


SCENE_CENTRE = np.array([0.0, 0.0, 0.9])
"""Where the rigs look and the motions play: the body's middle when it stands at the origin."""


def moved_rig(cameras: list[Camera], *, zoom: float = 1.0, distance: float = 1.0) -> list[Camera]:
    """The cameras with focal lengths x ``zoom`` and each moved back along its optical axis so that its
    depth d = f . (c_s - c) to :data:`SCENE_CENTRE` c_s becomes ``distance`` d (the body looks ``distance``
    times smaller); orientation, principal point and distortion unchanged."""
    out = []
    for camera in cameras:
        forward = camera.rotation[2]
        eye = camera.center - (distance - 1.0) * float(forward @ (SCENE_CENTRE - camera.center)) * forward
        matrix = camera.matrix.copy()
        matrix[0:2, 0:2] *= zoom
        out.append(dataclasses.replace(camera, matrix=matrix, translation=-camera.rotation @ eye))
    return out


TABLE_SIZE = (1.4, 0.6, 0.78)
"""Width, depth and height of a table, metres."""


def table_before(camera: Camera, gap: float = 0.75) -> Box:
    """A table standing on the floor between ``camera`` and the scene centre, its middle ``gap`` metres
    from the centre towards the camera (over the floor), its long side across the camera's view."""
    towards = camera.center[0:2] - SCENE_CENTRE[0:2]
    towards /= np.linalg.norm(towards)
    width, depth, height = TABLE_SIZE
    world_from_box = se3.from_rotvec(
        (0.0, 0.0, np.arctan2(-towards[0], towards[1])), (*(SCENE_CENTRE[0:2] + gap * towards), height / 2)
    )
    return Box(world_from_box, 0.5 * np.array([width, depth, height]))


@dataclass(frozen=True)
class Staging:
    """What makes a render unlike the tracking model (docs/suite.md); the defaults render the model itself.

    ``texture``: clothing pattern (:data:`tracker.synthetic.texture.CHOICES`); ``body``: ``model``, ``capsules`` or
    ``stretched`` (:mod:`tracker.synthetic.actor`, sizes within +-``jitter``); ``tables``: camera names (or ``all``)
    with a table between them and the body; ``zoom`` and ``distance``: :func:`moved_rig`; ``motion_blur``: sub-frames
    averaged per frame over an exposure of ``shutter`` frame intervals (:func:`tracker.synthetic.clips.exposure_poses`);
    ``backdrop``: ``photos`` (the background photos, people in them) or ``room`` (an empty furnished room
    rendered from the rig, :func:`room_backdrops`); ``face``: paint a face and hair on the head
    (:func:`head_face`); ``time_offsets``: (camera name, seconds) pairs, each such camera's frame n captured that
    much later than frame n's time, the truth's (a rig that is not frame-locked; the recording does not say so).
    """

    texture: str = "none"
    body: str = "model"
    jitter: float = 0.1
    tables: tuple[str, ...] = ()
    zoom: float = 1.0
    distance: float = 1.0
    motion_blur: int = 1
    shutter: float = 0.5
    backdrop: str = "photos"
    face: bool = False
    time_offsets: tuple[tuple[str, float], ...] = ()

    def check(self, cameras: list[Camera]) -> None:
        """Raise TrackerInputError naming the first value out of range, or a table's unknown camera."""
        names = [c.name for c in cameras]
        problems = [
            (self.texture not in textures.CHOICES, f"texture {self.texture!r}: use {', '.join(textures.CHOICES)}"),
            (self.body not in BODIES, f"body {self.body!r}: use {', '.join(BODIES)}"),
            (not 0.0 <= self.jitter < 0.5, f"jitter {self.jitter}: give a share in [0, 0.5)"),
            (not self.zoom > 0.0, f"zoom {self.zoom}: give a positive factor"),
            (not self.distance > 0.0, f"distance {self.distance}: give a positive factor"),
            (self.motion_blur < 1, f"motion blur {self.motion_blur}: give at least 1 sub-frame"),
            (not 0.0 < self.shutter <= 2.0, f"shutter {self.shutter}: give frame intervals in (0, 2]"),
            (self.backdrop not in BACKDROPS, f"backdrop {self.backdrop!r}: use {', '.join(BACKDROPS)}"),
        ]
        problems += [
            (name != "all" and name not in names, f"table before {name!r}: the rig has {', '.join(names)} (or all)")
            for name in self.tables
        ]
        problems += [
            (name not in names, f"time offset of {name!r}: the rig has {', '.join(names)}")
            for name, _ in self.time_offsets
        ]
        problems += [
            (not np.isfinite(seconds), f"time offset of {name!r}: {seconds} is not a number of seconds")
            for name, seconds in self.time_offsets
        ]
        for bad, message in problems:
            if bad:
                raise TrackerInputError(f"{message}; fix the synth option")

    def table_cameras(self, cameras: list[Camera]) -> list[Camera]:
        """The cameras that have a table before them."""
        return [c for c in cameras if "all" in self.tables or c.name in self.tables]


BODIES = ("model", "capsules", "stretched")
"""The values of ``tracker synth --body``."""

BACKDROPS = ("photos", "room")
"""The values of ``tracker synth --backdrop``."""


def room_backdrops(
    cameras: list[Camera], joints: np.ndarray, props: tuple[Box, ...] = (), *, seed: int = 0, blur: float = 0.7
) -> list[np.ndarray]:
    """Per camera the image (H, W, 3) uint8 of one seeded room (:mod:`tracker.synthetic.room`) whose furniture keeps
    clear of the volume the body's joints ``joints`` (..., 3) and the props take (0.5 m wider, 0.4 m higher)."""
    points = np.concatenate([np.asarray(joints, float).reshape(-1, 3), *(box_corners(box) for box in props)])
    low = np.array([*(points[:, 0:2].min(axis=0) - 0.5), 0.0])
    high = np.array([*(points[:, 0:2].max(axis=0) + 0.5), points[:, 2].max() + 0.4])
    room = make_room(cameras, low, high, seed=seed)
    return [room_backdrop(room, camera, blur=blur) for camera in cameras]


def head_face(body: Model) -> Face:
    """The face for ``body``'s component ``head``, fitted to the bounding box of its surfaces: its albedo as the
    skin, dark brown hair."""
    if "head" not in body.names:
        raise TrackerInputError("the model has no component named head to paint a face on; render without --face")
    head = body.index("head")
    points = np.concatenate(
        [
            surface_samples(shape, params)
            for shape, params, component in zip(body.quadric_shape, body.quadric_params, body.quadric_component)
            if component == head
        ]
    )
    low, high = points.min(axis=0), points.max(axis=0)
    return Face(head, 0.5 * (low + high), 0.5 * (high - low), albedos(body)[head], HAIR)


# ---------------------------------------------------------------------------------------------
# Recording folders

_CONTAINERS = {"MJPG": ".avi", "XVID": ".avi", "mp4v": ".mp4", "avc1": ".mp4", "FFV1": ".mkv", "png": ""}
DEFAULT_QUALITY = 70
"""MJPG quality (cv2.VIDEOWRITER_PROP_QUALITY, 0..100) of :func:`synthesize`."""


def motion_poses(
    model: Model, motion: str, frames: int, *, start: int = 0, stride: int = 2, fps: float = 60.0, seed: int = 0
) -> tuple[np.ndarray, float, Path | None]:
    """Poses (F, N, 4, 4), frame rate and the BVH path (or None) for a motion spec.

    ``motion`` is ``"bvh:PATH"`` (retargeted frames start, start + stride, ...;
    rate = BVH rate / stride), ``"procedural"``, ``"athletic"`` or ``"seated"`` (at ``fps``, varied by ``seed``).
    """
    if motion.startswith("bvh:"):
        path = Path(motion[4:])
        bvh = load_bvh(path)
        poses = retarget(bvh, model, start=start, frames=frames, stride=stride, path=path)
        rate = 1.0 / (bvh.frame_time * stride)
        return poses, float(round(rate)) if abs(rate - round(rate)) < 0.01 else rate, path
    if motion == "procedural":
        return procedural_motion(model, frames, fps=fps, seed=seed), float(fps), None
    if motion == "athletic":
        return athletic_motion(model, frames, fps=fps, seed=seed), float(fps), None
    if motion == "seated":
        return seated_motion(model, frames, fps=fps, seed=seed), float(fps), None
    raise TrackerInputError(
        f"motion {motion!r} is not known; use --motion bvh:PATH/TO/CLIP.bvh, procedural, athletic or seated"
    )


def write_truth(
    path: str | os.PathLike,
    model: Model,
    poses: np.ndarray,
    *,
    frame: np.ndarray | None = None,
    seen: np.ndarray | None = None,
) -> None:
    """truth.npz (formats.md): frame, component_names, poses, joint_names, joints; unicode strings, atomic.

    ``seen`` (F, J) bool: joints that no camera sees (False) are written NaN in ``joints``.
    """
    frame = np.arange(len(poses)) if frame is None else np.asarray(frame)
    joints = joint_centres(np.asarray(poses, dtype=np.float64))
    if seen is not None:
        joints[~seen] = np.nan
    arrays: dict[str, Any] = {  # Any: numpy's savez stub types **kwds like allow_pickle
        "frame": frame.astype(np.int64),
        "component_names": np.array(model.names, dtype=str),
        "poses": np.asarray(poses, dtype=np.float64),
        "joint_names": np.array(model.joint_names, dtype=str),
        "joints": joints,
    }
    atomic_write(path, lambda file: np.savez(file, **arrays))


def _readme(
    name: str,
    motion: str,
    bvh: Path | None,
    backgrounds: list[Path],
    frames: int,
    fps: float,
    cameras: list[Camera],
    model_path: Path,
    start: int,
    stride: int,
    staging: Staging,
    seed: int,
) -> str:
    lines = [
        f"# Synthetic recording `{name}`",
        "",
        "Rendered by `tracker.synthetic.synth` (ray-cast clipped quadrics of the body model, composited over",
        f"{'background photos' if staging.backdrop == 'photos' else 'a rendered room'}, Gaussian edge blur and"
        " sensor noise). Ground truth in `truth.npz`.",
        "",
        f"- model: `{model_path.name}` (copied as `model.toml`)",
        f"- cameras: {', '.join(c.name for c in cameras)} (`calibration.toml`)",
        f"- frames: {frames} at {fps:g} fps",
        f"- motion: `{motion}`"
        if bvh is None
        else f"- motion: `{bvh.name}` frames {start}, {start + stride}, ... {start + stride * (frames - 1)} "
        f"(every {stride}),"
        " retargeted onto the model",
        *_staging_lines(staging, cameras, seed),
        "",
        "## Credits and licences",
        "",
    ]
    if bvh is not None:
        lines += [
            f"- Motion `{bvh.name}`: CMU Graphics Lab Motion Capture Database, http://mocap.cs.cmu.edu/ .",
            '  "The data used in this project was obtained from mocap.cs.cmu.edu. The database was created',
            '  with funding from NSF EIA-0196217." Free for research and commercial use.',
        ]
    if backgrounds:
        lines += [
            f"- Background photos ({', '.join(p.name for p in backgrounds)}): OpenCV samples, https://opencv.org ,",
            "  Apache-2.0 / BSD-3-Clause (Copyright OpenCV contributors).",
        ]
    if bvh is None and not backgrounds:
        lines += ["- Everything here was generated by the tracker project (procedural motion and backdrop)."]
    lines += ["- The rendering itself was generated by the tracker project.", ""]
    return "\n".join(lines)


def _staging_lines(staging: Staging, cameras: list[Camera], seed: int) -> list[str]:
    """The README's lines on what departs from the plain render (none for the default staging)."""
    lines = []
    if staging.body != "model":
        parts = "capsules" if staging.body == "capsules" else "the model's parts"
        lines.append(
            f"- body: {parts} with lengths and radii within +-{100 * staging.jitter:g} % of the model's;"
            " `truth.npz` holds the rendered body's joints and `body.toml` its model,"
            " `model.toml` is the unperturbed model"
        )
    if staging.texture != "none":
        lines.append(f"- clothing texture: {staging.texture}")
    if staging.face:
        lines.append("- a face (eyes, eyebrows, nose, mouth) on the front of the head, hair on its back and top")
    if staging.backdrop == "room":
        lines.append("- backdrop: an empty furnished room ray-cast from every camera (no people in it)")
    if staging.tables:
        names = ", ".join(c.name for c in staging.table_cameras(cameras))
        lines.append(f"- a table ({' x '.join(f'{v:g}' for v in TABLE_SIZE)} m) before {names}, hiding the legs")
    if staging.zoom != 1.0:
        lines.append(f"- rig: focal lengths x {staging.zoom:g} (`calibration.toml` holds the zoomed rig)")
    if staging.distance != 1.0:
        lines.append(f"- rig: cameras {staging.distance:g} times as far (`calibration.toml` holds the moved rig)")
    if staging.motion_blur > 1:
        lines.append(f"- motion blur: {staging.motion_blur} sub-frames over {staging.shutter:g} frame intervals")
    if lines:
        lines.append(
            f"- seed {seed}; joints that no camera sees (behind a table, outside every image) are NaN in `truth.npz`"
        )
    return lines


def _captured(body: Model, poses: np.ndarray, staging: Staging, late: float) -> np.ndarray:
    """What a camera ``late`` frames behind the clip's clock records of ``poses`` (F, N, 4, 4): the poses at its
    capture times (F, N, 4, 4), or with motion blur each exposure's sub-frame poses (F, S, N, 4, 4)."""
    if staging.motion_blur > 1:
        return exposure_poses(body, poses, samples=staging.motion_blur, shutter=staging.shutter, shift=late)
    return poses_at(body, poses, np.arange(len(poses)) + late) if late else poses


def synthesize(
    model_path: str | os.PathLike,
    calib_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    motion: str = "procedural",
    frames: int = 160,
    start: int = 0,
    stride: int = 2,
    seed: int = 0,
    codec: str = "MJPG",
    quality: int = DEFAULT_QUALITY,
    fps: float = 60.0,
    backgrounds=None,
    noise: float = 3.0,
    blur: float = 0.7,
    progress: bool = True,
    staging: Staging = Staging(),
    write_init: bool = True,
    replace: bool = False,
) -> dict:
    """Render a recording folder with ground truth (formats.md, "Recording folder").

    Writes ``calibration.toml``, one video per camera ``<cam>.avi`` (``codec``
    MJPG at ``quality``; ``"png"`` writes ``<cam>/000000.png ...`` instead),
    ``model.toml``, ``init.toml`` (the first frame's truth; ``truth_init.toml``
    instead when not ``write_init``, so that a tracker must find the start), ``truth.npz``
    (joints no camera sees are NaN) and a ``README.md`` with credits.  ``motion``:
    ``"bvh:PATH"`` (frames start, start + stride, ... of the clip, at the clip's rate / stride),
    ``"procedural"``, ``"athletic"`` or ``"seated"`` (at ``fps``, varied by ``seed``).  ``quality`` applies to
    MJPG (libjpeg quality, 4:2:0); other OpenCV fourccs (``mp4v``, ``XVID``,
    ``FFV1``) go through ``cv2.VideoWriter``.  ``backgrounds``: image paths (see
    :func:`load_backgrounds`); ``noise`` sigma in grey levels; ``blur`` edge
    sigma in pixels; ``staging``: what departs from the plain render of the model (:class:`Staging`;
    ``calibration.toml`` holds the rig moved by its zoom and distance, ``model.toml`` is always the
    model given).  Returns a summary dict: out, frames, fps, cameras, files
    (name -> bytes), seconds (render, total), render_ms_per_image, in_view
    (camera -> fraction of frames with the whole body inside the image) and unseen (the share of
    truth joints no camera sees).

    It never writes over what it reads: a model, calibration or clip that is one of the files it would write in
    ``out_dir`` is refused, ``replace`` or not. Nor does it replace a recording (a folder with a calibration.toml or
    a camera's video, :func:`tracker.io.recording.recording_files`) unless ``replace``: whoever made it, for a render
    kept (the demo recording is one) cannot be told from one about to be made again. A recording replaced loses the
    files of the one before that this render does not write (:func:`_remove_stale`); the folder's other files stay.
    Raises TrackerInputError for bad inputs (missing BVH or joints, unreadable
    files, unwritable folder, staging values out of range, an output refused as above) before it renders.
    """
    from tqdm import tqdm

    started = time.perf_counter()
    model_path, calib_path, out = Path(model_path), Path(calib_path), Path(out_dir)
    if codec not in _CONTAINERS:
        raise TrackerInputError(f"codec {codec!r} is not supported; use one of {', '.join(_CONTAINERS)}")
    if frames < 1:
        raise TrackerInputError(f"frames = {frames}: render at least one frame")
    model = load_model(model_path)
    cameras = load_calibration(calib_path)
    staging.check(cameras)
    if staging.zoom != 1.0 or staging.distance != 1.0:
        cameras = moved_rig(cameras, zoom=staging.zoom, distance=staging.distance)
    poses, rate, bvh_path = motion_poses(model, motion, frames, start=start, stride=stride, fps=fps, seed=seed)
    written = _written(out, cameras, codec, write_init=write_init, body=staging.body != "model")
    keep_inputs(
        written,
        [
            (calib_path, "the calibration being rendered from (--calib)"),
            (model_path, "the body model being rendered (--model)"),
            (bvh_path, "the motion clip being rendered (--motion)"),
        ],
        "write the recording to another folder",
    )
    held = recording_files(out)
    if held and not replace:
        raise TrackerInputError(
            f"{out}: already holds a recording ({', '.join(path.name for path in held)}); write the render to "
            "another folder, or add --force to replace it"
        )
    body, shown = model, poses  # the body rendered and its poses
    actor = None  # the rendered body's model TOML document, when it is not the model
    if staging.body != "model":
        make = capsule_body if staging.body == "capsules" else stretched_body
        actor = make(read_toml(model_path, "model", "pass --model"), staging.jitter, seed)
        body = model_from_dict(actor, model_path)
        shown = actor_poses(body, model, poses)
    props = tuple(table_before(camera) for camera in staging.table_cameras(cameras))
    texture = (
        None
        if staging.texture == "none"
        else textures.make_texture(staging.texture, body.names, albedos(body), seed=seed)
    )
    face = head_face(body) if staging.face else None
    late = dict(staging.time_offsets)
    if any(abs(seconds) * rate >= frames for seconds in late.values()):
        raise TrackerInputError(
            f"time offsets {late} (seconds): each must be shorter than the recording ({frames} frames at "
            f"{rate:g} fps); fix the synth option"
        )
    views = [_captured(body, shown, staging, late.get(cam.name, 0.0) * rate) for cam in cameras]
    if staging.backdrop == "room" and backgrounds is not None:
        raise TrackerInputError("background photos and the room backdrop exclude each other; give only one")
    ensure_writable_folder(out)
    used: list[Path] = []  # the photos composited
    if staging.backdrop == "room":
        photos = room_backdrops(cameras, joint_centres(shown), props, seed=seed, blur=blur)
    else:
        photos, used = load_backgrounds(cameras, backgrounds, seed)
    renderers = [
        Renderer(body, cam, bg, noise=noise, blur=blur, texture=texture, face=face, props=props)
        for cam, bg in zip(cameras, photos)
    ]
    rng = np.random.default_rng(seed)

    writers: list[Path | MjpegAviWriter | cv2.VideoWriter] = []  # a PNG folder or a video writer per camera
    writer: Path | MjpegAviWriter | cv2.VideoWriter
    temps: list[Path] = []
    finals: list[Path] = []
    for cam in cameras:
        if codec == "png":
            folder = out / cam.name
            folder.mkdir(parents=True, exist_ok=True)
            writers.append(folder)
            continue
        final = out / f"{cam.name}{_CONTAINERS[codec]}"
        temp = out / f".{cam.name}.partial{_CONTAINERS[codec]}"
        if codec == "MJPG":
            writer = MjpegAviWriter(temp, rate, cam.size, quality)
        else:
            writer = cv2.VideoWriter(str(temp), cv2.VideoWriter.fourcc(*codec), rate, cam.size)
            if not writer.isOpened():
                raise TrackerInputError(f"{temp}: OpenCV cannot write {codec} video here; use codec='MJPG' or 'png'")
        writers.append(writer)
        temps.append(temp)
        finals.append(final)
    render_seconds = 0.0
    done = False
    try:
        for f in tqdm(range(frames), desc=f"synth {out.name}", unit="frame", disable=not progress):
            for renderer, writer, view in zip(renderers, writers, views):
                tick = time.perf_counter()
                image = renderer.render(view[f], rng)
                render_seconds += time.perf_counter() - tick
                if codec == "png":
                    assert isinstance(writer, Path)
                    cv2.imwrite(str(writer / f"{f:06d}.png"), image)
                else:
                    assert not isinstance(writer, Path)
                    writer.write(image)
        done = True
    finally:
        for writer in writers:
            if isinstance(writer, MjpegAviWriter):
                writer.close()
            elif not isinstance(writer, Path):
                writer.release()
        if not done:
            for temp in temps:
                temp.unlink(missing_ok=True)
    for temp, final in zip(temps, finals):
        os.replace(temp, final)

    save_calibration(cameras, out / "calibration.toml")
    model_bytes = model_path.read_bytes()

    atomic_write(out / "model.toml", lambda file: file.write(model_bytes))
    if actor is not None:
        save_model(
            out / "body.toml", actor, "The rendered body (tracker synth --body); model.toml is the tracking model."
        )
    save_pose_file(out / ("init.toml" if write_init else "truth_init.toml"), model, shown[0], frame=0)
    seen = seen_joints(joint_centres(shown), cameras, props)
    write_truth(out / "truth.npz", model, shown, seen=seen)
    text = _readme(
        out.name, motion, bvh_path, used, frames, rate, cameras, model_path, start, stride, staging, seed
    ).encode()

    atomic_write(out / "README.md", lambda file: file.write(text))
    _remove_stale(out, written)
    files = {p.name: p.stat().st_size for p in sorted(out.iterdir()) if p.is_file() and not p.name.startswith(".")}
    in_view = visibility(body, shown, cameras).mean(axis=0)
    return {
        "out": out,
        "frames": frames,
        "fps": rate,
        "cameras": [c.name for c in cameras],
        "files": files,
        "seconds": {"render": render_seconds, "total": time.perf_counter() - started},
        "render_ms_per_image": 1e3 * render_seconds / (frames * len(cameras)),
        "in_view": {cam.name: float(v) for cam, v in zip(cameras, in_view)},
        "unseen": float(1.0 - seen.mean()),
    }


def _written(out: Path, cameras: list[Camera], codec: str, *, write_init: bool, body: bool) -> list[Path]:
    """The files that :func:`synthesize` writes in ``out`` (``body``: the rendered body's model too)."""
    made = ["calibration.toml", "model.toml", *(["body.toml"] if body else [])]
    made.append("init.toml" if write_init else "truth_init.toml")
    made += ["truth.npz", "README.md", *(f"{camera.name}{_CONTAINERS[codec]}" for camera in cameras)]
    return [out / name for name in made]


_STALE = ("init.toml", "truth_init.toml", "body.toml", "timestamps.csv", "sync.toml")
"""Files of a recording folder that a render replacing one (``--force``) may not write, and that would otherwise be
read with it: an old first pose, rendered body, capture times or camera offsets."""


def _remove_stale(out: Path, written: list[Path]) -> None:
    """Remove from ``out`` the recording's files that this render did not write (:data:`_STALE`, and the videos of
    cameras it does not have), so that a replaced recording holds nothing of the one before."""
    kept = {path.name for path in written}
    for path in [*recording_files(out), *(out / name for name in _STALE)]:
        if path.name not in kept:
            path.unlink(missing_ok=True)


def seen_joints(joints: np.ndarray, cameras: list[Camera], props: tuple[Box, ...] = ()) -> np.ndarray:
    """(F, J) bool: some camera sees joint j in frame f, in front of it, inside its image and not behind a prop."""
    flat = joints.reshape(-1, 3)
    seen = np.zeros(len(flat), dtype=bool)
    for camera in cameras:
        depth = flat @ camera.rotation[2] + camera.translation[2]
        ahead = depth > 1e-6
        inside = np.zeros(len(flat), dtype=bool)
        pixels = camera.project(flat[ahead])
        w, h = camera.size
        inside[ahead] = np.all((pixels >= -0.5) & (pixels <= np.array([w - 0.5, h - 0.5])), axis=1)
        if props and inside.any():
            xy = (flat[inside] @ camera.rotation[0:2].T + camera.translation[0:2]) / depth[inside, None]
            inside[inside] = depth[inside] < cast_boxes(list(props), camera, xy)[0]
        seen |= inside
    return seen.reshape(joints.shape[:-1])


def visibility(model: Model, poses: np.ndarray, cameras: list[Camera], *, margin: float = 2.0) -> np.ndarray:
    """(F, C) bool: every sampled surface point of the body projects inside camera c's image (with ``margin`` px)."""
    out = np.zeros((len(poses), len(cameras)), dtype=bool)
    pieces = [
        (model.quadric_component[k], surface_samples(model.quadric_shape[k], p))
        for k, p in enumerate(model.quadric_params)
    ]
    for f, pose in enumerate(poses):
        points = np.concatenate([pts @ pose[c, 0:3, 0:3].T + pose[c, 0:3, 3] for c, pts in pieces])
        for j, cam in enumerate(cameras):
            depth = (points @ cam.rotation.T + cam.translation)[:, 2]
            pix = cam.project(points)
            w, h = cam.size
            out[f, j] = bool(
                np.all(depth > 0)
                and np.all(pix >= margin - 0.5)
                and np.all(pix[:, 0] <= w - 0.5 - margin)
                and np.all(pix[:, 1] <= h - 0.5 - margin)
            )
    return out
