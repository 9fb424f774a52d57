"""Every package declares what it imports: an image built from one folder's pyproject.toml must
not depend on what another package happened to pull in (the web's WebSocket once worked only
because MuJoCo brought `websockets`)."""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = sorted(p.parent for p in [*ROOT.glob("libs/*/pyproject.toml"), *ROOT.glob("services/*/pyproject.toml")])


def _name(requirement: str) -> str:
    """`opencv-python-headless>=4.9` -> `opencv-python-headless`, normalised as PEP 503 says."""
    bare = re.split(r"[<>=!~;\[ ]", requirement, maxsplit=1)[0]
    return re.sub(r"[-_.]+", "-", bare).lower()


def declared(folder: Path) -> set[str]:
    project = tomllib.loads((folder / "pyproject.toml").read_text())["project"]
    return {_name(r) for r in project.get("dependencies", [])}


def sources(folder: Path) -> list[Path]:
    """The folder's code; the test helpers' package is there for tests/ and bench/, so theirs too."""
    paths = sorted(folder.glob("asibot*/**/*.py"))
    if folder.name == "testing":
        paths += sorted(ROOT.glob("tests/**/*.py")) + sorted(ROOT.glob("bench/**/*.py"))
    return paths


def imported(folder: Path) -> dict[str, str]:
    """Top-level modules imported by the folder's code, each with one file that imports it."""
    found: dict[str, str] = {}
    for path in sources(folder):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                # A script's own neighbour, or a test folder a bench borrows a double from.
                if not (path.parent / f"{top}.py").exists() and not (ROOT / "tests" / top).is_dir():
                    found.setdefault(top, str(path.relative_to(ROOT)))
    return found


#: Module -> distribution where the distribution installs it in a way importlib cannot see
#: (pin puts pinocchio under its own prefix, reached through a .pth file).
DISTRIBUTIONS = {**metadata.packages_distributions(), "pinocchio": ["pin"]}
#: Our own modules (tests import their helpers as top-level modules) and typing-only names.
OURS = {"asibot", "asibot_testing", "__future__", "_typeshed", "tests"}


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda f: str(f.relative_to(ROOT)))
def test_every_third_party_import_is_declared_by_the_package_that_imports_it(folder: Path) -> None:
    # Tests and benches run with the whole workspace installed: any package may declare theirs.
    own = set().union(*map(declared, FOLDERS)) if folder.name == "testing" else declared(folder)
    missing = []
    for module, where in imported(folder).items():
        if module in sys.stdlib_module_names or module in OURS:
            continue
        dists = {_name(d) for d in DISTRIBUTIONS.get(module, [])}
        assert dists, f"{where} imports {module!r}, which no installed distribution provides"
        if not dists & own:
            missing.append(f"{module} ({' or '.join(sorted(dists))}, imported by {where})")
    assert not missing, f"{folder.relative_to(ROOT)}/pyproject.toml should declare: " + "; ".join(missing)


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda f: str(f.relative_to(ROOT)))
def test_every_declared_dependency_is_imported(folder: Path) -> None:
    """A dependency nobody imports is weight in every image (lz4 came with mcap all along)."""
    uses = {_name(d) for m in imported(folder) for d in DISTRIBUTIONS.get(m, [])}
    unused = [d for d in declared(folder) if not d.startswith("asibot-") and d not in uses and d not in RUNTIME_ONLY]
    assert not unused, f"{folder.relative_to(ROOT)}/pyproject.toml declares what no module of it imports: {unused}"


#: Needed at run time without an import statement: a command-line tool (the tests run mypy and
#: pyflakes, requirements/lock runs uv), a type stub, a plugin pytest loads by itself, what
#: uvicorn (WebSocket) and FastAPI (forms) load when a route needs it.
RUNTIME_ONLY = {"pytest-timeout", "pytest-xdist", "types-pyyaml", "mypy", "pyflakes", "uv", "websockets", "python-multipart"}
