"""BaseDriver against the emulator over TCP (pyserial socket://), in real time, no bus."""

from __future__ import annotations

import math
import socket
import threading
import time

import pytest

from asibot.base_driver import codec
from asibot.base_driver.codec import Cmd, Deframer
from asibot.base_driver.driver import BaseDriver
from asibot.safety.guarded_base import SPEED_TOLERANCE
from asibot.base_driver.emulator import ArcosEmulator
from asibot.base_driver.sip import parse_sip
from asibot.errors import RpcError
from asibot.safety.events import CommandRefused
from asibot.messages import COMMAND_WATCHDOG_S
from asibot.testing import wait_until


class Recorder:
    def __init__(self):
        self.states = []
        self.events = []
        self.lock = threading.Lock()

    def state(self, s):
        with self.lock:
            self.states.append(s)

    def event(self, level, code, text):
        with self.lock:
            self.events.append((level, code, text))

    def codes(self):
        with self.lock:
            return [c for _, c, _ in self.events]


@pytest.fixture
def rig(emulator):
    rec = Recorder()
    drv = BaseDriver(emulator.url, on_state=rec.state, on_event=rec.event)
    drv.start()
    wait_until(lambda: drv.connected and rec.states and rec.states[-1].motors_enabled, 5,
               message="driver did not connect to the emulator")
    yield drv, emulator, rec
    drv.close()


def stream(drv, vx, wz, seconds, period=0.05):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        drv.cmd_vel(vx, wz)
        time.sleep(period)


def commands_since(emulator, t0, cmd):
    return [(t, a) for t, c, a in list(emulator.robot.received) if t >= t0 and c == cmd]


def test_cmd_vel_for_2_s_drives_0_6_m(rig):
    drv, emu, rec = rig
    stream(drv, 0.3, 0.0, 2.0)
    drv.cmd_vel(0.0, 0.0)
    wait_until(lambda: rec.states[-1].vx == 0.0 and not rec.states[-1].moving, 3)
    s = rec.states[-1]
    assert s.x == pytest.approx(0.6, abs=0.06)
    assert abs(s.y) < 0.01 and abs(s.theta) < 0.01
    assert s.volts == pytest.approx(12.8) and len(s.sonar_ranges) == 16
    assert max(st.vx for st in rec.states) == pytest.approx(0.3, abs=0.005)


def test_turning_reports_heading_and_rate(rig):
    drv, emu, rec = rig
    stream(drv, 0.0, math.radians(45), 1.0)
    assert max(st.wz for st in rec.states) == pytest.approx(math.radians(45), abs=0.02)
    wait_until(lambda: rec.states[-1].wz == 0.0, 3)
    assert rec.states[-1].theta == pytest.approx(emu.robot.pose.theta, abs=0.01)
    assert rec.states[-1].theta > math.radians(30)


def test_speed_beyond_the_driver_limit_is_refused_not_clamped(rig):
    drv, emu, rec = rig
    t0 = time.monotonic()
    with pytest.raises(CommandRefused, match=r"vx 3 m/s is beyond the driver's max speed 0.5 m/s \(--max-vx\)"):
        drv.cmd_vel(3.0, 0.0)
    with pytest.raises(CommandRefused, match=r"wz -10 rad/s is beyond the driver's max turn rate 1.75 rad/s \(--max-wz\)"):
        drv.cmd_vel(0.0, -10.0)
    with pytest.raises(CommandRefused, match="vx is nan, not a finite number"):
        drv.cmd_vel(float("nan"), 0.0)
    # At the limit, and a hair over it (numerical noise), is obeyed at the limit.
    drv.cmd_vel(0.5 * (1 + SPEED_TOLERANCE / 2), -math.radians(100))
    wait_until(lambda: commands_since(emu, t0, Cmd.RVEL), 1)
    assert [a for _, a in commands_since(emu, t0, Cmd.VEL)] == [500]     # 0.5 m/s (p2os default)
    assert [a for _, a in commands_since(emu, t0, Cmd.RVEL)] == [-100]   # 100 deg/s
    assert drv.counters["refused"] == 3 and drv.counters["cmd_vel"] == 1


def test_watchdog_stops_the_base_200_ms_after_the_last_cmd_vel(rig):
    drv, emu, rec = rig
    t0 = time.monotonic()
    drv.cmd_vel(0.2, 0.0)
    wait_until(lambda: "watchdog" in rec.codes(), 2)
    # The event and the VEL 0 leave together; the emulator may read the packet a moment later.
    stop = wait_until(lambda: [t for t, a in commands_since(emu, t0, Cmd.VEL) if a == 0], 1)
    assert 0.19 < stop[0] - t0
    assert emu.robot.target_vel == 0
    assert drv.mode() == "idle"


