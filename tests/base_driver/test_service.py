"""The driver contract on the bus: cmd_vel in; odom, sonar, bumpers, battery, events out."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from asibot import keys
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.messages import Battery, Bumpers, EStop, Event, Odometry, Sonar, Twist
from asibot.testing import free_port, wait_until, release

from asibot.base_driver.service import BaseDriverService

ROBOT = "pioneer"


class Inbox:
    def __init__(self, bus: Bus, robot: str = ROBOT):
        self.lock = threading.Lock()
        self.got: dict[str, list] = {}
        for name, key, typ in (("odom", keys.base_odom(robot), Odometry), ("sonar", keys.base_sonar(robot), Sonar),
                               ("bumpers", keys.base_bumpers(robot), Bumpers),
                               ("battery", keys.base_battery(robot), Battery), ("events", keys.events(robot), Event)):
            bus.subscribe(key, typ, lambda m, n=name: self._add(n, m))

    def _add(self, name, msg):
        with self.lock:
            self.got.setdefault(name, []).append(msg)

    def __getitem__(self, name):
        with self.lock:
            return list(self.got.get(name, []))

    def codes(self):
        return [e.code for e in self["events"]]


@pytest.fixture
def world(memory_bus, emulator):
    svc_bus = Bus("base_driver")
    svc = BaseDriverService(svc_bus, ROBOT, emulator.url)
    user = Bus("test")
    controller = ownership.announce(user, ROBOT, "base", "test")   # the test drives the base
    inbox = Inbox(user)
    wait_until(lambda: svc.driver.connected and inbox["odom"], 5, message="no odometry on the bus")
    wait_until(lambda: svc.holder.current == controller.id, 5)
    yield svc, user, inbox, emulator, controller
    user.close()
    svc.close()
    svc_bus.close()


def test_cmd_vel_on_the_bus_moves_the_emulated_pioneer(world):
    svc, user, inbox, emu, controller = world
    pub = user.publisher(keys.base_cmd_vel(ROBOT), Twist)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        controller.put(pub, Twist(vx=0.3, wz=0.0))
        time.sleep(0.05)
    controller.put(pub, Twist(vx=0.0, wz=0.0))
    wait_until(lambda: inbox["odom"][-1].vx == 0.0 and inbox["odom"][-1].x > 0.2, 3)
    assert inbox["odom"][-1].x == pytest.approx(0.3, abs=0.06)
    sonar = inbox["sonar"][-1]
    assert len(sonar.ranges) == len(sonar.angles) == 16
    assert sonar.angles[0] == pytest.approx(math.pi / 2)
    assert 0.1 < min(sonar.ranges) and max(sonar.ranges) <= 4.335
    assert len(inbox["bumpers"][-1].front) == 7
    assert inbox["battery"][-1].volts == pytest.approx(12.8)


def test_bad_cmd_vel_is_rejected_and_moves_nothing(world):
    svc, user, inbox, emu, controller = world
    from asibot.messages import pack
    user.put_raw(keys.base_cmd_vel(ROBOT), pack({"vx": "fast", "wz": 0.0}))
    user.put_raw(keys.base_cmd_vel(ROBOT), pack({"vx": float("nan"), "wz": 0.0}))
    time.sleep(0.3)
    assert emu.robot.target_vel == 0 and svc.driver.counters["cmd_vel"] == 0


def test_latched_estop_stops_and_status_reports_it(world):
    svc, user, inbox, emu, controller = world
    user.latch(keys.estop(ROBOT), EStop(engaged=True, reason="test button"))
    wait_until(lambda: "estop" in inbox.codes(), 3)
    controller.put(user.publisher(keys.base_cmd_vel(ROBOT), Twist), Twist(vx=0.3, wz=0.0))
    time.sleep(0.3)
    assert emu.robot.target_vel == 0
    status = user.call(keys.driver_rpc(ROBOT, "status"), {}, timeout=2.0)
    assert status["ok"] and status["estop"] and status["connected"] and status["subclass"] == "p3at-sh"
    with pytest.raises(RpcError) as err:
        user.call(keys.driver_rpc(ROBOT, "reset_fault"), {}, timeout=2.0)
    assert err.value.code == "estop"
    release(user, ROBOT)
    wait_until(lambda: "estop_released" in inbox.codes(), 3)
    assert user.call(keys.driver_rpc(ROBOT, "reset_fault"), {}, timeout=2.0)["ok"]


def test_late_driver_learns_a_latched_estop(memory_bus, emulator):
    user = Bus("test")
    user.latch(keys.estop(ROBOT), EStop(engaged=True, reason="latched before start"))
    svc_bus = Bus("base_driver")
    svc = BaseDriverService(svc_bus, ROBOT, emulator.url)
    try:
        wait_until(lambda: svc.driver.connected, 5)
        wait_until(lambda: any(c == 55 for _, c, _ in list(emulator.robot.received)), 2)
        assert svc.driver.cmd_vel(0.3, 0) is False
    finally:
        svc.close()
        svc_bus.close()
        user.close()


def test_driver_alive_and_events_for_disconnect(world):
    svc, user, inbox, emu, controller = world
    assert user.alive(keys.driver_alive(ROBOT))
    emu.pull_cable(0.5)
    wait_until(lambda: "disconnected" in inbox.codes(), 3)
    wait_until(lambda: inbox.codes()[-2:] == ["connected", "ready"], 5)


@pytest.mark.slow
def test_standalone_processes_emulator_and_driver(router, tmp_path):
    """The two command lines of the compose `emulated` profile, driven over the bus."""
    port, control = free_port(), free_port()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    emu = subprocess.Popen([sys.executable, "-m", "asibot.base_driver.emulator", "--listen", f"127.0.0.1:{port}",
                            "--control", f"127.0.0.1:{control}"], env=env)
    drv = subprocess.Popen([sys.executable, "-m", "asibot.base_driver", "--robot", ROBOT,
                            "--port", f"socket://127.0.0.1:{port}"], env=env)
    user = Bus("test")
    try:
        controller = ownership.announce(user, ROBOT, "base", "test")
        inbox = Inbox(user)
        wait_until(lambda: inbox["odom"], 15, message="the driver process published no odometry")
        wait_until(lambda: user.call(keys.driver_rpc(ROBOT, "status"))["holders"]["base"] == controller.id, 5)
        pub = user.publisher(keys.base_cmd_vel(ROBOT), Twist)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            controller.put(pub, Twist(vx=0.2, wz=0.0))
            time.sleep(0.05)
        wait_until(lambda: inbox["odom"][-1].x > 0.1, 3)

        def ctl(line: str) -> dict:
            with socket.create_connection(("127.0.0.1", control), timeout=2) as s, s.makefile("rw") as f:
                f.write(line + "\n")
                f.flush()
                return json.loads(f.readline())

        assert ctl("status")["open"] is True
        assert ctl("fly 3")["ok"] is False
        assert ctl("unplug 0.5")["ok"] is True
        wait_until(lambda: "disconnected" in inbox.codes(), 3)
        wait_until(lambda: inbox.codes()[-2:] == ["connected", "ready"], 6)
    finally:
        user.close()
        for p in (drv, emu):
            p.send_signal(signal.SIGTERM)
        for p in (drv, emu):
            assert p.wait(timeout=5) == 0


def test_driver_without_a_port_says_what_to_pass(router):
    r = subprocess.run([sys.executable, "-m", "asibot.base_driver", "--robot", ROBOT],
                       env={k: v for k, v in os.environ.items() if k != "ASIBOT_PIONEER_PORT"},
                       capture_output=True, text=True, timeout=20)
    assert r.returncode == 1 and "--port" in r.stderr


def test_emulator_refuses_a_bad_map(tmp_path):
    r = subprocess.run([sys.executable, "-m", "asibot.base_driver.emulator", "--map", str(tmp_path / "none.yaml"),
                        "--listen", f"127.0.0.1:{free_port()}"], capture_output=True, text=True, timeout=20)
    assert r.returncode == 2 and "Cannot read the map file" in r.stderr
