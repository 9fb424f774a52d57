import subprocess
import sys
from pathlib import Path

import pytest

PEER = Path(__file__).with_name("peer.py")


@pytest.fixture
def spawn(router):
    """Start a peer process (see peer.py) and wait until it is set up; killed at teardown."""
    procs: list[subprocess.Popen] = []

    def start(role: str, key: str) -> subprocess.Popen:
        p = subprocess.Popen([sys.executable, str(PEER), role, key], stdout=subprocess.PIPE, text=True)
        procs.append(p)
        line = p.stdout.readline()
        assert line.strip() == "READY", f"peer {role} did not start: {line!r}"
        return p

    yield start
    for p in procs:
        p.kill()
        p.wait()


@pytest.fixture(params=["zenoh", "memory"])
def endpoint(request):
    """Each backend in turn: a real Zenoh router, then the in-memory bus."""
    if request.param == "zenoh":
        yield request.getfixturevalue("router")
    else:
        yield f"mem://{request.node.name}"
