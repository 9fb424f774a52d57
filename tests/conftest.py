"""Shared fixtures: every multi-process test gets its own real Zenoh router on loopback."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "osmesa")

from asibot import testing  # noqa: E402


@pytest.fixture
def router():
    """A real Zenoh router on a free loopback port; ASIBOT_ROUTER points at it."""
    with testing.router() as endpoint:
        yield endpoint
