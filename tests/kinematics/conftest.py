"""Fixtures: an ideal driver and a kinematics server (in threads, on the in-memory bus) plus a client.

One bus, driver and server serve the whole module (a fresh set per test would spend most of
the time on start-up); each test starts from a stopped controller and the same joints. Tests
that destroy the setup build their own (`fresh`).
"""

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from asibot import testing
from asibot.bus import Bus
from asibot.client import CartesianClient
from asibot.kinematics.server import KinematicsServer
from asibot.testing import IdealDriver, wait_until

from .robot_under_test import asibot_model, asibot_spec

ROBOT = "asibot-test"
START = np.radians([0.0, 5.0, 5.0, 5.0, 0.0])


class Sent:
    """The server's arm-command publisher, counting what it sent."""

    def __init__(self, pub) -> None:
        self.pub, self.count, self._lock = pub, 0, threading.Lock()

    def put(self, msg) -> None:
        self.pub.put(msg)
        with self._lock:
            self.count += 1


def build(robot: str, model=None) -> SimpleNamespace:
    """Driver, server (with `model`, default the real ASIBOT one) and client for `robot`.
    `server.cmd_pub.count` is how many arm commands the server sent."""
    driver = IdealDriver(robot, asibot_spec())
    driver.set_joints(START)
    bus = Bus("kinematics")
    server = KinematicsServer(bus, robot, model or asibot_model(), asibot_spec(), rate=100.0)
    server.cmd_pub = Sent(server.cmd_pub)
    wait_until(lambda: server.ctl.driver_alive and server.ctl.q is not None, timeout=5.0)
    wait_until(lambda: driver.holder.current == server.controller, timeout=5.0)   # it obeys this server
    return SimpleNamespace(robot=robot, driver=driver, bus=bus, server=server, client=CartesianClient(robot))


def quiet(s: SimpleNamespace) -> None:
    """Stop the controller, drop a hold it has not sent yet, and wait until the driver has
    every command it did send: one still on its way (the last reference of a motion that
    just ended) would move the arm after the next test puts it at START."""
    s.server.ctl.stop()
    wait_until(lambda: s.server.ctl.tick(0.0) is None, timeout=1.0)
    wait_until(lambda: len(s.driver.commands) >= s.server.cmd_pub.count, timeout=2.0)


def teardown(s: SimpleNamespace) -> None:
    s.client.close()
    s.server.close()
    s.bus.close()
    s.driver.close()


@pytest.fixture(scope="module")
def shared(request):
    with testing.memory_bus(request.node.nodeid):
        s = build(ROBOT)
        yield s
        teardown(s)


@pytest.fixture
def client(shared):
    quiet(shared)
    shared.driver.set_joints(START)
    wait_until(lambda: np.allclose(shared.server.ctl.q, START, atol=1e-9), timeout=2.0)
    yield shared.client
    shared.server.ctl.stop()


@pytest.fixture
def driver(shared):
    return shared.driver


@pytest.fixture
def server(shared):
    return shared.server


@pytest.fixture
def fresh(shared):
    """A second robot of its own on the shared bus, for tests that kill its driver."""
    s = build(ROBOT + "-2")
    yield s
    teardown(s)
