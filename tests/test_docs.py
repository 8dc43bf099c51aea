"""The code cites the method pages that ship with it, and nothing outside the repository."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "tracker"
SOURCES = sorted(PACKAGE.rglob("*.py"))
CITED = re.compile(r"(?:(docs/method-[a-z]+\.md)[,:] )?[Ss]ections? (\d+(?:(?:-| and |, )\d+)*)")


def _sections(page: str) -> set[int]:
    return {int(n) for n in re.findall(r"^## (\d+)\. ", (ROOT / page).read_text(encoding="utf-8"), re.M)}


def citations(text: str, default: str = "docs/method-tracking.md") -> list[tuple[str, int]]:
    """(page, section) of every 'section N' in ``text``: a bare one refers to the first method page the
    text names, else to ``default``."""
    named = re.search(r"docs/method-[a-z]+\.md", text)
    default = named.group(0) if named else default
    out = []
    for page, numbers in CITED.findall(text):
        for part in re.split(r" and |, ", numbers):
            first, _, last = part.partition("-")
            out += [(page or default, n) for n in range(int(first), int(last or first) + 1)]
    return out


def test_citations_are_parsed():
    text = "docs/method-physics.md, sections 2-4; section 1 and section 6, 7"
    assert citations(text) == [("docs/method-physics.md", n) for n in (2, 3, 4, 1, 6, 7)]
    assert citations("(section 5, eqs 23-25)") == [("docs/method-tracking.md", 5)]


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_cited_section_exists(source):
    default = "docs/method-physics.md" if "physics" in source.parts else "docs/method-tracking.md"
    cited = citations(source.read_text(encoding="utf-8"), default)
    missing = [f"{page} {n}" for page, n in cited if n not in _sections(page)]
    assert not missing, f"{source.relative_to(ROOT)} cites sections that docs/ lacks: {missing}"


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_code_points_inside_the_repository(source):
    text = " ".join(source.read_text(encoding="utf-8").split())  # a phrase may break across lines
    assert "shared/" not in text and '"shared"' not in text and "design note" not in text.lower()
