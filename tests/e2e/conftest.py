"""`asibot up` as a user runs it: a subprocess reading a copy of compose.yaml, its own router
port, recordings in a temporary folder, stopped with Ctrl-C (SIGINT) at the end."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.testing import free_port, wait_until

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "libs" / "common" / "examples"


class Stack:
    def __init__(self, folder: Path, profile: str, only: list[str]) -> None:
        self.folder = folder
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.env = dict(os.environ, ASIBOT_ROUTER=self.endpoint)
        shutil.copy(ROOT / "compose.yaml", folder / "compose.yaml")
        self.log_path = folder / "up.log"
        self._log = open(self.log_path, "w")
        cmd = [sys.executable, "-m", "asibot.cli", "up", "--profile", profile, "--file", str(folder / "compose.yaml")]
        if only:
            cmd += ["--only", *only]
        self.proc = subprocess.Popen(cmd, cwd=folder, env=self.env, stdout=self._log, stderr=subprocess.STDOUT)
        self.bus = Bus("e2e-test", self.endpoint, wait=20.0)

    def log(self) -> str:
        return self.log_path.read_text()

    def wait_alive(self, *services: str, timeout: float = 60.0) -> list[str]:
        """Wait until each `<service>/<instance>` announces itself; the live service keys."""
        want = {keys.service(*s.split("/", 1)) for s in services}
        try:
            wait_until(lambda: want <= set(self.bus.alive(keys.ALL_SERVICES)), timeout, interval=0.5)
        except AssertionError:
            missing = sorted(want - set(self.bus.alive(keys.ALL_SERVICES)))
            raise AssertionError(f"not alive after {timeout} s: {missing}\n{self.log()}") from None
        return self.bus.alive(keys.ALL_SERVICES)

    def run(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
        """Run a Python program against the stack; on a hang, fail with what it printed."""
        try:
            return subprocess.run([sys.executable, *args], env=self.env, capture_output=True, text=True,
                                  timeout=timeout, cwd=self.folder)
        except subprocess.TimeoutExpired as exc:
            raise AssertionError(f"{args} did not finish within {timeout} s; it printed:\n"
                                 f"{exc.stdout}\n{exc.stderr}\n--- asibot up:\n{self.log()}") from None

    def stop(self) -> int:
        self.bus.close()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)  # Ctrl-C
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode


@pytest.fixture
def up(tmp_path, monkeypatch):
    stacks: list[Stack] = []

    def start(profile: str = "sim", *only: str) -> Stack:
        stack = Stack(tmp_path, profile, list(only))
        monkeypatch.setenv("ASIBOT_ROUTER", stack.endpoint)  # for clients in this process
        stacks.append(stack)
        return stack

    yield start
    for s in stacks:
        s.stop()
