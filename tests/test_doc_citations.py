"""Every ``§`` citation resolves inside the repository, in docs/protocols.md (issue 15).

The code cites protocol facts by section (``§2.4``, ``§4.2 step 3``). Those sections used to live in
a note outside the repository; they are now docs/protocols.md, with the same numbers. These tests
read the text of the repository: each cited section is a heading there, each cited step is a
numbered item of its section, and nothing points at the old location any more.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTES = ROOT / "docs" / "protocols.md"
SCANNED = ("urdaemon", "tests", "docs", "resources", "benchmarks")
"""Top-level directories whose text may cite the notes."""
SUFFIXES = frozenset({".py", ".md", ".yaml", ".lark", ".urscript", ".txt", ".sh"})

OLD_HOME = "shared" + "/docs"
"""The directory the notes lived in outside the repository (split so this file does not name it)."""
NO_OLD_HOME = ("urdaemon", "docs", "resources")

CITATION = re.compile(r"(datasheet )?§(\d+(?:\.\d+)*)(?: step (\d+))?")
"""A citation, with an optional step; ``datasheet §7.3.3`` cites a chip's datasheet, not our notes."""
HEADING = re.compile(r"^#{2,4} §(\d+(?:\.\d+)*) ", re.MULTILINE)


def _files(tops: tuple[str, ...]) -> list[Path]:
    found: list[Path] = []
    for top in tops:
        found += [p for p in sorted((ROOT / top).rglob("*")) if p.is_file() and p.suffix in SUFFIXES]
    return found


def _sections() -> dict[str, str]:
    """Section number → its text up to the next numbered heading."""
    text = NOTES.read_text(encoding="utf-8")
    heads = list(HEADING.finditer(text))
    return {
        m.group(1): text[m.end() : heads[i + 1].start() if i + 1 < len(heads) else len(text)]
        for i, m in enumerate(heads)
    }


def _citations() -> list[tuple[str, int, str, str | None]]:
    """(file, line, section, step or None) for every citation of our notes in the scanned text."""
    found = []
    for path in _files(SCANNED):
        if path == Path(__file__).resolve():
            continue  # this file names the exceptions
        rel = path.relative_to(ROOT).as_posix()
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            found += [(rel, number, m[2], m[3]) for m in CITATION.finditer(line) if not m[1]]
    return found


def test_the_notes_number_their_sections_once() -> None:
    heads = HEADING.findall(NOTES.read_text(encoding="utf-8"))
    assert len(heads) == len(set(heads)), sorted(h for h in heads if heads.count(h) > 1)
    assert {"0", "1", "2", "3", "4", "5", "6"} <= set(heads)


def test_the_code_cites_sections_at_all() -> None:
    """A guard for the tests below: the scan finds the code's citations (~200 of them today)."""
    assert len(_citations()) > 150


def test_every_citation_names_a_section_of_the_notes() -> None:
    """Reproduction: before docs/protocols.md existed every citation pointed outside the repository."""
    sections = _sections()
    missing = [
        f"{rel}:{line}: §{section}" for rel, line, section, _ in _citations() if section not in sections
    ]
    assert not missing, "cited sections with no heading in docs/protocols.md:\n" + "\n".join(missing)


def test_every_cited_step_is_an_item_of_its_section() -> None:
    sections = _sections()
    missing = [
        f"{rel}:{line}: §{section} step {step}"
        for rel, line, section, step in _citations()
        if step is not None
        and section in sections
        and not re.search(rf"^\s*{step}\. ", sections[section], re.MULTILINE)
    ]
    assert not missing, "cited steps that are no numbered item of their section:\n" + "\n".join(missing)


def test_nothing_names_the_notes_old_home() -> None:
    """Reproduction: protocols/__init__.py named the note outside the repository as the reference."""
    naming = {p.relative_to(ROOT).as_posix() for p in _files(NO_OLD_HOME) if OLD_HOME in p.read_text("utf-8")}
    assert not naming, f"these still name {OLD_HOME}: {sorted(naming)}"


def test_the_protocols_package_names_the_notes() -> None:
    import urdaemon.protocols

    assert "docs/protocols.md" in (urdaemon.protocols.__doc__ or "")
