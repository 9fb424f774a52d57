"""Shared fixtures: every multi-process test gets its own real Zenoh router on loopback."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "osmesa")

from asibot import testing  # noqa: E402


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
