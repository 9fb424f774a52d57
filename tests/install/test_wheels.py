"""What is installed without the source tree (the Docker image, a robot's wheel) carries every
file of the source: the page's scripts and styles, the worlds, maps, robot files and setups. An
editable install cannot show a file left out, so each folder is built into a wheel here."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = sorted(p.parent for p in [*ROOT.glob("libs/*/pyproject.toml"), *ROOT.glob("services/*/pyproject.toml")])


def tracked(folder: Path) -> set[str]:
    """The package's files git knows, as paths inside the wheel (asibot/...)."""
    out = subprocess.run(["git", "ls-files", "--", "asibot*"], cwd=folder, capture_output=True, text=True, check=True)
    return {line for line in out.stdout.splitlines() if "__pycache__" not in line}


@pytest.mark.slow
def test_every_file_of_a_package_is_in_its_wheel(tmp_path: Path) -> None:
    # Built from a copy of what git tracks: setuptools writes build/ beside the sources.
    copies = []
    for folder in FOLDERS:
        copy = tmp_path / "src" / folder.name
        for name in subprocess.run(["git", "ls-files"], cwd=folder, capture_output=True, text=True,
                                   check=True).stdout.splitlines():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(folder / name, copy / name)
        copies.append(copy)
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                    "--wheel-dir", str(wheels), *map(str, copies)], check=True, capture_output=True)
    missing = {}
    for folder in FOLDERS:
        wheel = next(wheels.glob(f"asibot_{folder.name}-*.whl"))
        inside = set(zipfile.ZipFile(wheel).namelist())
        lost = sorted(tracked(folder) - inside)
        if lost:
            missing[str(folder.relative_to(ROOT))] = lost
    assert not missing, f"files the wheels leave out (pyproject.toml's package-data): {missing}"
