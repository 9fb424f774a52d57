"""Fixtures: fresh simulations of both worlds (fast: built in a fraction of a second)."""

import pytest

from asibot import robots
from asibot.sim.simulation import Simulation


@pytest.fixture
def robot_catalog():
    return robots


@pytest.fixture
def kitchen() -> Simulation:
    return Simulation("asibot-sim")


@pytest.fixture
def apartment() -> Simulation:
    return Simulation("pioneer-sim", odom_noise=(0.0, 0.0))
