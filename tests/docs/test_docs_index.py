"""A newcomer can find their way: docs/README.md lists every page, every link leads to a file,
the variables table names exactly what the code reads, and the licence the packages declare
is in the tree."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
INDEX = DOCS / "README.md"
VARIABLES = DOCS / "configuration.md"
#: Where the stack reads its environment: the code, the deployment, the installer and CI.
SOURCES = ("libs", "services", "compose.yaml", "Dockerfile", "bootstrap", ".ci")
#: Folders of generated or third-party files (npm packages, the bundled page libraries, caches):
#: a name in them is not one the stack reads.
SKIP = {"node_modules", "vendor", "__pycache__", "build"}
NAME = re.compile(r"ASIBOT_[A-Z0-9_]+")
LINK = re.compile(r"\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def _pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def _links(page: Path) -> list[str]:
    """The targets of the page's Markdown links; code blocks and code spans show links, they
    are not links."""
    text = re.sub(r"^```.*?^```", "", page.read_text(encoding="utf-8"), flags=re.S | re.M)
    text = re.sub(r"`[^`\n]*`", "", text)
    return LINK.findall(text)


def _local(page: Path, target: str) -> Path | None:
    """The file a relative link points at; None for a web address or an anchor of the page."""
    if SCHEME.match(target) or target.startswith("#"):
        return None
    path = target.split("#", 1)[0].split("?", 1)[0]
    return (page.parent / path).resolve() if path else None


def _source_files() -> list[Path]:
    files = []
    for name in SOURCES:
        top = ROOT / name
        candidates = top.rglob("*") if top.is_dir() else [top]
        for path in candidates:
            parts = path.relative_to(ROOT).parts
            if path.is_file() and not any(p in SKIP or p.endswith(".egg-info") for p in parts):
                files.append(path)
    return files


def _names_in_code() -> dict[str, list[str]]:
    """Each ASIBOT_* name of the source, with the files it appears in."""
    found: dict[str, list[str]] = {}
    for path in _source_files():
        data = path.read_bytes()
        if b"\0" in data[:8192]:    # an image, a mesh: no text to read
            continue
        for name in set(NAME.findall(data.decode("utf-8", errors="replace"))):
            found.setdefault(name, []).append(str(path.relative_to(ROOT)))
    return found


def _names_in_table() -> list[str]:
    rows = [line for line in VARIABLES.read_text(encoding="utf-8").splitlines() if line.startswith("| `ASIBOT_")]
    return [row.split("|")[1].strip().strip("`") for row in rows]


def test_every_page_is_in_the_index() -> None:
    """A page that the index does not list is a page nobody finds."""
    linked = {target for target in (_local(INDEX, t) for t in _links(INDEX)) if target is not None}
    missing = [str(p.relative_to(ROOT)) for p in _pages() if p != INDEX and p.resolve() not in linked]
    assert not missing, "add a line for each to docs/README.md:\n" + "\n".join(missing)


def test_every_relative_link_leads_to_a_file() -> None:
    """A renamed or moved file must not leave a reader at a dead link."""
    broken = []
    for page in [ROOT / "README.md", *_pages()]:
        for target in _links(page):
            path = _local(page, target)
            if path is not None and not path.exists():
                broken.append(f"{page.relative_to(ROOT)}: ({target})")
    assert not broken, "links to nothing:\n" + "\n".join(broken)


def test_the_variables_table_names_what_the_code_reads() -> None:
    """An owner looks a setting up in docs/configuration.md: every variable the code reads is
    there, and a row for a variable the code dropped would send them after a setting that does
    nothing."""
    in_code = _names_in_code()
    rows = _names_in_table()
    assert len(rows) == len(set(rows)), f"a variable has two rows: {sorted(n for n in rows if rows.count(n) > 1)}"
    missing = sorted(set(in_code) - set(rows))
    assert not missing, "add a row to docs/configuration.md for:\n" + "\n".join(
        f"{name} (in {', '.join(sorted(in_code[name])[:3])})" for name in missing)
    stale = sorted(set(rows) - set(in_code))
    assert not stale, f"no code reads these any more; remove their rows from docs/configuration.md: {stale}"


def test_the_licence_is_in_the_tree() -> None:
    """Every package declares Apache-2.0 (pyproject.toml), whose text must go with the code, whole."""
    licence = ROOT / "LICENSE"
    assert licence.is_file(), "LICENSE is missing at the repository's root"
    text = licence.read_text(encoding="utf-8")
    assert text.lstrip().startswith("Apache License"), "LICENSE must be the Apache License 2.0 text"
    for part in ("Version 2.0, January 2004", "END OF TERMS AND CONDITIONS",
                 "APPENDIX: How to apply the Apache License to your work."):
        assert part in text, f"LICENSE is not the full Apache License 2.0 text: {part!r} is missing"
