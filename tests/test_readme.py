"""The commands of the README and of docs/ run as written, and the documentation's links hold.

Convention: a shell block (```sh) in README.md or a docs/ page that holds a ``tracker`` command is
preceded by one of two HTML comments:

* ``<!-- test -->``: the block uses only files the repository ships (``recordings/demo``,
  ``models/``, ``calib/``) and is run here, one command after the other, in a temporary folder
  where those three folders are linked in. Commands are shortened by appending limiting options
  (``LIMITS``; argparse keeps the last value of a repeated option), so the whole file runs in
  well under a minute once the numba kernels are cached.
* ``<!-- not tested: REASON -->``: the block needs something a clone lacks (``../shared/data``,
  the user's own recording, a camera, a person at the browser); REASON says what.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from tracker.cli import main
from tracker.landmarks.store import load_keypoints

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
SHIPPED = ("recordings", "models", "calib")
SHELL = {"sh", "bash", "shell"}

# Options appended to keep each command short; every one exists on that subcommand.
LIMITS: dict[str, list[str]] = {
    "track": ["--frames", "12", "--quiet"],
    "synth": ["--frames", "6"],
    "view": ["--quiet", "--port", "0"],
    "background": ["--samples", "5", "--quiet"],
    "bench": ["--repeats", "1"],
    "experiment": ["--frames", "2", "--quiet"],
    "keypoints": ["--frames", "6", "--quiet"],
    "suite": ["--frames", "3", "--quiet"],  # make: 3 frames a render; run: passed on to tracker track
}


def _blocks(path: Path) -> list[tuple[str, str, list[str], int]]:
    """Fenced blocks of a markdown file: (marker comment before it or '', language, lines, line number)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks = []
    i = 0
    while i < len(lines):
        fence = re.match(r"^```(\w*)\s*$", lines[i])
        if not fence:
            i += 1
            continue
        before = [line for line in lines[:i] if line.strip()]
        marker = before[-1].strip() if before and before[-1].strip().startswith("<!--") else ""
        end = i + 1
        while end < len(lines) and not lines[end].startswith("```"):
            end += 1
        blocks.append((marker, fence.group(1), lines[i + 1 : end], i + 1))
        i = end + 1
    return blocks


def _commands(block: list[str]) -> list[list[str]]:
    """Shell commands of a block, continuation lines joined and comments dropped."""
    joined = "\n".join(block).replace("\\\n", " ")
    return [words for line in joined.splitlines() if (words := shlex.split(line, comments=True))]


def _tracker_blocks(path: Path):
    for marker, language, block, line in _blocks(path):
        if language in SHELL and any(words[0] == "tracker" for words in _commands(block)):
            yield marker, block, line


def _pages() -> list[Path]:
    return [README, *sorted(DOCS.glob("*.md"))]


TESTED = [
    (f"{page.relative_to(ROOT)}:{line}", block)
    for page in _pages()
    for marker, block, line in _tracker_blocks(page)
    if marker == "<!-- test -->"
]


def test_every_tracker_block_is_tested_or_excused():
    for page in _pages():
        where = page.relative_to(ROOT)
        for marker, block, line in _tracker_blocks(page):
            excused = re.fullmatch(r"<!-- not tested: (.+\S) -->", marker)
            assert marker == "<!-- test -->" or excused, f"{where} line {line}: mark the block test or not tested"
            if marker == "<!-- test -->":
                for words in _commands(block):
                    assert words[0] == "tracker", f"{where} line {line}: only tracker commands in a tested block"
                    assert not any("../shared" in word for word in words), f"{where} line {line}: not shipped"
    assert any(where.startswith("README.md") for where, _ in TESTED), "no tested block in the README"


def _makefile_demo() -> list[str]:
    recipe = (ROOT / "Makefile").read_text(encoding="utf-8").split("\ndemo:", 1)[1].splitlines()[1]
    words = shlex.split(recipe)
    start = next(i for i, word in enumerate(words) if word.endswith("/tracker"))
    return ["tracker", *words[start + 1 :]]


def _frames_of(poses: Path) -> int:
    with np.load(poses) as arrays:
        return len(arrays["joints"])


def _check_poses(path: Path, recording: Path | None, views: int) -> None:
    """Mostly tracked, finite joints, and near the truth where there is one: MPJPE under 25 mm, or 100 mm
    with a single view (depth is then weakly observed)."""
    with np.load(path) as arrays:
        joints, status, frames = arrays["joints"], arrays["status"], arrays["frame"]
        names = list(arrays["joint_names"])
    assert len(joints) > 0
    assert np.mean(status == 0) >= 0.9, f"{path}: status {np.bincount(status, minlength=3)}"
    assert np.all(np.isfinite(joints[status != 2]))
    truth_file = recording / "truth.npz" if recording else None
    if truth_file and truth_file.exists():
        with np.load(truth_file) as truth:
            rows = {int(f): r for r, f in enumerate(truth["frame"])}
            true = truth["joints"][[rows[int(f)] for f in frames]]
            columns = [list(truth["joint_names"]).index(name) for name in names]
        error_mm = 1000 * np.linalg.norm(joints - true[:, columns], axis=2)
        bound = 25.0 if views != 1 else 100.0
        assert np.nanmean(error_mm) < bound, f"{path}: MPJPE {np.nanmean(error_mm):.1f} mm"


