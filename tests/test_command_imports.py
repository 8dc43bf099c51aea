"""The command layer sits on top: no module outside tracker/commands/ and tracker/cli.py imports them."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "tracker"
TOP = ("tracker.cli", "tracker.commands")


def _imported(path: Path) -> set[str]:
    """Every module and module.name that ``path`` imports (``from a import b`` counts as a and a.b)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _is_top(name: str) -> bool:
    return any(name == top or name.startswith(top + ".") for top in TOP)


def test_nothing_below_the_commands_imports_them():
    below = [
        path
        for path in PACKAGE.rglob("*.py")
        if path != PACKAGE / "cli.py" and PACKAGE / "commands" not in path.parents
    ]
    offenders = {str(path.relative_to(PACKAGE)): sorted(filter(_is_top, _imported(path))) for path in below}
    assert {path: names for path, names in offenders.items() if names} == {}
    assert len(below) > 50  # the scan saw the package
