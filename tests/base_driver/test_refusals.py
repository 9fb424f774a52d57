"""Issue 10, finding 1 and 8: a cmd_vel beyond the driver's limits is refused with an Event,
never clamped and obeyed, and a stream of them gives about one Event a second.

The service on the in-memory bus against the ARCOS emulator (a P3-AT over TCP)."""

from __future__ import annotations

import math
import time

import pytest

from asibot import keys, messages
from asibot.safety.events import stands_for
from asibot.messages import Event, Twist
from asibot.testing import Inbox, wait_until, signed_raw

from .conftest import ROBOT


def refusals(events: Inbox) -> list[Event]:
    return [e for e in events.all() if e.code == "bad_command"]


def assert_still(odom: Inbox, emulator, n: int = 5) -> None:
    """The base stays put over the next `n` odometry messages (0.5 s at 10 Hz)."""
    first = odom.all()[-1]
    start = len(odom)
    wait_until(lambda: len(odom) >= start + n, 5, message="no odometry")
    for o in odom.all()[start:start + n]:
        assert (o.x, o.y, o.theta, o.vx, o.wz) == pytest.approx((first.x, first.y, first.theta, 0.0, 0.0), abs=1e-6)
    assert emulator.robot.target_vel == 0 and emulator.robot.target_rot == 0


@pytest.mark.parametrize("payload, says", [
    ({"vx": 1e300, "wz": 0.0}, "vx 1e+300 m/s is beyond the driver's max speed 0.5 m/s (--max-vx)"),
    ({"vx": -0.6, "wz": 0.0}, "vx -0.6 m/s is beyond the driver's max speed 0.5 m/s (--max-vx)"),
    ({"vx": 0.0, "wz": 2.0}, "wz 2 rad/s is beyond the driver's max turn rate 1.75 rad/s (--max-wz)"),
    ({"vx": math.nan, "wz": 0.0}, "not finite"),
])
def test_a_cmd_vel_beyond_the_limits_is_refused_with_an_event_and_nothing_moves(base, payload, says):
    svc, user, odom, events, emu = base.svc, base.user, base.odom, base.events, base.emulator
    user.put_raw(keys.base_cmd_vel(ROBOT), signed_raw(base.controller, Twist, payload))
    wait_until(lambda: refusals(events), 5, message="no bad_command event")
    event = refusals(events)[0]
    assert event.level == "error"
    assert event.text.startswith("Base command refused, the base keeps its previous motion: ")
    assert says in event.text, event.text
    assert_still(odom, emu)
    assert svc.driver.counters["cmd_vel"] == 0


def test_a_burst_of_300_bad_cmd_vel_gives_one_event_a_second_with_the_count(base):
    svc, user, odom, events, emu = base.svc, base.user, base.odom, base.events, base.emulator
    pub = user.publisher(keys.base_cmd_vel(ROBOT), Twist)
    t0 = time.monotonic()
    for i in range(300):
        base.controller.put(pub, Twist(vx=1.0 + i, wz=0.0))
    sent_in = time.monotonic() - t0

    def accounted() -> int:
        return sum(stands_for(e.text) for e in refusals(events))

    wait_until(lambda: accounted() >= 300, 10, message=f"refusals accounted for: {accounted()}")
    got = refusals(events)
    assert len(got) <= 2 + math.ceil(sent_in), [e.text for e in got]
    assert accounted() == 300 and svc.driver.counters["refused"] == 300
    assert "vx 1 m/s" in got[0].text and "vx 300 m/s" in got[-1].text
    assert_still(odom, emu)


def test_a_different_mistake_is_reported_at_once(base):
    user, events = base.user, base.events
    pub = user.publisher(keys.base_cmd_vel(ROBOT), Twist)
    for _ in range(5):
        base.controller.put(pub, Twist(vx=3.0, wz=0.0))
    user.put_raw(keys.base_cmd_vel(ROBOT), messages.pack({"vx": "fast", "wz": 0.0}))
    wait_until(lambda: len(refusals(events)) >= 2, 0.9, message="the second kind of mistake was held back")
    assert "vx 3 m/s" in refusals(events)[0].text and "Twist.vx" in refusals(events)[1].text