def _check_output(path: Path, recording: Path | None, views: int) -> None:
    """A written file holds what it should, with sensible numbers."""
    assert path.stat().st_size > 0, path
    poses = path.with_suffix(".npz")
    if path.name == "poses.npz":
        _check_poses(path, recording, views)
    elif path.name == "truth.npz":
        assert _frames_of(path) > 0
    elif path.suffix == ".trc":
        header = path.read_text().splitlines()[2].split("\t")
        if poses.exists():
            assert int(header[2]) == _frames_of(poses)
        assert float(header[0]) > 0  # frame rate
    elif path.suffix == ".bvh":
        counts = re.findall(r"^Frames:\s*(\d+)", path.read_text(), re.M)
        assert counts and (not poses.exists() or int(counts[0]) == _frames_of(poses))
    elif path.name == "keypoints.npz":
        keypoints = load_keypoints(path)
        assert 1 <= len(keypoints.frame) <= 6 and keypoints.pixels.shape[1] == len(keypoints.camera_names)
        assert (keypoints.confidence.max(axis=2) > 0.5).any(axis=1).all()  # a person in some view of every frame
    elif path.suffix == ".csv" and poses.exists():
        assert len(path.read_text().splitlines()) == 1 + _frames_of(poses)


def _recording_of(words: list[str], cwd: Path) -> Path | None:
    """The recording folder a command reads (its first positional argument that is a folder)."""
    for word in words[2:]:
        if not word.startswith("-") and (cwd / word).is_dir():
            return cwd / word
    return None


def _run(words: list[str], cwd: Path) -> None:
    subcommand = words[1]
    before = {p for p in cwd.rglob("*") if p.is_file() and p.parts[len(cwd.parts)] not in SHIPPED}
    argv = words[1:] + LIMITS.get(subcommand, [])
    assert main(argv) == 0, f"exit code of: {shlex.join(words)}"
    after = {p for p in cwd.rglob("*") if p.is_file() and p.parts[len(cwd.parts)] not in SHIPPED}
    written = after - before
    if subcommand != "eval":
        assert written, f"{shlex.join(words)} wrote no file"
    recording = _recording_of(words, cwd) if subcommand == "track" else None
    for path in written:
        views = len(words[words.index("--cameras") + 1].split(",")) if "--cameras" in words else 0
        _check_output(path, recording, views)
    if subcommand == "synth":
        out = cwd / words[words.index("--out") + 1]
        assert (out / "calibration.toml").exists() and _frames_of(out / "truth.npz") == 6


@pytest.fixture
def workdir(tmp_path, monkeypatch) -> Path:
    for name in SHIPPED:
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    return tmp_path


@pytest.mark.parametrize("where,block", TESTED, ids=[where for where, _ in TESTED])
def test_documented_block_runs(where, block, workdir):
    for words in _commands(block):
        _run(words, workdir)


def test_make_demo_command_runs(workdir):
    words = _makefile_demo()
    assert words[:3] == ["tracker", "track", "recordings/demo"]
    _run(words, workdir)


# --- links -----------------------------------------------------------------------------------

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _relative_links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)  # not inside code
    targets = [t for t in LINK.findall(text) if not re.match(r"^[a-z]+:", t) and not t.startswith("#")]
    return [t.split("#", 1)[0] for t in targets]


def test_every_docs_page_is_linked_from_the_readme():
    linked = {(README.parent / t).resolve() for t in _relative_links(README)}
    missing = [p.name for p in sorted(DOCS.glob("*.md")) if p.resolve() not in linked]
    assert not missing, f"docs pages not linked from README.md: {missing}"


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_to_files(page):
    broken = [t for t in _relative_links(page) if not (page.parent / t).exists()]
    assert not broken, f"{page.relative_to(ROOT)}: broken links {broken}"


@pytest.mark.parametrize("page,count", [("method-tracking.md", 8), ("method-physics.md", 7)])
def test_method_pages_keep_the_section_numbers(page, count):
    """Docstrings cite 'docs/method-....md, section N': every N must exist, once, in order."""
    numbers = re.findall(r"^## (\d+)\. \S", (DOCS / page).read_text(encoding="utf-8"), re.M)
    assert [int(n) for n in numbers] == list(range(1, count + 1))


def test_readme_is_a_front_door():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 300
