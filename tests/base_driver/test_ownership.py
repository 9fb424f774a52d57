"""Issue 10, finding 1 and 4, for the Pioneer: the driver obeys only the controller that holds
the base (asibot.safety.ownership); a cmd_vel stream that keeps coming through a pulled cable or an
estop does not drive the base when it is back until the stream pauses (asibot.safety.arming); the
estop outlives whoever engaged it (asibot.safety.estop).

The service on the in-memory bus against the ARCOS emulator (a P3-AT over TCP)."""

from __future__ import annotations

import time

import pytest

from asibot import keys, messages
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.messages import COMMAND_WATCHDOG_S, EStop, Twist
from asibot.testing import Inbox, Stream, wait_until, release, release_counts_only_signed

from .conftest import ROBOT


def stays_still(base, seconds: float) -> None:
    """The emulated Pioneer is told no velocity, sampled throughout `seconds`."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        assert base.emulator.robot.target_vel == 0 and base.emulator.robot.target_rot == 0, "the base moved"
        time.sleep(0.02)


def events(base, code: str) -> list:
    return [e for e in base.events.all() if e.code == code]


def test_only_the_holders_cmd_vel_drives_the_base(base):
    other = Bus("a-teleop-program")
    try:
        second = ownership.announce(other, ROBOT, "base", "teleop")
        wait_until(lambda: second.id in base.svc.holder.alive, 5)
        for controller in ("", "nav-0badc0de", second.id):    # anonymous, a stranger, the second one
            base.user.put_raw(keys.base_cmd_vel(ROBOT), messages.pack({"vx": 0.3, "wz": 0.0,
                                                                      "controller": controller}))
        wait_until(lambda: events(base, "not_holder"), 5, message="no not_holder event")
        stays_still(base, 0.3)
        text = events(base, "not_holder")[0].text
        assert text.startswith("Base command refused") and f"controller {base.controller.id!r} holds the base" in text
        assert base.svc.not_holder == 3 and base.svc.driver.counters["cmd_vel"] == 0
        # The holder's id, read from its liveliness token, borrowed by another process.
        base.user.put_raw(keys.base_cmd_vel(ROBOT), messages.pack({"vx": 0.3, "wz": 0.0,
                                                                  "controller": base.controller.id}))
        wait_until(lambda: events(base, "not_signed"), 5, message="no not_signed event")
        stays_still(base, 0.3)
        base.controller.put(base.user.publisher(keys.base_cmd_vel(ROBOT), Twist), Twist(vx=0.3, wz=0.0))
        wait_until(lambda: base.emulator.robot.target_vel == 300, 3)
    finally:
        other.close()


# A stream timed against the watchdog, as the arm driver's: tests/run runs it with the robots.
@pytest.mark.realtime
@pytest.mark.parametrize("interruption", ["cable", "estop"])
def test_a_stream_through_an_interruption_drives_only_after_it_pauses(base, interruption):
    """The stream goes on while the cable is out (or the estop engaged); when the base is back
    it stays still, says it is ready, and drives only once the stream paused and restarted."""
    cmd = base.user.publisher(keys.base_cmd_vel(ROBOT), Twist)
    stream = Stream(lambda: base.controller.put(cmd, Twist(vx=0.2, wz=0.0)))
    try:
        wait_until(lambda: base.emulator.robot.target_vel == 200, 3, message="the stream did not drive the base")
        if interruption == "cable":
            base.emulator.pull_cable(0.5)
            wait_until(lambda: "disconnected" in base.codes(), 3)
            wait_until(lambda: "ready" in base.codes()[base.codes().index("disconnected"):], 6,
                       message="no reconnection")
        else:
            base.user.latch(keys.estop(ROBOT), EStop(engaged=True, reason="test"))
            wait_until(lambda: events(base, "estop"), 3)
            release(base.user, ROBOT, by="a tester")
            wait_until(lambda: events(base, "ready"), 3)
        back = time.monotonic()
        wait_until(lambda: base.emulator.robot.target_vel == 0, 3)    # a fresh line, or the E_STOP
        stays_still(base, 0.6)
        assert stream.longest_gap(back) < COMMAND_WATCHDOG_S / 2, "the machine paused the stream itself"
        wait_until(lambda: events(base, "not_ready"), 3, message="no not_ready event")
        assert base.svc.driver.counters["not_ready"] > 0
        stream.pause()
        time.sleep(COMMAND_WATCHDOG_S)
        stream.resume()
        wait_until(lambda: base.emulator.robot.target_vel == 200, 3, message="the restarted stream did not drive")
    finally:
        stream.close()


def test_the_estop_outlives_whoever_engaged_it_and_its_release_says_who(base):
    with Bus("asibot-estop") as button:                   # engages and exits, as `asibot estop` does
        button.latch(keys.estop(ROBOT), EStop(engaged=True, reason="test", by="ana@home (asibot estop, pid 7)"))
        wait_until(lambda: events(base, "estop"), 3)
    late = Bus("a-ui-started-later")
    try:
        learnt = Inbox()
        late.subscribe(keys.estop(ROBOT), EStop, learnt, latest=True)
        wait_until(lambda: len(learnt), 5, message="a late subscriber learnt nothing of the estop")
        assert learnt.last().engaged and learnt.last().by == "ana@home (asibot estop, pid 7)"
        # Anyone can write a name; a release counts only signed, by the key it names.
        release_counts_only_signed(late, ROBOT, lambda code: events(base, code), "bob@home (asibot release, pid 8)")
    finally:
        late.close()


def test_a_joystick_takes_the_base_from_nav_at_once_and_nav_drives_again_once_it_is_quiet(base):
    """twist_mux's rule, in the driver: a person's controller (TELEOP) overtakes nav (AUTONOMOUS)
    with its first command; nav's are refused while it drives and for TAKEOVER_HOLD after."""
    nav_bus, joy_bus = Bus("nav"), Bus("a-joystick-program")
    try:
        base.controller_bus.close()                      # the fixture's controller ends: nav holds
        nav = ownership.announce(nav_bus, ROBOT, "base", "nav")
        joystick = ownership.announce(joy_bus, ROBOT, "base", "joystick")
        wait_until(lambda: base.svc.holder.current == nav.id and joystick.id in base.svc.holder.alive, 5)
        to_base = base.user.publisher(keys.base_cmd_vel(ROBOT), Twist)
        time.sleep(COMMAND_WATCHDOG_S)                   # nav's stream begins after the change of holder
        nav_stream = Stream(lambda: nav.put(to_base, Twist(vx=0.2, wz=0.0)))
        with nav_stream:
            wait_until(lambda: base.emulator.robot.target_vel == 200, 3, message="nav never drove")
            with Stream(lambda: joystick.put(to_base, Twist(vx=-0.1, wz=0.0))):
                wait_until(lambda: base.emulator.robot.target_vel == -100, 3, message="the joystick never drove")
                assert base.svc.holder.current == joystick.id
                time.sleep(0.3)
                assert base.emulator.robot.target_vel == -100, "nav's stream fought the joystick's"
            # the joystick let go: the base stops (the driver's watchdog), and nav's stream still
            # running from before the takeover does not move it again
            wait_until(lambda: base.svc.holder.current == nav.id, ownership.TAKEOVER_HOLD + 2,
                       message="the base was never given back to nav")
            stays_still(base, 0.5)
        time.sleep(COMMAND_WATCHDOG_S)                   # a new motion of nav's drives
        with Stream(lambda: nav.put(to_base, Twist(vx=0.15, wz=0.0))):
            wait_until(lambda: base.emulator.robot.target_vel == 150, 3, message="nav could not drive again")
    finally:
        joy_bus.close()
        nav_bus.close()