def test_idle_driver_keeps_the_pioneer_watchdog_quiet(rig):
    drv, emu, rec = rig
    time.sleep(2.5)
    assert not emu.robot.watchdog_tripped
    assert commands_since(emu, 0, Cmd.PULSE)


def test_estop_sends_e_stop_and_refuses_motion_until_released(rig):
    drv, emu, rec = rig
    stream(drv, 0.3, 0.0, 0.5)
    t0 = time.monotonic()
    drv.set_estop(True, "test")
    wait_until(lambda: commands_since(emu, t0, Cmd.E_STOP) and emu.robot.vel == 0, 1)
    assert drv.cmd_vel(0.3, 0.0) is False
    stream(drv, 0.3, 0.0, 0.3)
    # No motion after the E_STOP, in the order the robot read them: a VEL sent before it may
    # still be read after t0 (seen under load).
    received = list(emu.robot.received)
    stop = next(i for i, (t, c, _) in enumerate(received) if t >= t0 and c == Cmd.E_STOP)
    assert emu.robot.target_vel == 0 and not [a for _, c, a in received[stop:] if c == Cmd.VEL and a]
    assert rec.codes().count("estop") == 1
    drv.set_estop(True, "again")                   # latched: no second event
    assert rec.codes().count("estop") == 1
    time.sleep(COMMAND_WATCHDOG_S)                 # the next cmd_vel is a new request (asibot.safety.arming)
    drv.set_estop(False)
    assert drv.cmd_vel(0.3, 0.0) is True
    wait_until(lambda: emu.robot.target_vel == 300, 1)
    assert "estop_released" in rec.codes()


@pytest.mark.slow
def test_pulled_cable_reconnects_and_the_base_was_stopped_meanwhile(rig):
    drv, emu, rec = rig
    stream(drv, 0.3, 0.0, 1.0)
    assert emu.robot.vel == 300
    emu.pull_cable(3.0)
    # the user keeps streaming for a moment: nothing reaches the robot
    stream(drv, 0.3, 0.0, 0.3)
    wait_until(lambda: "disconnected" in rec.codes(), 2)
    assert not drv.connected and drv.mode() == "fault" and "not connected" in drv.fault()
    wait_until(lambda: emu.robot.watchdog_tripped and emu.robot.vel == 0, 3.5,
               message="the Pioneer's own watchdog did not stop it")
    assert not drv.connected                      # stopped meanwhile, while the cable was out
    wait_until(lambda: rec.codes()[-2:] == ["connected", "ready"], 6, message="the driver did not reconnect")
    assert emu.connections == 2
    time.sleep(0.5)
    assert emu.robot.target_vel == 0 and emu.robot.vel == 0    # the old velocity did not come back
    assert rec.states[-1].vx == 0
    stream(drv, 0.2, 0.0, 0.5)                    # fresh commands drive again
    wait_until(lambda: emu.robot.vel == 200, 1)


def test_garbage_on_the_line_is_skipped(rig):
    drv, emu, rec = rig
    n0 = drv.counters["sips"]
    for _ in range(10):
        emu.inject_garbage(40)
        stream(drv, 0.2, 0.0, 0.1)
    drv.cmd_vel(0.0, 0.0)
    assert drv.connected and "disconnected" not in rec.codes()
    assert drv.counters["dropped_bytes"] > 0
    assert drv.counters["sips"] - n0 >= 7
    assert rec.states[-1].x > 0.05


def test_dropped_bytes_lose_one_sip_not_the_link(rig):
    drv, emu, rec = rig
    n0 = drv.counters["sips"]
    emu.drop_bytes(5)
    time.sleep(0.6)
    assert drv.connected and drv.counters["sips"] - n0 >= 3
    assert drv.counters["dropped_bytes"] > 0


def test_a_silent_controller_is_a_disconnect_then_a_reconnect(rig):
    drv, emu, rec = rig
    emu.go_silent(1.0)
    wait_until(lambda: "disconnected" in rec.codes(), 2)
    wait_until(lambda: drv.connected and rec.codes()[-2:] == ["connected", "ready"], 6)


