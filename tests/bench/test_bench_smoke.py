"""Every bench runs: `python bench/<name>.py --quick` exits 0 and prints its table.

Nothing else runs the benches, so one that no longer fits the code it measures would go unseen
until someone needs its figures. The smoke run takes the bench's real path (its routers,
processes, browser) on tiny sizes; its figures mean nothing and are not checked, but nothing it
runs may raise. A new
bench/bench_*.py is covered without being named here.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from asibot.testing import free_port

ROOT = Path(__file__).resolve().parents[2]
BENCHES = sorted(p.name for p in (ROOT / "bench").glob("bench_*.py"))
#: s for one smoke run: the slowest (bench_teach) takes 30 s on an idle 2-core machine; a loaded CI is slower.
TIMEOUT = 400
#: A Markdown table as bench/table.py prints it: a header row, the rule under it, one row at least.
TABLE = re.compile(r"^\|.*\|\n\|(---\|)+\n\|.*\|$", re.MULTILINE)

pytestmark = [pytest.mark.slow, pytest.mark.timeout(TIMEOUT + 60)]


def browser_marked(name: str):
    """A bench that drives chromium is a browser test (tests/run runs it with those, not beside
    the robots moving in real time: tests/conftest.py)."""
    drives_chromium = "playwright" in (ROOT / "bench" / name).read_text()
    return pytest.param(name, marks=[pytest.mark.browser] if drives_chromium else [])


def run(name: str, data: Path) -> tuple[int, str, str]:
    """Run the bench in a session of its own, so that a hung one is ended with everything it
    started (a stack, a browser), as Ctrl-C would and then by force; (exit status, stdout, stderr)."""
    # A bench starts its own router or stack; one that forgot would reach this port, where no
    # router listens, and fail, instead of joining a developer's `asibot up` on 7447.
    env = dict(os.environ, MUJOCO_GL="osmesa", ASIBOT_DATA=str(data),
               ASIBOT_ROUTER=f"tcp/127.0.0.1:{free_port()}")
    # stderr apart: a helper's log line must not land inside the table.
    proc = subprocess.Popen([sys.executable, f"bench/{name}", "--quick"], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        # An ended bench whose output is still open left a process behind that holds it.
        ended = "" if proc.poll() is None else f" (it exited with {proc.returncode}; a process it started did not)"
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
        pytest.fail(f"{name} --quick did not end within {TIMEOUT} s{ended}\n{said(out, err)}")
    finally:
        try:                        # what it left behind (a helper process it did not wait for)
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return proc.returncode, out, err


def said(out: str, err: str) -> str:
    return f"--- stdout:\n{out[-4000:]}\n--- stderr:\n{err[-6000:]}"


@pytest.mark.parametrize("name", [browser_marked(name) for name in BENCHES])
def test_quick_run_prints_its_table(name, tmp_path):
    rc, out, err = run(name, tmp_path / "data")
    assert rc == 0, f"{name} --quick exited with {rc}\n{said(out, err)}"
    assert TABLE.search(out), f"{name} --quick printed no table\n{said(out, err)}"
    # A thread of what it measures died (bench_voice's Task Creator double once answered a launch
    # with too little, and the service's worker died on it): the table printed, its figures lie.
    assert "Traceback (most recent call last)" not in err, f"{name} --quick raised in a thread\n{said(out, err)}"
