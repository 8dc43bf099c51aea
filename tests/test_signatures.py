"""Public signatures: no public function or method of the package takes more than three positional parameters
(self and cls not counted); what follows the data a function acts on is keyword-only (``*``).

Scanned: the module-level functions of every module under tracker/ and the methods of its classes. Not scanned:
names starting with ``_`` (private ones, and the dunders whose signature Python fixes: ``__init__``, ``__exit__``,
``__call__``), functions nested in others, and numba kernels (``@njit``/``@jit``), which keep their arrays
positional. Callbacks whose signature an outside API fixes (scipy.optimize's ``fun(x, *args)``, thread and process
targets, argparse actions) are all private or lambdas today; one that is not goes in :data:`ALLOWED` by name."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

MOST = 3
"""The positional parameters a public function may take."""

ALLOWED: tuple[str, ...] = ()
"""Paths (a folder ends in /) or ``path:qualified.name`` entries exempt from the rule; each must still hold an
offender (test_the_allow_list_is_exact)."""

NUMBA = {"njit", "jit"}


def _decorator_name(node: ast.expr) -> str:
    node = node.func if isinstance(node, ast.Call) else node
    return node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else ""


def positional(function: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> list[str]:
    """The names of ``function``'s positional parameters, less a method's self or cls."""
    names = [arg.arg for arg in function.args.posonlyargs + function.args.args]
    static = any(_decorator_name(d) == "staticmethod" for d in function.decorator_list)
    return names[1:] if method and not static and names[:1] in (["self"], ["cls"]) else names


def offenders(source: str) -> list[tuple[str, list[str]]]:
    """(qualified name, positional parameters) of each public function or method in ``source`` (module text)
    that takes more than :data:`MOST` positional parameters, numba kernels aside."""
    found = []

    def visit(body: list[ast.stmt], prefix: str, in_class: bool) -> None:
        for node in body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                visit(node.body, f"{prefix}{node.name}.", True)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
                if any(_decorator_name(d) in NUMBA for d in node.decorator_list):
                    continue
                names = positional(node, in_class)
                if len(names) > MOST:
                    found.append((prefix + node.name, names))
            elif isinstance(node, (ast.If, ast.Try, ast.With)):  # definitions under a module's if, try or with
                for part in [node.body, getattr(node, "orelse", []), getattr(node, "finalbody", [])]:
                    visit(part, prefix, in_class)
                for handler in getattr(node, "handlers", []):
                    visit(handler.body, prefix, in_class)

    visit(ast.parse(source).body, "", False)
    return found


def _allowed(path: str, name: str) -> str | None:
    """The entry of :data:`ALLOWED` that exempts ``name`` in ``path`` (relative, with /), if any."""
    for entry in ALLOWED:
        where, _, qualified = entry.partition(":")
        if (path.startswith(where) if where.endswith("/") else path == where) and qualified in ("", name):
            return entry
    return None


def _scan() -> list[tuple[str, str, list[str]]]:
    return [
        (path.relative_to(ROOT).as_posix(), name, names)
        for path in sorted((ROOT / "tracker").rglob("*.py"))
        for name, names in offenders(path.read_text(encoding="utf-8"))
    ]


SCANNED = _scan()


def test_the_scan_counts_positional_parameters():
    source = """
def four(a, b, c, d): ...
def three_then_options(a, b, c, *, d, e=1): ...
def only_positional(a, b, /, c, d): ...
def with_args(a, b, c, d, *rest): ...
def _private(a, b, c, d): ...
@njit(cache=True)
def kernel(a, b, c, d): ...
@numba.jit
def other_kernel(a, b, c, d): ...
def outer(a):
    def nested(a, b, c, d): ...
try:
    import fast
except ImportError:
    def fallback(a, b, c, d): ...
class Thing:
    def method(self, a, b, c): ...
    def wide(self, a, b, c, d): ...
    @classmethod
    def make(cls, a, b, c): ...
    @staticmethod
    def plain(a, b, c, d): ...
    def __init__(self, a, b, c, d): ...
class _Hidden:
    def wide(self, a, b, c, d): ...
"""
    assert [name for name, _ in offenders(source)] == [
        "four",
        "only_positional",
        "with_args",
        "fallback",
        "Thing.wide",
        "Thing.plain",
    ]


def test_no_public_function_takes_more_than_three_positional_parameters():
    wide = [f"{path}: {name}({', '.join(names)})" for path, name, names in SCANNED if _allowed(path, name) is None]
    assert not wide, f"more than {MOST} positional parameters: put a `*` after the data each acts on\n" + "\n".join(
        wide
    )


@pytest.mark.parametrize("entry", ALLOWED)
def test_the_allow_list_is_exact(entry):
    """Each entry names something that exists and still needs it: a fixed one leaves the list."""
    where = entry.partition(":")[0]
    assert (ROOT / where).exists(), f"{entry}: no such path"
    assert any(_allowed(path, name) == entry for path, name, _ in SCANNED), f"{entry} exempts nothing: remove it"
