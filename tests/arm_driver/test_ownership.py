"""Issue 10, finding 1 and 4: the arm driver obeys only the controller that holds the arm
(asibot.safety.ownership), a new holder's stream from before does not move the arm (asibot.safety.arming),
and the estop it obeys outlives whoever engaged it (asibot.safety.estop).

The service with its five emulated drives in this process, on the in-memory bus."""

from __future__ import annotations

import time

import pytest

from asibot import keys, messages
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.messages import COMMAND_WATCHDOG_S, ArmCommand, EStop
from asibot.testing import Inbox, Stream, wait_until, release_counts_only_signed

from .conftest import R


def still(arm, seconds: float = 0.3) -> None:
    """The joints stay where they are, on the bus and in the drives, for `seconds`."""
    here = arm.states.last().positions
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        assert arm.states.last().positions == pytest.approx(here, abs=1e-6), "the arm moved"
        time.sleep(0.02)
    drives = arm.svc.emulator.positions()
    assert [drives[n] for n in range(1, 6)] == pytest.approx(here, abs=1e-6)


def events(arm, code: str) -> list:
    return [e for e in arm.events.all() if e.code == code]


def test_only_the_holders_commands_move_the_arm(arm):
    other = Bus("another-kinematics")
    try:
        second = ownership.announce(other, R, "arm", "kinematics")   # alive, but came second
        wait_until(lambda: second.id in arm.svc.holder.alive, 5)
        goal = [0.05, 0.0, 0.0, 0.0, 0.0]
        for controller in ("", "kinematics-deadbeef", second.id):     # anonymous, a stranger, the second
            arm.user.put_raw(keys.arm_command(R), messages.pack({"mode": "position", "values": goal,
                                                                "controller": controller}))
        wait_until(lambda: len(events(arm, "not_holder")) >= 1, 5, message="no not_holder event")
        still(arm)
        first = events(arm, "not_holder")[0]
        assert first.level == "error" and first.text.startswith("Arm command refused, the arm keeps its previous motion")
        assert f"controller {arm.controller.id!r} holds the arm of {R}" in first.text, first.text
        assert arm.svc.not_holder == 3 and arm.svc.health()["holder"] == arm.controller.id
        # The holder's id, read from its liveliness token, borrowed by another process.
        arm.user.put_raw(keys.arm_command(R), messages.pack({"mode": "position", "values": goal,
                                                            "controller": arm.controller.id}))
        wait_until(lambda: events(arm, "not_signed"), 5, message="no not_signed event")
        assert "it is not signed" in events(arm, "not_signed")[0].text
        # The holder's command moves it, once: the same command played again is refused.
        pub = arm.user.publisher(keys.arm_command(R), ArmCommand)
        signed = arm.controller.sign(ArmCommand(mode="position", values=goal))
        pub.put(signed)
        wait_until(lambda: abs(arm.states.last().positions[0] - goal[0]) < 1e-4, 5)
        pub.put(signed)
        wait_until(lambda: events(arm, "replayed"), 5, message="no replayed event")
        assert arm.svc.not_holder == 5
    finally:
        other.close()


def test_a_new_holder_moves_the_arm_only_on_a_stream_begun_after_it_took_over(arm):
    """The second controller streams (refused) while the first holds; the first vanishes: the
    second holds the arm now, and its stream from before moves nothing until it pauses."""
    other = Bus("second-kinematics")
    cmd = other.publisher(keys.arm_command(R), ArmCommand)
    second = ownership.announce(other, R, "arm", "kinematics")
    stream = Stream(lambda: second.put(cmd, ArmCommand(mode="velocity", values=[0.2, 0, 0, 0, 0])))
    try:
        wait_until(lambda: events(arm, "not_holder"), 5)
        arm.controller_bus.close()                                  # the first controller exits
        took_over = time.monotonic()
        wait_until(lambda: arm.svc.holder.current == second.id, 5)
        wait_until(lambda: any(second.id in e.text for e in events(arm, "ready")), 5, message="no ready event")
        still(arm, 0.6)
        assert stream.longest_gap(took_over) < COMMAND_WATCHDOG_S / 2, "the machine paused the stream itself"
        wait_until(lambda: events(arm, "not_ready"), 5, message="no not_ready event")
        assert "pause it for 200 ms (or restart it)" in events(arm, "not_ready")[0].text
        stream.pause()
        time.sleep(COMMAND_WATCHDOG_S)
        stream.resume()
        wait_until(lambda: arm.states.last().velocities[0] > 0.1, 5, message="the restarted stream did not move the arm")
    finally:
        stream.close()
        other.close()


def test_the_estop_outlives_whoever_engaged_it_and_its_release_says_who(arm):
    with Bus("asibot-estop") as button:                            # `asibot estop`: engages and exits
        button.latch(keys.estop(R), EStop(engaged=True, reason="test", by="ana@kitchen (asibot estop, pid 7)"))
        wait_until(lambda: events(arm, "estop"), 5)
    assert "by ana@kitchen (asibot estop, pid 7)" in events(arm, "estop")[0].text
    late = Bus("a-ui-started-later")
    try:
        learnt = Inbox()
        late.subscribe(keys.estop(R), EStop, learnt, latest=True)
        wait_until(lambda: len(learnt), 5, message="a late subscriber learnt nothing of the estop")
        assert learnt.last().engaged and learnt.last().by.startswith("ana@kitchen")
        assert late.call(keys.driver_rpc(R, "status"))["estop"] is True
        # Anyone can write a name; a release counts only signed, by the key it names.
        release_counts_only_signed(late, R, lambda code: events(arm, code), "bob@kitchen (asibot release, pid 8)")
        wait_until(lambda: events(arm, "ready"), 5)
    finally:
        late.close()
