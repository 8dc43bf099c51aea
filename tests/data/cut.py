"""Remake the files in tests/data from ../shared/data (run from the repository root, with ../shared beside it):

    python tests/data/cut.py

Marker C3Ds keep their first frames and every POINT parameter, without the analog channels
(ezc3d rewrites them); TRC and BVH keep their header and first (or a window of) frames, text unchanged;
the calibration files, background photos and licences are copied as they are.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import ezc3d
import numpy as np

HERE = Path(__file__).resolve().parent
SHARED = HERE.parents[2] / "shared" / "data"


def cut_c3d(source: Path, target: Path, frames: int) -> None:
    """The first ``frames`` frames of ``source``'s points and residuals; the analog channels dropped."""
    c3d = ezc3d.c3d(str(source))
    parameters = c3d["parameters"]
    ratio = round(parameters["ANALOG"]["RATE"]["value"][0] / parameters["POINT"]["RATE"]["value"][0])
    c3d["data"]["points"] = c3d["data"]["points"][:, :, :frames]
    for key in list(c3d["data"]["meta_points"]):
        c3d["data"]["meta_points"][key] = c3d["data"]["meta_points"][key][..., :frames]
    c3d["data"]["analogs"] = np.zeros((1, 0, frames * ratio))
    analog = parameters["ANALOG"]
    analog["USED"]["value"] = np.array([0])
    for key in ("GAIN", "SCALE", "OFFSET"):
        if key in analog:
            analog[key]["value"] = np.array([])
    for key in ("UNITS", "LABELS", "DESCRIPTIONS"):
        if key in analog:
            analog[key]["value"] = []
    c3d.write(str(target))


def cut_trc(source: Path, target: Path, frames: int) -> None:
    """The header (NumFrames and OrigNumFrames set to ``frames``) and the first ``frames`` rows."""
    lines = source.read_text().splitlines(keepends=True)
    names = lines[1].rstrip("\n").split("\t")
    values = lines[2].rstrip("\n").split("\t")
    for key in ("NumFrames", "OrigNumFrames"):
        i = names.index(key)
        values[i] = values[i].replace(values[i].strip(), str(frames))
    lines[2] = "\t".join(values) + "\n"
    start = next(i for i, line in enumerate(lines) if i > 4 and line.strip())  # first data row
    target.write_text("".join(lines[: start + frames]))


def cut_bvh(source: Path, target: Path, first: int, frames: int) -> None:
    """The hierarchy and motion rows ``first`` .. ``first + frames - 1``."""
    lines = source.read_text().splitlines(keepends=True)
    motion = next(i for i, line in enumerate(lines) if line.startswith("Frames:"))
    lines[motion] = f"Frames: {frames}\n"
    rows = motion + 2  # after "Frame Time:"
    target.write_text("".join(lines[:rows] + lines[rows + first : rows + first + frames]))


def main() -> None:
    markers = HERE / "markers"
    markers.mkdir(exist_ok=True)
    cut_c3d(SHARED / "markers" / "Vicon.c3d", markers / "Vicon.c3d", 160)
    cut_c3d(SHARED / "markers" / "Qualisys.c3d", markers / "Qualisys.c3d", 40)
    cut_trc(SHARED / "markers" / "subject01_walk1.trc", markers / "subject01_walk1.trc", 60)
    shutil.copyfile(SHARED / "markers" / "arm26_elbow_flex.trc", markers / "arm26_elbow_flex.trc")
    for name in ("LICENSE_ezc3d_MIT.txt", "LICENSE_NOTE_from_gait2354_simbody_osim.txt"):
        shutil.copyfile(SHARED / "markers" / name, markers / name)

    pose2sim = HERE / "pose2sim"
    pose2sim.mkdir(exist_ok=True)
    shutil.copyfile(SHARED / "pose2sim-balancing" / "calibration.toml", pose2sim / "calibration.toml")
    shutil.copyfile(SHARED / "pose2sim-intrinsics" / "Calib.qca.txt", pose2sim / "Calib.qca.txt")
    shutil.copyfile(SHARED / "pose2sim-balancing" / "LICENSE", pose2sim / "LICENSE")

    caliscope = HERE / "caliscope"
    caliscope.mkdir(exist_ok=True)
    for name in ("camera_array.toml", "charuco.toml", "LICENSE"):
        shutil.copyfile(SHARED / "caliscope-4cam" / name, caliscope / name)

    backgrounds = HERE.parents[1] / "tracker" / "data" / "backgrounds"
    backgrounds.mkdir(exist_ok=True)
    for name in ("basketball1.png", "basketball2.png", "COPYRIGHT"):
        shutil.copyfile(SHARED / "backgrounds" / name, backgrounds / name)

    cmu = HERE / "cmu-mocap"
    cmu.mkdir(exist_ok=True)
    cut_bvh(SHARED / "cmu-mocap" / "131_01.bvh", cmu / "131_01_500-619.bvh", 500, 120)
    shutil.copyfile(SHARED / "cmu-mocap" / "README.md", cmu / "README.md")


if __name__ == "__main__":
    main()