def test_reset_fault_enables_the_motors(rig):
    drv, emu, rec = rig
    emu.robot.motors_enabled = False
    wait_until(lambda: "motors_disabled" in rec.codes(), 2)
    assert "motors are disabled" in drv.fault()
    drv.reset_fault()
    wait_until(lambda: rec.states[-1].motors_enabled, 2)
    assert drv.fault() == ""


def test_bumping_a_wall_reports_stall_and_bumper():
    from asibot.base_driver.emulator import gridmap
    from asibot.base_driver.emulator.robot import EmulatedP3at
    with ArcosEmulator(EmulatedP3at(gridmap.room(2.0, 2.0))) as emu:
        rec = Recorder()
        drv = BaseDriver(emu.url, on_state=rec.state, on_event=rec.event)
        drv.start()
        try:
            wait_until(lambda: drv.connected, 5)
            stream(drv, 0.5, 0.0, 2.5)
            assert "stall" in rec.codes() and "bumper" in rec.codes()
            assert any(any(s.front_bumpers) for s in rec.states)
            assert rec.states[-1].sonar_ranges[3] < 0.4
        finally:
            drv.close()


def test_low_battery_warns_once(rig):
    drv, emu, rec = rig
    emu.robot.battery_volts = 11.6
    wait_until(lambda: "battery_low" in rec.codes(), 2)
    time.sleep(0.3)
    assert rec.codes().count("battery_low") == 1
    emu.robot.battery_volts = 10.8
    wait_until(lambda: "battery_critical" in rec.codes(), 2)


def test_nobody_listening_is_reported_once_and_retried():
    rec = Recorder()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    drv = BaseDriver(f"socket://127.0.0.1:{port}", on_state=rec.state, on_event=rec.event)
    drv.start()
    try:
        wait_until(lambda: rec.codes(), 3)
        time.sleep(1.5)
        assert rec.codes() == ["disconnected"] and "retrying" in rec.events[0][2]
        assert not drv.connected and drv.cmd_vel(0.2, 0) is False
        with pytest.raises(RpcError, match="not connected") as err:
            drv.reset_fault()
        assert err.value.code == "unavailable"
    finally:
        drv.close()


def test_missing_keepalive_makes_the_emulated_pioneer_stop(emulator):
    """A raw client over TCP that goes quiet: after 2 s the Pioneer stops by itself."""
    with socket.create_connection(emulator.address) as s:
        s.settimeout(1.0)
        d = Deframer()

        def expect(pred):
            deadline = time.monotonic() + 2
            while time.monotonic() < deadline:
                for p in d.feed(s.recv(4096)):
                    if pred(p):
                        return p
            raise AssertionError("no such packet")

        for c in (0, 1, 2):
            s.sendall(codec.command(c))
            expect(lambda p, c=c: p[0] == c)
        for pkt in (codec.command(Cmd.OPEN), codec.command_int(Cmd.ENABLE, 1), codec.command_int(Cmd.VEL, 300)):
            s.sendall(pkt)
        wait_until(lambda: emulator.robot.vel == 300, 2)
        t0 = time.monotonic()
        wait_until(lambda: emulator.robot.watchdog_tripped, 3.5)
        assert time.monotonic() - t0 > 1.5
        sip = parse_sip(expect(lambda p: p[0] == 0x32))
        assert sip.left_vel == 0 and sip.right_vel == 0 and not sip.moving


def test_driver_over_a_pty_device_path(tmp_path):
    """The emulator's pty stands in for /dev/ttyUSB0: a plain device path as --port."""
    path = str(tmp_path / "ttyPioneer")
    with ArcosEmulator(pty_link=path):
        rec = Recorder()
        drv = BaseDriver(path, on_state=rec.state, on_event=rec.event)
        drv.start()
        try:
            wait_until(lambda: drv.connected and rec.states, 5)
            stream(drv, 0.2, 0.0, 0.5)
            wait_until(lambda: rec.states[-1].x > 0.05, 2)
        finally:
            drv.close()


def test_control_lines_of_the_standalone_emulator(emulator):
    from asibot.base_driver.emulator import ControlServer
    ctl = ControlServer(emulator, ("127.0.0.1", 0))
    try:
        assert ctl.handle("status")["ok"] and ctl.handle("status")["open"] is False
        assert ctl.handle("drop 3") == {"ok": True} and emulator._drop == 3
        assert ctl.handle("garbage 4") == {"ok": True} and len(emulator._garbage) == 4
        for bad in ("", "silent", "silent -1", "silent nan", "unplug 1 2", "fly 1", "drop x"):
            reply = ctl.handle(bad)
            assert reply["ok"] is False and reply["message"]
    finally:
        ctl.close()
