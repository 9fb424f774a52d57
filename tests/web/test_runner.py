"""The program runner on real subprocesses: output, robot argument, limits, Stop, crash sentences."""

from __future__ import annotations

import sys
import textwrap
import threading
import uuid
from pathlib import Path

import pytest

from asibot.testing import alive, processes_with, wait_until
from asibot.web.runner import CUT_MARK, Limits, ProgramRunner, RunResult


class Recorder:
    """Everything the runner told the server, as the server's callbacks would see it."""

    def __init__(self, **limits: int) -> None:
        self.lines: list[tuple[str, str]] = []
        self.results: list[RunResult] = []
        self.stopped: list[str] = []
        self.lock = threading.Lock()
        self.runner = ProgramRunner(limits=Limits(**limits), env={"EXTRA": "from the server"},
                                    on_output=self._output, on_exit=self.results.append,
                                    stop_robot=self.stopped.append)

    def _output(self, stream: str, line: str) -> None:
        with self.lock:
            self.lines.append((stream, line))

    def run(self, path: Path, robot: str = "asibot-sim", timeout: float = 10.0) -> RunResult:
        """Start `path` and wait for its end."""
        count = len(self.results)
        self.runner.start(path, robot)
        wait_until(lambda: len(self.results) > count, timeout=timeout, message=f"{path.name} did not end")
        return self.results[-1]

    def out(self) -> list[str]:
        with self.lock:
            return [line for stream, line in self.lines if stream == "out"]


@pytest.fixture
def recorder():
    made: list[Recorder] = []

    def make(**limits: int) -> Recorder:
        made.append(Recorder(**limits))
        return made[-1]
    yield make
    for r in made:
        r.runner.close()


def program(folder: Path, text: str, name: str = "prog.py") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(textwrap.dedent(text).lstrip())
    return path


def test_hello_world_output_and_finished(recorder, tmp_path):
    r = recorder()
    path = program(tmp_path, """
        import sys
        print("hello, robot!")
        print("to stderr", file=sys.stderr)
        print("done!")
    """)
    result = r.run(path)
    assert (result.reason, result.ok, result.exit_code) == ("finished", True, 0)
    assert (result.program, result.robot) == ("prog", "asibot-sim")
    assert result.started <= result.ended
    assert r.out() == ["hello, robot!", "done!"]
    assert ("err", "to stderr") in r.runner.output()
    assert r.stopped == []  # a clean end leaves the arm alone
    status = r.runner.status()
    assert status["running"] is False and status["last"]["reason"] == "finished"


def test_robot_is_argv1_and_environment(recorder, tmp_path):
    r = recorder()
    path = program(tmp_path, """
        import os, sys
        print(sys.argv[1])
        print(os.environ["ASIBOT_ROBOT"])
        print(os.environ["EXTRA"], os.environ["PYTHONUNBUFFERED"])
        print(os.getcwd())
    """)
    assert r.run(path, robot="pioneer-sim").ok
    assert r.out() == ["pioneer-sim", "pioneer-sim", "from the server 1", str(tmp_path.resolve())]


def test_endless_loop_is_stopped_by_the_cpu_limit(recorder, tmp_path):
    r = recorder(cpu_seconds=1)
    result = r.run(program(tmp_path, "while True:\n    pass\n"), timeout=15)
    assert result.reason == "stopped: it used all of its 1 s of CPU time"
    assert not result.ok
    assert r.stopped == ["asibot-sim"]


@pytest.mark.parametrize("text", ["x = bytearray(10**10)\n",
                                  "x = []\nwhile True:\n    x.append(bytearray(10**6))\n"],
                         ids=["one-big", "growing"])
def test_memory_bomb_is_stopped_by_the_memory_limit(recorder, tmp_path, text):
    r = recorder(memory_bytes=128 << 20)
    result = r.run(program(tmp_path, text))
    assert result.reason == "stopped: it needed more memory than its limit of 128 MiB"
    assert r.stopped == ["asibot-sim"]


def test_default_limits_let_the_client_library_and_zenoh_run(recorder, tmp_path):
    # The reason for RLIMIT_DATA: Zenoh hangs when it cannot start its threads.
    r = recorder()
    path = program(tmp_path, """
        import numpy, zenoh, asibot.client
        config = zenoh.Config.from_json5('{"scouting": {"multicast": {"enabled": false}}, "listen": {"endpoints": []}}')
        with zenoh.open(config) as session:
            got = []
            sub = session.declare_subscriber("runner/test", lambda sample: got.append(1))
            for _ in range(10):
                session.put("runner/test", b"x")
            a = numpy.ones(50_000_000)  # 400 MB of the program's own
            print("ok", a.sum())
    """)
    result = r.run(path, timeout=15)
    assert result.ok, (result.reason, r.runner.output())
    assert r.out() == ["ok 50000000.0"]


