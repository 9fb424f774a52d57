"""The source tree is what the tools see: every folder is a package of the `asibot` namespace,
every `asibot` import resolves to a file in the tree, and mypy passes over all of it."""

from __future__ import annotations

import ast
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = sorted(p.parent for p in [*ROOT.glob("libs/*/pyproject.toml"), *ROOT.glob("services/*/pyproject.toml")])


def _sources() -> list[Path]:
    return [f for folder in ("libs", "services", "tests", "bench") for f in (ROOT / folder).rglob("*.py")
            if "node_modules" not in f.parts and "build" not in f.parts]


def _resolves(module: str) -> bool:
    """Whether `module` is a file or a package folder under one of the package roots."""
    parts = module.split(".")
    for root in PACKAGES:
        base = root.joinpath(*parts)
        if base.with_suffix(".py").is_file() or (base / "__init__.py").is_file():
            return True
        if base.is_dir() and len(parts) <= 2:   # a namespace folder: asibot itself, asibot.examples
            return True
    return False


def _asibot_imports(path: Path) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "asibot"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "asibot":
            found.append((node.lineno, node.module))
            for a in node.names:   # `from asibot import keys`: keys is a module here
                if _resolves(f"{node.module}.{a.name}"):
                    found.append((node.lineno, f"{node.module}.{a.name}"))
    return found


def test_every_asibot_import_resolves_to_a_file_in_the_tree() -> None:
    unresolved = [f"{path.relative_to(ROOT)}:{line}: {module}"
                  for path in _sources() for line, module in _asibot_imports(path) if not _resolves(module)]
    assert not unresolved, "imports that name no file of the tree:\n" + "\n".join(unresolved)


def test_every_service_imports_the_contract_it_keeps() -> None:
    """The import graph, read from the source alone, has each service's arrows to libs/common."""
    for service in sorted((ROOT / "services").glob("*/pyproject.toml")):
        name = service.parent.name
        targets = {module for path in (service.parent / "asibot").rglob("*.py")
                   for _, module in _asibot_imports(path)}
        assert any(t.startswith(f"asibot.{name}.") for t in targets), f"{name}: no import of its own modules"
        common = {t for t in targets if _resolves(t) and (ROOT / "libs/common").joinpath(*t.split(".")).with_suffix(".py").exists()}
        assert common, f"{name}: imports nothing of libs/common (asibot.keys, asibot.messages, ...)"


def test_the_namespace_has_no_init_and_every_package_is_checked_and_installed() -> None:
    """`asibot` is shared: an __init__.py in one folder would hide all the others. mypy and
    ./bootstrap must both know every package folder."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    roots = set(config["mypy_path"].split(":"))
    for package in PACKAGES:
        rel = str(package.relative_to(ROOT))
        assert not (package / "asibot" / "__init__.py").exists(), f"{rel}/asibot/__init__.py hides the namespace"
        assert (package / "asibot").is_dir(), f"{rel}: its code belongs in {rel}/asibot/"
        assert rel in roots, f"{rel} is missing from [tool.mypy] mypy_path in pyproject.toml"
        project = tomllib.loads((package / "pyproject.toml").read_text())["project"]
        assert project["name"].startswith("asibot-"), f"{rel}: name the package asibot-<folder>"


def test_data_is_found_through_the_package_not_by_counting_folders() -> None:
    offenders = []
    for folder in ("libs", "services"):
        for path in (ROOT / folder).rglob("*.py"):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if "__file__" in line and ".parent" in line:
                    offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not offenders, "use importlib.resources.files('asibot.<package>'):\n" + "\n".join(offenders)


def test_mypy_passes_over_the_whole_tree() -> None:
    result = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]
