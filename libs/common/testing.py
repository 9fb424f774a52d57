"""Test helpers: a real router on a free loopback port, and polling with a deadline."""

from __future__ import annotations

import contextlib
import os
import socket
import time
from typing import Callable, Iterator

from asibot.bus import ROUTER_ENV, open_router


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def router(port: int | None = None) -> Iterator[str]:
    """Run a Zenoh router in this process and point ASIBOT_ROUTER at it (restored after)."""
    endpoint = f"tcp/127.0.0.1:{port or free_port()}"
    session = open_router(endpoint)
    previous = os.environ.get(ROUTER_ENV)
    os.environ[ROUTER_ENV] = endpoint
    try:
        yield endpoint
    finally:
        if previous is None:
            os.environ.pop(ROUTER_ENV, None)
        else:
            os.environ[ROUTER_ENV] = previous
        session.close()


def wait_until(predicate: Callable[[], object], timeout: float = 5.0, interval: float = 0.01,
               message: str = "") -> object:
    """Poll until predicate() is truthy; return its value or raise AssertionError on timeout."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(message or f"condition not met within {timeout} s")
        time.sleep(interval)
