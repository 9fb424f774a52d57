"""`asibot up` as a user runs it: a subprocess reading a copy of compose.yaml, its own router
port, recordings in a temporary folder, stopped with Ctrl-C (SIGINT) at the end."""

from __future__ import annotations

from pathlib import Path

import pytest

from asibot.testing import Stack

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "libs" / "common" / "asibot" / "examples"


@pytest.fixture
def up(tmp_path, monkeypatch):
    stacks: list[Stack] = []

    def start(profile: str = "sim", *only: str) -> Stack:
        stack = Stack(tmp_path, profile, list(only), ROOT / "compose.yaml")
        monkeypatch.setenv("ASIBOT_ROUTER", stack.endpoint)  # for clients in this process
        stacks.append(stack)
        return stack

    yield start
    for s in stacks:
        s.stop()
