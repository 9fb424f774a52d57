"""Issue 10, finding 1 and 8, for the sim: arm commands beyond the joint limits or max speeds,
and cmd_vel beyond the P3-AT's max speeds, are refused with an Event, never clipped and
obeyed, and a stream of them gives about one Event a second.

The sim service in this process (real time, no cameras) on the in-memory bus."""

from __future__ import annotations

import math
import time

import pytest

from asibot import keys
from asibot import messages as m
from asibot.safety.events import stands_for
from asibot.testing import Inbox, wait_until, signed_raw

from .conftest import ROBOT


def refusals(events: Inbox) -> list[m.Event]:
    return [e for e in events.all() if e.code == "bad_command"]


def assert_still(arm: Inbox, odom: Inbox, before: list[float], n: int = 30) -> None:
    """Over the next `n` arm states (0.3 s at 100 Hz) the arm stays put and the base too."""
    x0 = odom.last().x
    start = len(arm)
    wait_until(lambda: len(arm) >= start + n, 10, message="no arm states")
    for s in arm.all()[start:start + n]:
        assert s.positions == pytest.approx(before, abs=1e-3), "a refused command moved the arm"
        assert s.mode == "idle"
    assert odom.last().x == pytest.approx(x0, abs=1e-4) and odom.last().vx == pytest.approx(0.0, abs=1e-4)


def names_and_limits(svc):
    r = svc.sim.robot
    return r.joint_names, r.lower, r.upper, r.max_velocity


@pytest.mark.parametrize("case", ["huge", "nan", "past_upper", "past_lower", "velocity", "feed_forward"])
def test_an_arm_command_beyond_the_limits_is_refused_with_an_event_and_nothing_moves(sim, case):
    svc, user, arm, odom, events = sim
    names, lower, upper, vmax = names_and_limits(svc)
    here = list(arm.last().positions)
    payload, says = {
        "huge": ({"mode": "position", "values": [1e300] * 5},
                 f"joint {names[0]} position 1e+300 rad is beyond its upper limit {upper[0]:.3g} rad"),
        "nan": ({"mode": "position", "values": [math.nan] + here[1:]}, "not finite"),
        "past_upper": ({"mode": "position", "values": here[:1] + [upper[1] + 0.05] + here[2:]},
                       f"joint {names[1]} position {upper[1] + 0.05:.3g} rad is beyond its upper limit "
                       f"{upper[1]:.3g} rad"),
        "past_lower": ({"mode": "position", "values": here[:2] + [lower[2] - 1.0] + here[3:]},
                       f"joint {names[2]} position {lower[2] - 1.0:.3g} rad is beyond its lower limit "
                       f"{lower[2]:.3g} rad"),
        "velocity": ({"mode": "velocity", "values": [0.0, 0.0, 0.0, 2 * vmax[3], 0.0]},
                     f"joint {names[3]} velocity {2 * vmax[3]:.3g} rad/s is beyond its max speed {vmax[3]:.3g} rad/s"),
        "feed_forward": ({"mode": "position", "values": here, "velocities": [0.0, 0.0, 0.0, 0.0, -1e300]},
                         f"joint {names[4]} velocity feed-forward -1e+300 rad/s is beyond its max speed"),
    }[case]
    user.put_raw(keys.arm_command(ROBOT), signed_raw(sim.arm_controller, m.ArmCommand, payload))
    wait_until(lambda: refusals(events), 5, message="no bad_command event")
    event = refusals(events)[0]
    assert event.level == "error"
    assert event.text.startswith("Arm command refused, the arm keeps its previous motion: ")
    assert says in event.text, event.text
    assert_still(arm, odom, here)


@pytest.mark.parametrize("payload, says", [
    ({"vx": 1e300, "wz": 0.0}, "vx 1e+300 m/s is beyond the P3-AT's max speed 1.2 m/s"),
    ({"vx": 0.0, "wz": -6.0}, "wz -6 rad/s is beyond the P3-AT's max turn rate 5.24 rad/s"),
    ({"vx": math.nan, "wz": 0.0}, "not finite"),
])
def test_a_cmd_vel_beyond_the_p3at_is_refused_with_an_event_and_nothing_moves(sim, payload, says):
    svc, user, arm, odom, events = sim
    here = list(arm.last().positions)
    user.put_raw(keys.base_cmd_vel(ROBOT), signed_raw(sim.base_controller, m.Twist, payload))
    wait_until(lambda: refusals(events), 5, message="no bad_command event")
    event = refusals(events)[0]
    assert event.text.startswith("Base command refused, the base keeps its previous motion: ")
    assert says in event.text, event.text
    assert_still(arm, odom, here)
    assert svc.sim.truth()[0] == pytest.approx(1.0, abs=1e-3)  # the apartment's start


def test_a_burst_of_300_bad_commands_gives_one_event_a_second_per_reason(sim):
    svc, user, arm, odom, events = sim
    here = list(arm.last().positions)
    cmd = user.publisher(keys.arm_command(ROBOT), m.ArmCommand)
    drive = user.publisher(keys.base_cmd_vel(ROBOT), m.Twist)
    t0 = time.monotonic()
    for i in range(300):        # every one different, as a fuzzer sends them; two reasons
        if i % 2:
            sim.arm_controller.put(cmd, m.ArmCommand(mode="position", values=[1e3 + i] + here[1:]))
        else:
            sim.base_controller.put(drive, m.Twist(vx=10.0 + i, wz=0.0))
    sent_in = time.monotonic() - t0

    def accounted() -> int:
        return sum(stands_for(e.text) for e in refusals(events))

    wait_until(lambda: accounted() >= 300, 10, message=f"refusals accounted for: {accounted()}")
    got = refusals(events)
    assert len(got) <= 2 * (2 + math.ceil(sent_in)), [e.text for e in got]
    assert accounted() == 300
    assert sum(e.text.startswith("Arm") for e in got) >= 1 and sum(e.text.startswith("Base") for e in got) >= 1
    assert_still(arm, odom, here)
