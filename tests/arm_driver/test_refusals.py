"""Issue 10, finding 1 and 8: a command beyond the limits is refused with an Event, never
clipped and obeyed, and a stream of them gives about one Event a second.

The service with its five emulated drives in this process, on the in-memory bus."""

from __future__ import annotations

import math
import time

import pytest

from asibot import keys
from asibot.safety.events import stands_for
from asibot.messages import ArmCommand, Event
from asibot.testing import Inbox, wait_until, signed_raw

from .conftest import R

Q2_UPPER = math.radians(135)
VMAX = math.radians(25)


def refusals(events: Inbox) -> list[Event]:
    return [e for e in events.all() if e.code == "bad_command"]


def assert_still(svc, states: Inbox, before: list[float], n: int = 30) -> None:
    """The joints stay where they were over the next `n` states (0.3 s at 100 Hz), on the bus
    and in the emulated drives."""
    start = len(states)
    wait_until(lambda: len(states) >= start + n, 10, message="no arm states")
    for s in states.all()[start:start + n]:
        assert s.positions == pytest.approx(before, abs=1e-6), "a refused command moved the arm"
        assert s.mode == "idle"
    drives = svc.emulator.positions()
    assert [drives[n] for n in range(1, 6)] == pytest.approx(before, abs=1e-6)


@pytest.mark.parametrize("payload, says", [
    ({"mode": "position", "values": [1e300] * 5},
     "joint q1 position 1e+300 rad is beyond its upper limit 6.28 rad"),
    ({"mode": "position", "values": [0.0, Q2_UPPER + 0.01, 0.0, 0.0, 0.0]},
     "joint q2 position 2.37 rad is beyond its upper limit 2.36 rad"),
    ({"mode": "position", "values": [0.0, 0.0, -1e300, 0.0, 0.0]},
     "joint q3 position -1e+300 rad is beyond its lower limit -2.36 rad"),
    ({"mode": "position", "values": [0.1] * 5, "velocities": [0.0, 0.0, 0.0, 1.0, 0.0]},
     "joint q4 velocity feed-forward 1 rad/s is beyond its max speed 0.436 rad/s"),
    ({"mode": "velocity", "values": [0.0, 0.0, 0.0, 0.0, -2 * VMAX]},
     "joint q5 velocity -0.873 rad/s is beyond its max speed 0.436 rad/s"),
    ({"mode": "velocity", "values": [1e300, 0.0, 0.0, 0.0, 0.0]},
     "joint q1 velocity 1e+300 rad/s is beyond its max speed 0.436 rad/s"),
    ({"mode": "position", "values": [math.nan, 0.0, 0.0, 0.0, 0.0]}, "not finite"),
])
def test_a_command_beyond_the_limits_is_refused_with_an_event_and_nothing_moves(arm, payload, says):
    svc, user, states, events = arm.svc, arm.user, arm.states, arm.events
    before = states.last().positions
    user.put_raw(keys.arm_command(R), signed_raw(arm.controller, ArmCommand, payload))
    wait_until(lambda: refusals(events), 5, message="no bad_command event")
    event = refusals(events)[0]
    assert event.level == "error"
    assert event.text.startswith("Arm command refused, the arm keeps its previous motion: ")
    assert says in event.text, event.text
    assert_still(svc, states, before)
    assert svc.driver.counters["rejected_commands"] + svc.bus.rejected >= 1


def test_a_refused_command_does_not_interrupt_the_motion_under_way(arm):
    states, events, c = arm.states, arm.events, arm.controller
    cmd = arm.user.publisher(keys.arm_command(R), ArmCommand)
    c.put(cmd, ArmCommand(mode="position", values=[0.3, 0.0, 0.0, 0.0, 0.0]))   # 0.7 s at 25 deg/s
    wait_until(lambda: states.last().velocities[0] > 0.1, 5)
    c.put(cmd, ArmCommand(mode="position", values=[1e300] * 5))
    wait_until(lambda: refusals(events), 5)
    assert states.last().positions[0] < 0.3 and states.last().mode == "position"
    wait_until(lambda: abs(states.last().positions[0] - 0.3) < 1e-4, 5, message="the motion stopped")
    start = len(states)
    wait_until(lambda: len(states) >= start + 20, 5)
    assert max(abs(s.positions[0] - 0.3) for s in states.all()[start:]) < 1e-4   # and never passed it


def test_the_planners_noise_at_a_limit_is_not_refused(arm):
    """A position a few micro-radians past a limit (a hold at a measured position, half an
    encoder count off) is clamped to the limit, without an event."""
    svc, states, events = arm.svc, arm.states, arm.events
    svc.driver.ref.vmax = [v * 20 for v in svc.driver.ref.vmax]       # get to the limit quickly
    svc.emulator.drives[2].max_speed_counts *= 20
    cmd = arm.user.publisher(keys.arm_command(R), ArmCommand)
    arm.controller.put(cmd, ArmCommand(mode="position", values=[0.0, Q2_UPPER + 5e-6, 0.0, 0.0, 0.0]))
    wait_until(lambda: abs(states.last().positions[1] - Q2_UPPER) < 1e-4, 5)
    start = len(states)
    wait_until(lambda: len(states) >= start + 20, 5)
    assert max(s.positions[1] for s in states.all()[start:]) <= Q2_UPPER + 5e-6   # half a count at most
    assert not refusals(events)


def test_a_burst_of_300_bad_commands_gives_one_event_a_second_with_the_count(arm):
    svc, states, events = arm.svc, arm.states, arm.events
    before = states.last().positions
    cmd = arm.user.publisher(keys.arm_command(R), ArmCommand)
    t0 = time.monotonic()
    for i in range(300):        # every one different, as a fuzzer sends them
        arm.controller.put(cmd, ArmCommand(mode="position", values=[10.0 + i, 0.0, 0.0, 0.0, 0.0]))
    sent_in = time.monotonic() - t0

    def accounted() -> int:
        return sum(stands_for(e.text) for e in refusals(events))

    wait_until(lambda: accounted() >= 300, 10, message=f"refusals accounted for: {accounted()}")
    got = refusals(events)
    assert len(got) <= 2 + math.ceil(sent_in), [e.text for e in got]
    assert accounted() == 300
    assert "joint q1 position 10 rad" in got[0].text and "joint q1 position 309 rad" in got[-1].text
    assert_still(svc, states, before)
