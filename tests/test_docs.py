"""What the code and the documents point a reader at exists, and nothing else is pointed at.

* No reference to files a user of the repository does not have (design notes kept
  outside it) and no issue numbers, in the package's sources, the README or ``docs/``.
* No nickname of a source paper (``S0`` ... ``S4``): papers are cited by author and
  year, with the bibliography in ``docs/references.md``.
* Every ``docs/<file>`` named in the package's sources, the README or ``docs/`` exists,
  and every relative Markdown link of the README and ``docs/`` resolves.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

UNAVAILABLE = re.compile(r"SEEDS\.md|DESIGN\.md|shared/design|\bissues?\s+#?\d+", re.IGNORECASE)
"""References to files outside the repository, and issue numbers."""

NICKNAME = re.compile(r"\bS[0-4]\b")
"""``S0`` ... ``S4``: the papers' nicknames."""

DOCS_PATH = re.compile(r"(?<![\w./-])docs/([\w.-]+(?:/[\w.-]+)*)")
"""``docs/<path>`` not preceded by another path component (``foo/docs/x`` is not ours)."""

MD_LINK = re.compile(r"\]\(([^)\s]+)\)")
"""The target of a Markdown link ``[text](target)``."""


def texts() -> list[Path]:
    """Every file the rules apply to: package sources, the README, the documents."""
    return [
        *sorted((ROOT / "companion").rglob("*.py")),
        ROOT / "README.md",
        *sorted(DOCS.glob("*.md")),
    ]


def _matches(pattern: re.Pattern[str]) -> list[str]:
    found: list[str] = []
    for path in texts():
        if not path.is_file():
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            m = pattern.search(line)
            if m:
                found.append(f"{path.relative_to(ROOT)}:{n}: {m.group(0)!r} in {line.strip()}")
    return found


def test_no_reference_to_files_users_do_not_have() -> None:
    found = _matches(UNAVAILABLE)
    assert found == [], "references a reader cannot follow:\n" + "\n".join(found)


def test_papers_are_cited_by_author_not_nickname() -> None:
    found = _matches(NICKNAME)
    assert found == [], "paper nicknames (cite author and year):\n" + "\n".join(found)


def test_the_documents_exist() -> None:
    for name in ("architecture", "mavlink", "replay", "methods", "references"):
        assert (DOCS / f"{name}.md").is_file(), f"docs/{name}.md is missing"


def test_named_docs_paths_exist() -> None:
    missing: list[str] = []
    for path in texts():
        if not path.is_file():
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for m in DOCS_PATH.finditer(line):
                target = m.group(1).rstrip(".")
                if not (DOCS / target).exists():
                    missing.append(f"{path.relative_to(ROOT)}:{n}: docs/{target}")
    assert missing == [], "paths under docs/ that do not exist:\n" + "\n".join(missing)


def anchors(path: Path) -> set[str]:
    """The anchors of a Markdown file's headings, as GitHub makes them."""
    found: set[str] = set()
    in_code = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            found.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return found


def test_markdown_links_resolve() -> None:
    broken: list[str] = []
    for path in [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for m in MD_LINK.finditer(line):
                target, _, anchor = m.group(1).partition("#")
                if re.match(r"^[a-z][a-z0-9+.-]*:", target):
                    continue  # a URL
                linked = path.parent / target if target else path
                if not linked.exists():
                    broken.append(f"{path.relative_to(ROOT)}:{n}: {m.group(1)}")
                elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
                    broken.append(f"{path.relative_to(ROOT)}:{n}: {m.group(1)} (no such heading)")
    assert broken == [], "Markdown links to nothing:\n" + "\n".join(broken)


def test_the_patterns_catch_what_they_are_for() -> None:
    """A mutation check: each rule fires on a line that breaks it, and not on its neighbours."""
    assert UNAVAILABLE.search("see ../shared/design/DESIGN.md")
    assert UNAVAILABLE.search("(issue 5)") and UNAVAILABLE.search("Issue #12")
    assert UNAVAILABLE.search("SEEDS.md §S0")
    assert not UNAVAILABLE.search("an issue of timing")
    assert NICKNAME.search("paper S4") and NICKNAME.search("(S0)")
    assert not NICKNAME.search("S40 and s0 and GPS1")
    assert [m.group(1) for m in DOCS_PATH.finditer("see docs/methods.md.")] == ["methods.md."]
    assert not DOCS_PATH.search("https://example.org/docs/x.html")
    assert MD_LINK.search("[a](methods.md#1-position-potential-filter)")
