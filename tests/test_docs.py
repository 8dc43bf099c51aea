"""The code cites the pages that ship with it, and nothing outside the repository; the pages carry no dates."""

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


PAGES = sorted((ROOT / "docs").glob("*.md"))
MONTHS = "January|February|March|April|May|June|July|August|September|October|November|December"
SHORT = "Jan|Feb|Mar|Apr|Jun|Jul|Aug|Sep|Sept|Oct|Nov|Dec"
DATE = re.compile(rf"\b\d{{4}}-\d{{2}}-\d{{2}}\b|\b(?:{MONTHS}|(?:{SHORT})\.?) \d{{4}}\b")
"""A date: ISO (2026-11-29) or a month and a year (November 2026, Nov. 2026)."""


def test_dates_are_found():
    assert DATE.findall("measured on 2026-11-29, and again in December 2026 and Nov. 2026") == [
        "2026-11-29",
        "December 2026",
        "Nov. 2026",
    ]
    assert not DATE.findall("Drummond & Cipolla (ICCV 2001), frames 200-598, NSF EIA-0196217, seed 2026")


@pytest.mark.parametrize("page", [ROOT / "README.md", *PAGES], ids=lambda p: str(p.relative_to(ROOT)))
def test_reference_pages_carry_no_dates(page):
    """The pages say what the code does now; when something changed is CHANGELOG.md's to say."""
    lines = page.read_text(encoding="utf-8").splitlines()
    dated = [f"line {i}: {m}" for i, line in enumerate(lines, 1) for m in DATE.findall(line)]
    assert not dated, f"{page.relative_to(ROOT)} has dates: {dated}"


def _headings(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {heading.replace("`", "").strip() for heading in re.findall(r"^#+ (.+)$", text, re.M)}


QUOTED = re.compile(r"(docs/[a-z-]+\.md)[,:]? \"([^\"]+)\"")


CITING = SOURCES + sorted((ROOT / "tests").rglob("*.py"))


@pytest.mark.parametrize("source", CITING, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_quoted_section_exists(source):
    """A page's section that the code cites by its quoted heading is a heading of that page (or the part before its
    colon)."""
    text = " ".join(source.read_text(encoding="utf-8").split())  # a heading may break across lines
    missing = []
    for page, quoted in QUOTED.findall(text):
        headings = _headings(ROOT / page)
        if not any(h == quoted or h.startswith(quoted + ":") for h in headings):
            missing.append(f'{page}, "{quoted}"')
    assert not missing, f"{source.relative_to(ROOT)} cites sections that docs/ lacks: {missing}"
