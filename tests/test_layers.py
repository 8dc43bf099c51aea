"""The package's layers: a module imports only from its own layer or the ones below, the import
graph has no cycle, the tracking method never imports the rendered-data generator (not even through
another module), and every module imports alone, with no other module of the package loaded; docs/layout.md names
every module, and a module name means one thing across the package."""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

LAYERS = (
    (
        "tracker.errors",
        "tracker.status",
        "tracker.atomic",
        "tracker.overwrite",
        "tracker.tomlfile",
        "tracker.npzfile",
        "tracker.stop_signals",
        "tracker.geometry",
    ),
    ("tracker.chain",),  # the joint algebra, which the model compiles its joints with
    ("tracker.model", "tracker.camera", "tracker.proportions", "tracker.evaluate"),
    ("tracker.raycast", "tracker.io"),  # the body's pixels in a camera; files and cameras in and out
    ("tracker.landmarks",),  # the detector's landmarks: names on the model, detection, cache, checks across views
    ("tracker.tracking",),  # the tracking method
    ("tracker.seeding", "tracker.shape", "tracker.calibrate", "tracker.physics", "tracker.viewer"),  # beside it
    ("tracker.synthetic",),  # the rendered-data generator, made to test the method and never imported by it
    ("tracker.apps",),  # what runs the method: tracker track's library form, live, bench
    ("tracker.commands", "tracker.cli"),
)
"""Bottom to top; a module belongs to the layer of the longest name here that it starts with."""


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path for path in sorted((ROOT / "tracker").rglob("*.py"))}


def layer(module: str) -> int:
    """The index in LAYERS of ``module``'s layer (the package ``tracker`` itself is below them all)."""
    if module == "tracker":
        return -1
    matches = [
        (len(prefix), index)
        for index, names in enumerate(LAYERS)
        for prefix in names
        if module == prefix or module.startswith(prefix + ".")
    ]
    if not matches:
        raise AssertionError(f"{module} is in no layer: add it to LAYERS")
    return max(matches)[1]


def imports(module: str, *, typing: bool = True) -> set[str]:
    """The modules of this package that ``module`` imports anywhere in its source (``from a import b``
    counts as a.b when that is a module); without ``typing``, not those imported only for type checking (under
    ``if TYPE_CHECKING:``), which are never imported when the program runs."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    package = module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
    typed = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
        for statement in node.body
        for inner in ast.walk(statement)
    }
    found = set()
    for node in ast.walk(tree):
        if not typing and id(node) in typed:
            continue
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(
                    package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else [])
                )
            names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base for alias in node.names]
        else:
            continue
        found |= {name for name in names if name in MODULES and name != module}
    return found


GRAPH = {module: imports(module) for module in MODULES}
RUNNING = {module: imports(module, typing=False) for module in MODULES}
"""The imports that run: a cue's module names the tracker it serves only for type checking (tracking/cue.py)."""


def test_every_module_has_a_layer():
    for module in MODULES:
        layer(module)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_module_imports_a_higher_layer(module):
    higher = sorted(name for name in GRAPH[module] if layer(name) > layer(module))
    assert not higher, f"{module} (layer {layer(module)}) imports {higher} from higher layers"


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    return found


def test_cycles_are_found():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_import_graph_has_no_cycle():
    assert cycles(RUNNING) == []


def test_imports_for_type_checking_alone_are_no_running_imports():
    assert "tracker.tracking.frame_loop" in GRAPH["tracker.tracking.cue"]
    assert "tracker.tracking.frame_loop" not in RUNNING["tracker.tracking.cue"]
    assert RUNNING["tracker.tracking.cues"] == GRAPH["tracker.tracking.cues"]


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    """The modules ``start`` imports, directly or through others."""
    found: set[str] = set()
    todo = [start]
    while todo:
        for other in graph[todo.pop()] - found:
            found.add(other)
            todo.append(other)
    return found


