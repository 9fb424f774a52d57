"""The `asibot` command as a process: Ctrl-C exits 130 with no traceback from any subcommand
(stopping what it started, or the robot it moves), and `asibot status --json` gives the restart
count of each service `asibot up` supervises. These start routers and services: run them
under the machine's heavy-work lock."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.testing import free_port, wait_until

ROBOT = "cli-base"


class Command:
    """`asibot ARGV` in the background, its output collected line by line as it comes."""

    def __init__(self, *argv: str, cwd: Path | None = None, env: dict[str, str] | None = None) -> None:
        # PYTHONFAULTHANDLER: a SIGABRT makes it print every thread's stack (see ctrl_c).
        env = dict(os.environ if env is None else env, PYTHONFAULTHANDLER="1")
        # As from a terminal, where Ctrl-C is at its default. A process inherits an ignored
        # SIGINT (the tests run in the background of a script: `cmd &` ignores it), and Python
        # then keeps ignoring it, so a command would never hear this test's Ctrl-C.
        inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            self.proc = subprocess.Popen([sys.executable, "-m", "asibot.cli.main", *argv], cwd=cwd, env=env,
                                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        finally:
            signal.signal(signal.SIGINT, inherited)
        self.out: list[str] = []
        self.err: list[str] = []
        for stream, lines in ((self.proc.stdout, self.out), (self.proc.stderr, self.err)):
            threading.Thread(target=lambda s=stream, ls=lines: ls.extend(s), daemon=True).start()

    def says(self, text: str, timeout: float = 30.0) -> None:
        wait_until(lambda: text in self.text(), timeout, interval=0.1,
                   message=lambda: f"never said {text!r}: {self.text()}")

    def text(self) -> str:
        return "".join(self.out) + "".join(self.err)

    def ctrl_c(self, timeout: float = 20.0) -> int:
        self.proc.send_signal(signal.SIGINT)
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            # Where was each thread? Its signal masks and its stacks, then the failure.
            with open(f"/proc/{self.proc.pid}/status") as f:
                masks = "".join(line for line in f if line.startswith(("State", "Sig", "Shd")))
            self.proc.send_signal(signal.SIGABRT)
            self.proc.wait(10)
            time.sleep(0.2)
            pytest.fail(f"still running {timeout:g} s after Ctrl-C\n{masks}{self.text()}")
        time.sleep(0.1)   # the readers take the last lines
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def stack_env(port: int) -> dict[str, str]:
    env = dict(os.environ, ASIBOT_ROUTER=f"tcp/127.0.0.1:{port}")
    env.pop("ASIBOT_ACCESS", None)
    return env


def write_compose(folder: Path, services: str) -> Path:
    path = folder / "compose.yaml"
    path.write_text("services:\n  router: {command: [asibot, router], restart: always}\n"
                    + textwrap.indent(textwrap.dedent(services), "  "))
    return path


def test_ctrl_c_while_waiting_for_the_router_exits_130():
    """A command without a signal handler of its own (here: status, waiting for a router)."""
    cmd = Command("status", "--wait", "60", env=stack_env(free_port()))
    try:
        cmd.says("waiting for the router")
        assert cmd.ctrl_c() == 130
    finally:
        cmd.kill()
    assert "Traceback" not in cmd.text(), cmd.text()


def test_ctrl_c_stops_the_router_and_exits_130():
    port = free_port()
    cmd = Command("router", "--listen", f"tcp/127.0.0.1:{port}", env=stack_env(port))
    try:
        cmd.says("router listening")
        assert cmd.ctrl_c() == 130
    finally:
        cmd.kill()
    assert "Traceback" not in cmd.text(), cmd.text()


@pytest.mark.slow
def test_ctrl_c_stops_up_and_its_services_and_exits_130(tmp_path):
    path = write_compose(tmp_path, """
        steady:
          command: ["python", "-c", "import os, time; print('pid', os.getpid(), flush=True); time.sleep(60)"]
          restart: always
          depends_on: [router]
    """)
    cmd = Command("up", "--file", str(path), cwd=tmp_path, env=stack_env(free_port()))
    try:
        cmd.says("steady | pid ")
        pid = int(cmd.text().split("steady | pid ")[1].split()[0])
        assert cmd.ctrl_c() == 130
    finally:
        cmd.kill()
    text = cmd.text()
    assert "asibot | stopped" in text.replace("  ", " ").replace("  ", " ") and "Traceback" not in text, text
    assert f"recordings in {tmp_path / 'recordings'}" in text   # the one folder, `asibot recordings`'s too
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_ctrl_c_cancels_a_goal_and_exits_130(router):
    """`asibot nav goto` waits for the goal: Ctrl-C cancels it (the robot stops), then exits 130."""
    asked: list[str] = []
    with Bus("nav") as nav:
        def verb(name: str, answer: dict) -> None:
            nav.serve(keys.nav_rpc(ROBOT, name), lambda request: asked.append(name) or answer)
        verb("status", {"state": "idle", "text": "idle"})
        verb("goto", {"goal_id": 3, "place": "", "goal": [1.0, 2.0, 0.0], "text": "on my way"})
        verb("result", {"goal_id": 3, "state": "active", "text": "driving, 2.0 m left"})
        verb("cancel", {"goal_id": 3, "state": "canceled", "text": "canceled"})
        cmd = Command("nav", "--robot", ROBOT, "goto", "1,2,0")
        try:
            wait_until(lambda: "result" in asked, 30, interval=0.1, message=lambda: f"never waited: {cmd.text()}")
            assert cmd.ctrl_c() == 130
        finally:
            cmd.kill()
    assert "cancel" in asked and "stopped on Ctrl-C" in cmd.text()
    assert "Traceback" not in cmd.text(), cmd.text()


@pytest.mark.slow
def test_status_json_counts_the_restarts_of_each_service_up_runs(tmp_path):
    path = write_compose(tmp_path, """
        flaky:
          command: ["python", "-c", "raise SystemExit(3)"]
          restart: on-failure
          depends_on: [router]
    """)
    env = stack_env(free_port())
    up = Command("up", "--file", str(path), cwd=tmp_path, env=env)
    try:
        def status() -> dict | None:
            r = subprocess.run([sys.executable, "-m", "asibot.cli.main", "status", "--json"], env=env,
                               capture_output=True, text=True, timeout=30)
            if r.returncode != 0:
                return None
            document = json.loads(r.stdout)
            flaky = next(s for s in document["launched"] if s["name"] == "flaky") if document["launched"] else None
            return document if flaky and flaky["restarts"] >= 2 else None
        document = wait_until(status, 40, interval=0.5, message=lambda: f"no restarts counted: {up.text()}")
        assert up.ctrl_c() == 130
    finally:
        up.kill()
    launched = {s["name"]: s for s in document["launched"]}
    assert launched["router"]["restarts"] == 0 and launched["router"]["running"]
    assert {(s["service"], s["instance"]) for s in document["services"]} >= {("router", "main"), ("launcher", "main")}
    assert "restarting flaky (restart 2)" in up.text()
