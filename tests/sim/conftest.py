"""Fixtures: fresh simulations of both worlds (fast: built in a fraction of a second)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))  # sim_reach

from asibot import robots  # noqa: E402
from asibot.sim.simulation import Simulation  # noqa: E402


@pytest.fixture
def robot_catalog():
    return robots


@pytest.fixture
def kitchen() -> Simulation:
    return Simulation("asibot-sim")


@pytest.fixture
def apartment() -> Simulation:
    return Simulation("pioneer-sim", odom_noise=(0.0, 0.0))