def test_stop_kills_the_whole_process_group(recorder, tmp_path):
    r = recorder()
    marker = f"runner-stop-{uuid.uuid4().hex}"
    # Both the program and its child ignore SIGTERM: Stop must still end them. Pids inside the
    # sandbox are its own namespace's, so the test finds them by a marker in their command line.
    path = program(tmp_path, f"""
        import signal, subprocess, sys, time
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        child = subprocess.Popen([sys.executable, "-c",
            "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('child up', flush=True); time.sleep(60)",
            "{marker}"])
        time.sleep(0.2)
        print("child", child.pid)
        time.sleep(60)
    """)
    r.runner.start(path, "asibot-sim")
    wait_until(lambda: "child up" in r.out() and any(line.startswith("child ") and line != "child up"
                                                     for line in r.out()), timeout=10)
    pid = r.runner.status()["pid"]
    assert r.runner.running() and alive(pid) and processes_with(marker)
    r.runner.stop()
    assert not r.runner.running()
    assert r.results[-1].reason == "stopped by the user" and not r.results[-1].ok
    assert r.stopped == ["asibot-sim"]
    assert not alive(pid)
    assert processes_with(marker) == [], "the program's child survived Stop"
    r.runner.stop()  # idempotent
    assert len(r.results) == 1


@pytest.mark.parametrize("files, sentence", [
    ({"prog.py": "print('a')\nprint('b')\nprint(x)\n"},
     "failed with an error on line 3: NameError: name 'x' is not defined"),
    # The error is raised in a module of the user's folder: the line is the user's call.
    ({"helper.py": "def boom():\n    raise ValueError('bad point')\n",
      "prog.py": "import helper\n\n\nhelper.boom()\n"},
     "failed with an error on line 4: ValueError: bad point"),
    ({"prog.py": "x = 1\nif x\n    pass\n"},
     "failed with an error on line 2: SyntaxError: expected ':'"),
], ids=["name-error", "in-helper", "syntax"])
def test_error_sentence_names_the_users_line(recorder, tmp_path, files, sentence):
    r = recorder()
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    result = r.run(tmp_path / "prog.py")
    assert (result.reason, result.ok, result.exit_code) == (sentence, False, 1)
    assert r.stopped == ["asibot-sim"]


@pytest.mark.parametrize("text, sentence", [
    ("import sys\nsys.exit(3)\n", "exited with code 3"),
    # A program that stops itself with its own words is said to have stopped for them.
    ("import sys\nprint('closing')\nsys.exit('nothing in the gripper after closing at red-can')\n",
     "nothing in the gripper after closing at red-can"),
    ("import os, signal\nos.kill(os.getpid(), signal.SIGUSR1)\n", "killed by signal 10 (SIGUSR1)"),
])
def test_other_ends(recorder, tmp_path, text, sentence):
    r = recorder()
    result = r.run(program(tmp_path, text))
    assert (result.reason, result.ok) == (sentence, False)
    assert r.stopped == ["asibot-sim"]


def test_second_start_is_refused(recorder, tmp_path):
    r = recorder()
    path = program(tmp_path, "import time\nprint('up')\ntime.sleep(60)\n", name="sleeper.py")
    r.runner.start(path, "asibot-sim")
    wait_until(lambda: r.out() == ["up"], timeout=10)
    with pytest.raises(RuntimeError, match=r"^'sleeper' is still running; stop it first$"):
        r.runner.start(program(tmp_path, "print(1)\n", name="other.py"), "asibot-sim")
    r.runner.stop()
    assert r.run(tmp_path / "other.py").ok  # and once stopped, the next one runs


def test_output_ring_is_bounded_and_long_lines_are_cut(recorder, tmp_path):
    r = recorder(max_output_lines=50, max_line_chars=100)
    path = program(tmp_path, """
        print("x" * 1_000_000)
        for i in range(500):
            print("line", i)
    """)
    assert r.run(path).ok
    assert r.out()[0] == "x" * 100 + CUT_MARK  # every line reached the server, capped
    assert len(r.out()) == 501
    kept = r.runner.output()
    assert len(kept) == 50
    assert kept[-1] == ("out", "line 499") and kept[0] == ("out", "line 450")


def test_no_shell_paths_and_robot_names_are_taken_literally(recorder, tmp_path):
    r = recorder()
    folder = tmp_path / "my programs; touch PWNED"
    path = program(folder, "import sys\nprint('ok', sys.argv[1])\n", name="give me; the can.py")
    result = r.run(path, robot="asibot-sim; touch PWNED2")
    assert result.ok and result.program == "give me; the can"
    assert r.out() == ["ok asibot-sim; touch PWNED2"]
    assert not any(p.name.startswith("PWNED") for p in tmp_path.rglob("*"))
    assert not (Path.cwd() / "PWNED").exists()


def test_callback_errors_do_not_break_the_runner(tmp_path):
    def broken(*args: object) -> None:
        raise RuntimeError("server bug")
    runner = ProgramRunner(on_output=broken, on_exit=broken, stop_robot=broken)
    try:
        runner.start(program(tmp_path, "print('a')\nraise SystemExit(2)\n"), "asibot-sim")
        wait_until(lambda: runner.status()["last"], timeout=10)
        assert runner.status()["last"]["reason"] == "exited with code 2"
        assert runner.output() == [("out", "a")]
        runner.start(tmp_path / "prog.py", "asibot-sim")  # still usable
        wait_until(lambda: not runner.running(), timeout=10)
    finally:
        runner.close()


def test_missing_program_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="no program file 'nope.py'"):
        ProgramRunner(python=sys.executable).start(tmp_path / "nope.py", "asibot-sim")
