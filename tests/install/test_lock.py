"""The lock files agree with the pyproject.toml files: what a package declares is pinned, at a
version it allows, with hashes; the test lock is the runtime lock plus the test packages.
(requirements/lock resolves them again when this fails.)"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[2]
REQUIREMENTS = ROOT / "requirements"
OURS = {canonicalize_name(tomllib.loads(p.read_text())["project"]["name"])
        for p in [*ROOT.glob("libs/*/pyproject.toml"), *ROOT.glob("services/*/pyproject.toml")]}
#: The interpreter the lock is installed on here and in the image.
HERE = {"python_version": "3.11", "python_full_version": "3.11.2", "sys_platform": "linux",
        "platform_python_implementation": "CPython", "implementation_name": "cpython"}


def pins(lock: str) -> dict[str, str]:
    """name -> version of every requirement of a lock file that applies to Python 3.11 on Linux,
    after checking that each one carries at least one hash."""
    text = (REQUIREMENTS / lock).read_text()
    found: dict[str, str] = {}
    for entry in re.split(r"\n(?=[a-z0-9])", text):
        first = entry.split("\\")[0].strip()
        if not first or first.startswith(("#", "-")):
            continue
        req = Requirement(first)
        assert "--hash=sha256:" in entry, f"{lock}: {req.name} has no hash"
        if req.marker is None or req.marker.evaluate(HERE):
            (spec,) = req.specifier
            assert spec.operator == "==", f"{lock}: {first} is not pinned"
            found[canonicalize_name(req.name)] = spec.version
    return found


def declared(folder: Path) -> list[Requirement]:
    return [Requirement(r) for r in tomllib.loads((folder / "pyproject.toml").read_text())["project"]["dependencies"]]


FOLDERS = sorted(p.parent for p in [*ROOT.glob("libs/*/pyproject.toml"), *ROOT.glob("services/*/pyproject.toml")])


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda f: str(f.relative_to(ROOT)))
def test_every_declared_dependency_is_pinned_at_a_version_it_allows(folder: Path) -> None:
    lock = "test.txt" if folder.name == "testing" else "runtime.txt"
    pinned = pins(lock)
    for req in declared(folder):
        name = canonicalize_name(req.name)
        if name in OURS:
            continue
        assert name in pinned, f"{folder.relative_to(ROOT)} needs {req}, which requirements/{lock} lacks: run requirements/lock"
        assert req.specifier.contains(pinned[name], prereleases=True), (
            f"{folder.relative_to(ROOT)} needs {req}, requirements/{lock} pins {pinned[name]}: run requirements/lock")


def test_the_test_lock_is_the_runtime_lock_plus_the_test_packages() -> None:
    runtime, test = pins("runtime.txt"), pins("test.txt")
    differ = {n: (v, test.get(n)) for n, v in runtime.items() if test.get(n) != v}
    assert not differ, f"requirements/test.txt pins these differently from runtime.txt: {differ}"


def test_our_own_packages_are_not_in_the_locks() -> None:
    """bootstrap installs them editable; a pin of ours would fetch a stranger's package of that name."""
    for lock in ("runtime.txt", "test.txt", "build.txt"):
        assert not OURS & set(pins(lock)), lock
