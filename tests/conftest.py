"""Shared fixtures: every multi-process test gets its own real Zenoh router on loopback;
service unit tests get an in-memory bus. `pytest --cpu-burners 2` runs the suite with both
cores of a 2-core machine kept busy, as a loaded CI machine would be.

With `-n 2` (pytest-xdist) each test file runs whole on one worker (`--dist loadfile`, in
pyproject.toml), so a module's fixtures (a stack, a browser) start once. `tests/run` (CI) runs
the tests in three passes that keep the robots moving in real time (marked `slow`, no browser)
and the unit tests timed against a watchdog (marked `realtime`) apart from the browser tests
(marked `browser` here): beside a browser test a navigating robot lost its odometry for half a
second, which no robot would. The tests marked `alone` (whose input a busy machine would spoil)
run last, one at a time."""

import collections
import os
import signal
import subprocess
import sys

import pytest

os.environ.setdefault("MUJOCO_GL", "osmesa")

from asibot import testing  # noqa: E402


@pytest.fixture
def permissive_umask():
    """The umask most desktops have: without care, folders 0755 and files 0644."""
    old = os.umask(0o022)
    yield
    os.umask(old)


@pytest.fixture
def memory_bus(request):
    """Every Bus() this test opens joins one in-memory bus, with no router; the endpoint."""
    with testing.memory_bus(request.node.nodeid) as endpoint:
        yield endpoint


@pytest.fixture
def router():
    """A real Zenoh router on a free loopback port; ASIBOT_ROUTER points at it."""
    with testing.router() as endpoint:
        yield endpoint


@pytest.fixture(scope="session", autouse=True)
def user_data(tmp_path_factory):
    """The user's data folder is a temporary one for the whole session: no test reads or writes
    the real ~/.local/share/asibot (a developer's own settings there must not change a test)."""
    folder = tmp_path_factory.mktemp("user-data")
    old = os.environ.get("ASIBOT_DATA")
    os.environ["ASIBOT_DATA"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("ASIBOT_DATA", None)
    else:
        os.environ["ASIBOT_DATA"] = old


def pytest_collection_modifyitems(config, items):
    """`browser`: every test with a real browser (the `browser` fixture, however deep). The
    image's test last: its engine's clean-up (containers stopping, layers unmounted) must not
    run under the page's microphone, which it starved once (a word learned cut, in CI)."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.browser)
    items.sort(key=lambda item: item.get_closest_marker("docker") is not None)


_file_seconds: collections.Counter[str] = collections.Counter()


def pytest_runtest_logreport(report):
    """Every phase's time, by test file (under xdist, the workers' reports come here too)."""
    _file_seconds[report.nodeid.split("::", 1)[0]] += report.duration


def pytest_terminal_summary(terminalreporter):
    """Where the run's time went, by file: the module fixtures (a stack, a browser) are in their
    first test's setup, which --durations shows apart from the tests."""
    if not _file_seconds:
        return
    total = sum(_file_seconds.values())
    terminalreporter.write_sep("=", f"slowest files: {total:.0f} s of tests in all")
    for path, seconds in _file_seconds.most_common(20):
        terminalreporter.write_line(f"{seconds:8.1f}s {100 * seconds / total:5.1f} %  {path}")


def pytest_addoption(parser):
    parser.addoption("--cpu-burners", type=int, default=int(os.environ.get("ASIBOT_CPU_BURNERS", "0")),
                     help="keep N busy processes running during the tests (stress: a loaded machine)")


@pytest.fixture(scope="session", autouse=True)
def cpu_burners(request):
    """N processes spinning for the whole session, when asked for (--cpu-burners N)."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
             for _ in range(request.config.getoption("--cpu-burners"))]
    yield procs
    for p in procs:
        p.kill()
        p.wait()


@pytest.fixture
def burners_paused(cpu_burners):
    """The burners stopped for one test whose input the load itself would spoil, not our code.

    Chromium's fake microphone plays its file from an ordinary thread: with both cores busy it
    skips audio, and a word learned from a cut saying is learned wrong for good (seen in loaded
    runs: "L AO R OW G" for zorblat, then "only 50% of the speech" at every later saying). A
    real microphone feeds the browser's real-time audio thread (our page captures in an
    AudioWorklet). Learning under load is covered by tests/voice, which feed the audio directly.
    Such a test is marked `alone` too, so that tests/run gives it the machine.
    """
    for p in cpu_burners:
        p.send_signal(signal.SIGSTOP)
    yield
    for p in cpu_burners:
        p.send_signal(signal.SIGCONT)
