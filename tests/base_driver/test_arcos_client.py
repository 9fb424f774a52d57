"""The ARCOS client's handshake and state reflection, on an in-memory line with a fake clock."""

import pytest
import serial

from asibot.base_driver import codec
from asibot.base_driver.arcos import ArcosClient, ArcosError, to_firmware
from asibot.base_driver.codec import Cmd
from asibot.base_driver.emulator.robot import EmulatedP3at
from asibot.base_driver.link import open_link
from asibot.base_driver.params import P3AT, P3AT_SH

from .conftest import RobotLink


def connected(robot=None):
    link = RobotLink(robot)
    client = ArcosClient(link, clock=link.clock)
    ident = client.connect()
    return link, client, ident


def test_handshake_order_and_identity():
    link, client, ident = connected(EmulatedP3at(params=P3AT, name="bob"))
    assert (ident.name, ident.klass, ident.subclass) == ("bob", "Pioneer", "p3at")
    assert client.params is P3AT
    assert link.written[:3] == [codec.command(0), codec.command(1), codec.command(2)]
    assert link.written[3:8] == [codec.command(Cmd.OPEN), codec.command(Cmd.PULSE),
                                 codec.command_int(Cmd.ENABLE, 1), codec.command_int(Cmd.SONAR, 1),
                                 codec.command_int(Cmd.VEL, 0)]
    assert link.written[8] == codec.command_int(Cmd.RVEL, 0)
    assert link.robot.is_open and link.robot.motors_enabled


def test_a_robot_still_open_gets_close_and_a_fresh_sync():
    robot = EmulatedP3at()
    link, client, _ = connected(robot)
    client.set_velocity(400, 0)
    # a new client on the same robot (old session never closed)
    link2 = RobotLink(robot, link.clock)
    client2 = ArcosClient(link2, clock=link2.clock)
    client2.connect()
    assert codec.command(Cmd.CLOSE) in link2.written
    assert robot.is_open and robot.target_vel == 0            # the old setpoint is gone


def test_no_robot_on_the_line_is_a_clear_error():
    class Dead(RobotLink):
        def read(self, size=1):
            self.clock.t += 0.05
            return b""
    link = Dead()
    with pytest.raises(ArcosError, match="SYNC0/1/2"):
        ArcosClient(link, clock=link.clock).connect()


def test_forced_params_win_over_the_subclass():
    link = RobotLink(EmulatedP3at(params=P3AT))
    client = ArcosClient(link, params=P3AT_SH, clock=link.clock)
    client.connect()
    assert client.params is P3AT_SH


def test_unknown_subclass_closes_and_says_how_to_force():
    robot = EmulatedP3at()
    robot.params = robot.params.__class__(subclass="amigo")
    link = RobotLink(robot)
    with pytest.raises(ArcosError, match="--params"):
        ArcosClient(link, clock=link.clock).connect()
    assert link.written[-1] == codec.command(Cmd.CLOSE)


def test_state_reflection_sends_only_changes_and_refreshes_every_500_ms():
    link, client, _ = connected()
    n = len(link.written)
    client.set_velocity(300, 0)
    client.set_velocity(300, 0)
    assert link.written[n:] == [codec.command_int(Cmd.VEL, 300)]
    client.set_velocity(300, -10)
    assert link.written[n + 1:] == [codec.command_int(Cmd.RVEL, -10)]
    n = len(link.written)
    link.clock.t += 0.3
    client.refresh()
    assert len(link.written) == n                              # nothing due yet
    link.clock.t += 0.25
    client.refresh()
    assert link.written[n:] == [codec.command_int(Cmd.VEL, 300), codec.command_int(Cmd.RVEL, -10)]


def test_idle_client_pulses_to_keep_the_watchdog_quiet():
    link, client, _ = connected()
    n = len(link.written)
    for _ in range(60):                 # 3 s of cycles on the fake clock
        link.clock.t += 0.05
        client.read_payloads()
        client.refresh()
    pulses = link.written[n:].count(codec.command(Cmd.PULSE))
    assert pulses >= 5 and not link.robot.watchdog_tripped


def test_emergency_stop_sends_e_stop_and_a_zero_setpoint():
    link, client, _ = connected()
    client.set_velocity(500, 20)
    n = len(link.written)
    client.emergency_stop()
    assert link.written[n:] == [codec.command(Cmd.E_STOP), codec.command_int(Cmd.VEL, 0),
                                codec.command_int(Cmd.RVEL, 0)]
    assert client.desired == (0, 0) and link.robot.vel == 0


def test_close_sends_stop_then_close():
    link, client, _ = connected()
    client.close()
    assert link.written[-2:] == [codec.command(Cmd.STOP), codec.command(Cmd.CLOSE)] and link.closed


def test_to_firmware_rounds_like_p2os():
    assert to_firmware(0.3, 0.0) == (300, 0)
    assert to_firmware(-0.1234, -1.0) == (-123, -57)


def test_over_tcp_with_pyserial_socket_url(emulator):
    link = open_link(emulator.url)
    client = ArcosClient(link)
    try:
        ident = client.connect()
        assert ident.subclass == "p3at-sh"
        payloads = []
        for _ in range(30):
            payloads += client.read_payloads()
        assert any(p[0] in (0x32, 0x33) for p in payloads)
    finally:
        client.close()


def test_a_closed_port_raises_a_serial_error():
    with pytest.raises(serial.SerialException):
        open_link("socket://127.0.0.1:1")
