"""`asibot up --profile emulated`: the real drivers against their wire-level emulators, driven
from the same client API and messages as the simulation."""

import json
import math
import socket
import threading
import time

import numpy as np
import pytest

from asibot import keys
from asibot.safety import ownership
from asibot.client import CartesianClient, NavClient
from asibot.messages import ArmState, Event, LaserScan, Odometry, Twist
from asibot.testing import wait_until

pytestmark = pytest.mark.slow


def test_the_emulated_profile_drives_both_robots(up):
    stack = up("emulated")
    stack.wait_alive("arm_driver/asibot", "base_driver/pioneer", "kinematics/asibot", "recorder/main")

    # The arm: CANopen drives behind the kinematics service, from CartesianClient. The driver
    # announces itself once the five drives are in operation enabled.
    wait_until(lambda: stack.bus.alive(keys.driver_alive("asibot")), 20)
    states: list[ArmState] = []
    stack.bus.subscribe(keys.arm_state("asibot"), ArmState, states.append)
    with CartesianClient() as arm:
        arm.open("asibot")
        arm.movj(joints=[10, 20, 30, 20, 0])
        arm.wait(timeout=30)
        assert arm.state()["joints"] == pytest.approx([10, 20, 30, 20, 0], abs=0.2)
    assert states and states[-1].positions[0] == pytest.approx(0.1745, abs=0.005)

    # The base: ARCOS over TCP to the emulated P3-AT, cmd_vel in (from the controller that
    # holds the base: this test, asibot.safety.ownership), odometry out.
    # nav drives the base too in this profile: a test, as a person's teleop, takes it from nav
    # with its first command, once the driver knows it is alive.
    controller = ownership.announce(stack.bus, "pioneer", "base", "test")
    assert ownership.HoldWait(stack.bus, "pioneer", "base", controller.id).wait(time.monotonic() + 10)
    odom: list[Odometry] = []
    stack.bus.subscribe(keys.base_odom("pioneer"), Odometry, odom.append)
    wait_until(lambda: odom, 10)
    x0 = odom[-1].x
    cmd = stack.bus.publisher(keys.base_cmd_vel("pioneer"), Twist)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        controller.put(cmd, Twist(vx=0.3, wz=0.0))
        time.sleep(0.05)
    # The driver's 200 ms watchdog stops the base once the commands end.
    wait_until(lambda: abs(odom[-1].vx) < 1e-3, 5)
    assert odom[-1].x - x0 == pytest.approx(0.6, abs=0.12)

    # The Katana on the P3-AT: an emulated controller on a pseudo-terminal, in the base driver's
    # process under the robot's one driver contract, calibrated at start (each motor to its
    # stopper), jogged through the kinematics service as the sim's Katana is.
    katana: list[ArmState] = []
    stack.bus.subscribe(keys.arm_state("pioneer"), ArmState, katana.append)
    wait_until(lambda: katana and katana[-1].mode == "idle", 60, message="the emulated Katana never calibrated")
    stack.wait_alive("kinematics/pioneer", timeout=30)
    with CartesianClient() as arm:
        arm.open("pioneer")
        before = arm.state()["joints"]
        arm.relj([10, 0, 0, 0, 15])            # one jog of joint 1 and the wrist (calibration leaves it low)
        arm.wait(timeout=30)
    # The Katana's own position loop (25 Hz over its serial line) settles after the trajectory ends.
    goal = [before[0] + 10, before[4] + 15]
    wait_until(lambda: abs(math.degrees(katana[-1].positions[0]) - goal[0]) < 0.5
               and abs(math.degrees(katana[-1].positions[4]) - goal[1]) < 0.5, 10,
               message=lambda: f"the Katana stands at {[math.degrees(q) for q in katana[-1].positions]}, not {goal}")
    assert stack.bus.call(keys.driver_rpc("pioneer", "status"))["arm"]["serial"] == "emulated"

    assert stack.stop() == 130   # stopped by Ctrl-C: the shell's 128 + SIGINT


def emulator_pose(stack) -> tuple[float, float, float]:
    """Where the emulated P3-AT really is: its control port's `status` (not what nav believes)."""
    with socket.create_connection(("127.0.0.1", stack.pioneer_control), timeout=5) as s, \
            s.makefile("rw", encoding="utf-8", newline="\n") as f:
        f.write("status\n")
        f.flush()
        st = json.loads(f.readline())
    return st["x"], st["y"], st["theta"]


class TextClient:
    """The bridge's text protocol, as netcat: one line out, the lines that come back."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.sock.settimeout(None)          # a trip is minutes of silence; close() ends the reader
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        with self.sock.makefile("r", encoding="utf-8", newline="\n") as f:
            try:
                for line in f:
                    self.lines.append(line.strip())
            except OSError:
                pass

    def say(self, text: str) -> None:
        self.sock.sendall(text.encode() + b"\n")

    def close(self) -> None:
        self.sock.close()


@pytest.mark.timeout(420)
def test_the_emulated_pioneer_goes_to_the_fridge_by_nav_and_back_by_the_bridge_on_its_sonar_alone(up):
    """The users' side on the hardware path: nav and perception on the real ARCOS driver, the
    P3-AT's 16 sonars its only sensor (no depth camera), judged by the emulator's own pose."""
    stack = up("emulated", "base-driver-emulated", "nav-pioneer", "asterics-bridge-emulated")
    stack.wait_alive("base_driver/pioneer", "perception/pioneer", "nav/pioneer", "asterics_bridge/pioneer", timeout=120)
    events: list[Event] = []
    stack.bus.subscribe(keys.events("pioneer"), Event, events.append)
    scans: list[LaserScan] = []
    stack.bus.subscribe(keys.scan("pioneer"), LaserScan, scans.append)
    wait_until(lambda: scans, 20, message="no scan from the sonar")
    assert np.isfinite(scans[-1].ranges).sum() <= 16, "a scan from sonar has at most one return per sonar"
    with NavClient("pioneer", timeout=10) as nav:
        wait_until(lambda: nav.status()["localised"], 60, interval=0.5, message="nav never localised on sonar")
        fridge = nav.places()["fridge"]
        nav.wait(nav.goto("fridge"), timeout=240)
        x, y, theta = emulator_pose(stack)
        assert math.hypot(x - fridge[0], y - fridge[1]) < 0.3, (x, y, fridge)
        assert abs(math.remainder(theta - fridge[2], 2 * math.pi)) < 0.3
    # parked facing the fridge: the sonar heard it ahead
    assert any(e.code == "obstacle" and "ahead" in e.text for e in events), [e.text for e in events]
    # the switch user's way: the bridge's text protocol, as AsTeRICS's or a netcat's line
    client = TextClient(stack.asterics_port)
    try:
        client.say("goto charging station")
        wait_until(lambda: any(ln.startswith("ok") for ln in client.lines), 15, message=lambda: f"{client.lines}")
        wait_until(lambda: any("goal reached" in ln for ln in client.lines), 240, interval=0.5,
                   message=lambda: f"no 'goal reached' line; got {client.lines}; nav: "
                                   f"{stack.bus.call(keys.nav_rpc('pioneer', 'status'), timeout=5)}; "
                                   f"the emulator: {emulator_pose(stack)}")
    finally:
        client.close()
    x, y, _ = emulator_pose(stack)
    assert math.hypot(x - 0.75, y - 1.5) < 0.3, (x, y)