def inside(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


METHOD = sorted(module for module in MODULES if inside(module, "tracker.tracking"))


def test_reachable_follows_imports_through_others():
    assert reachable({"a": {"b"}, "b": {"c", "a"}, "c": set(), "d": {"a"}}, "a") == {"a", "b", "c"}
    assert reachable({"a": set(), "b": {"a"}}, "a") == set()


@pytest.mark.parametrize("module", METHOD)
def test_the_tracking_method_never_imports_the_generator(module):
    generator = sorted(name for name in reachable(GRAPH, module) if inside(name, "tracker.synthetic"))
    assert not generator, f"{module} imports {generator}, directly or through others"


def test_importing_the_tracking_method_loads_no_generator_module():
    """The same at run time: every module of the method imported in a fresh interpreter, none of the generator's
    is loaded."""
    code = "import sys; " + "; ".join(f"import {module}" for module in METHOD)
    code += "; print(' '.join(name for name in sys.modules if name.startswith('tracker.synthetic')))"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    assert done.stdout.split() == []


ALONE = """
import importlib, json, sys
failed = {}
for module in sys.argv[1:]:
    for loaded in [name for name in sys.modules if name == "tracker" or name.startswith("tracker.")]:
        del sys.modules[loaded]
    try:
        importlib.import_module(module)
    except Exception as error:
        failed[module] = f"{type(error).__name__}: {error}"
print(json.dumps(failed))
"""
"""Imports each module named on the command line with none of the package's modules loaded (each one before it
dropped from sys.modules), and prints the failures as JSON: module -> error."""


@pytest.fixture(scope="module")
def alone_failures() -> dict[str, str]:
    """Each module that fails to import alone, with its error: one interpreter imports them all in turn, each with
    none of the package loaded before it (the packages it imports from elsewhere, numpy, numba, OpenCV, stay loaded:
    they are not the package's layers, and loading them afresh for every module took most of this file's time)."""
    done = subprocess.run([sys.executable, "-c", ALONE, *sorted(MODULES)], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    return json.loads(done.stdout.splitlines()[-1])


def test_a_module_that_needs_another_loaded_first_fails_alone(tmp_path):
    """The check itself: a module that uses a name its package sets only when another module is loaded imports
    after that module, and fails alone."""
    package = tmp_path / "tracker"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "first.py").write_text("import tracker\ntracker.ready = True\n")
    (package / "second.py").write_text("import tracker\nassert tracker.ready\n")
    modules = ["tracker.first", "tracker.second"]
    together = subprocess.run([sys.executable, "-c", "import tracker.first, tracker.second"], cwd=tmp_path)
    done = subprocess.run([sys.executable, "-c", ALONE, *modules], cwd=tmp_path, capture_output=True, text=True)
    assert together.returncode == 0 and list(json.loads(done.stdout)) == ["tracker.second"]


@pytest.mark.parametrize("module", sorted(MODULES))
def test_module_imports_alone(module, alone_failures):
    assert module not in alone_failures, alone_failures[module]


LAYOUT = ROOT / "docs" / "layout.md"
FILES = sorted(path.relative_to(ROOT).as_posix() for path in (ROOT / "tracker").rglob("*.py"))
LISTED = set(re.findall(r"`(tracker/[\w/]+\.py)`", LAYOUT.read_text(encoding="utf-8")))


def test_the_layout_page_names_every_module():
    """docs/layout.md names every module by its path (a package's __init__.py aside), and only modules that exist."""
    missing = [path for path in FILES if path not in LISTED and not path.endswith("/__init__.py")]
    assert not missing, f"docs/layout.md does not list {missing}"
    stale = sorted(LISTED - set(FILES))
    assert not stale, f"docs/layout.md lists modules that do not exist: {stale}"


SHARED_NAMES = {
    "bench.py": {"tracker/commands/bench.py", "tracker/apps/bench.py"},
    "evaluate.py": {"tracker/commands/evaluate.py", "tracker/evaluate.py"},
    "experiment.py": {"tracker/commands/experiment.py", "tracker/physics/experiment.py"},
    "live.py": {"tracker/commands/live.py", "tracker/apps/live.py"},
    "points.py": {"tracker/commands/points.py", "tracker/physics/points.py"},
    "refine.py": {"tracker/commands/refine.py", "tracker/calibrate/refine.py"},
    "suite.py": {"tracker/commands/suite.py", "tracker/synthetic/suite.py"},
    "sync.py": {"tracker/commands/sync.py", "tracker/apps/sync.py"},
    "synth.py": {"tracker/commands/synth.py", "tracker/synthetic/synth.py"},
    "track.py": {"tracker/commands/track.py", "tracker/apps/track.py"},
}
"""The module names two packages share: each a command's module (its options and output) and the one module that is
that command's library form, which the command calls to do its work."""


def test_a_module_name_means_one_thing():
    """No module name is used in two packages, but for a command's module and its library form
    (:data:`SHARED_NAMES`, which holds no more than those)."""
    by_name: dict[str, set[str]] = {}
    for path in FILES:
        if not path.endswith("/__init__.py"):
            by_name.setdefault(path.rpartition("/")[2], set()).add(path)
    shared = {name: paths for name, paths in by_name.items() if len(paths) > 1}
    assert shared == SHARED_NAMES


@pytest.mark.parametrize("name", sorted(SHARED_NAMES))
def test_a_command_shares_its_name_with_the_module_it_calls(name):
    command = f"tracker/commands/{name}"
    (library,) = SHARED_NAMES[name] - {command}
    assert module_name(ROOT / library) in GRAPH[module_name(ROOT / command)]
