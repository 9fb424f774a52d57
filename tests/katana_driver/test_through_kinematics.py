"""The Pioneer's Katana commanded as the sim's is: the kinematics service (its own solver for
the Katana) holds the arm and plans a movj, the Katana driver obeys it over the serial line,
the emulated controller's motors end at the joints asked for."""

from __future__ import annotations

import math

import pytest

from asibot import robots
from asibot.bus import Bus
from asibot.client import CartesianClient
from asibot.katana_driver.emulator import KatanaEmulator
from asibot.katana_driver.katana import KATANA_300_6M180
from asibot.katana_driver.service import KatanaDriverService
from asibot.kinematics.model import solver_for
from asibot.kinematics.server import KinematicsServer
from asibot.testing import wait_until

from .conftest import R

SPEC = robots.get(R)


@pytest.mark.slow
def test_a_movj_of_the_kinematics_service_reaches_its_joints_on_the_emulated_katana(memory_bus):
    driver_bus, kin_bus = Bus("katana_driver"), Bus("kinematics")
    start = [m.to_counts(h) for m, h in zip(KATANA_300_6M180, SPEC.home)] + [30000]
    svc = KatanaDriverService(driver_bus, R, "emulated", calibrate=False, emulator=KatanaEmulator(start))
    server = KinematicsServer(kin_bus, R, solver_for(SPEC), SPEC, rate=100.0)
    client = CartesianClient(R)
    try:
        wait_until(lambda: server.ctl.driver_alive and server.ctl.q is not None, 10)
        wait_until(lambda: svc.holder.current == server.controller, 10, message="the driver never saw kinematics")
        goal = [h + d for h, d in zip(SPEC.home, [0.3, -0.2, 0.2, 0.3, -0.4])]
        client.movj(joints=[math.degrees(g) for g in goal])
        assert client.wait(timeout=20)
        want = [m.to_counts(g) for m, g in zip(KATANA_300_6M180, goal)]
        assert svc.emulator is not None
        wait_until(lambda: all(abs(c - w) <= 2 for c, w in zip(svc.emulator.counters(), want)), 5,
                   message=lambda: f"the motors stand at {svc.emulator.counters()}, not {want}")
        assert svc.driver.status()["fault"] == ""
    finally:
        client.close()
        server.close()
        kin_bus.close()
        svc.close()
        driver_bus.close()
