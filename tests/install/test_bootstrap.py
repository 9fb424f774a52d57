"""`./bootstrap` as another user than root: it names what is missing, says how to get it, and
stops before it changes anything. Debian's package tools are stood in for by small scripts, so
the test sees what bootstrap would say on a machine with other packages than this one."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def machine(tmp_path: Path):
    """A PATH whose `id` says uid 1000 and whose dpkg knows the packages it is given."""
    def make(installed: dict[str, str]) -> subprocess.CompletedProcess:
        tools = tmp_path / "bin"
        tools.mkdir(exist_ok=True)
        known = " ".join(f"{name}={version}" for name, version in installed.items())
        (tools / "id").write_text('#!/bin/sh\necho 1000\n')
        # dpkg -s NAME: installed or not; dpkg --compare-versions: the real one.
        (tools / "dpkg").write_text(f"""#!/bin/sh
[ "$1" = --compare-versions ] && exec /usr/bin/dpkg "$@"
for p in {known}; do [ "${{p%%=*}}" = "$2" ] && exit 0; done
exit 1
""")
        (tools / "dpkg-query").write_text(f"""#!/bin/sh
for p in {known}; do [ "${{p%%=*}}" = "$4" ] && echo "${{p#*=}}" && exit 0; done
exit 1
""")
        for tool in tools.iterdir():
            tool.chmod(0o755)
        env = {**os.environ, "PATH": f"{tools}:{os.environ['PATH']}"}
        return subprocess.run(["sh", str(ROOT / "bootstrap")], env=env, capture_output=True, text=True, timeout=60)
    return make


EVERYTHING = {p: "1.0" for p in ("libosmesa6", "espeak-ng", "libportaudio2", "bubblewrap", "libopenni2-0",
                                   "chromium", "docker.io", "debootstrap")}


def test_compose_1_29_is_named_as_missing_with_how_to_get_compose_v2(machine) -> None:
    done = machine({**EVERYTHING, "docker-compose": "1.29.2-3"})
    assert done.returncode == 1
    assert "missing: docker-compose" in done.stderr
    assert "Compose v2" in done.stderr and "as root once" in done.stderr
    assert "installing the stack" not in done.stdout       # it stopped first


def test_with_compose_v2_only_what_is_missing_is_named(machine) -> None:
    done = machine({**{k: v for k, v in EVERYTHING.items() if k != "chromium"}, "docker-compose": "2.26.1-4"})
    assert done.returncode == 1
    assert "missing: chromium" in done.stderr
    assert "docker-compose" not in done.stderr
