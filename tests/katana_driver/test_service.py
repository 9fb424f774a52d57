"""The driver contract of the Katana service on the in-memory bus, against the emulated
Katana in the same process: motion, estop, watchdog, faults and refusals."""

from __future__ import annotations

import math

import pytest

from asibot import keys, robots
from asibot.errors import RpcError
from asibot.katana_driver import protocol as p
from asibot.katana_driver.katana import KATANA_300_6M180, gripper_counts
from asibot.messages import ArmCommand, EStop, GripperCommand
from asibot.testing import release, signed_raw, wait_until

from .conftest import R

SPEC = robots.get(R)
JOINTS = KATANA_300_6M180[:5]


def at(k, goal, tol=2e-3) -> bool:
    s = k.states.last()
    return all(abs(a - b) < tol for a, b in zip(s.positions, goal))


def counts_of(goal):
    return [m.to_counts(g) for m, g in zip(JOINTS, goal)]


def frozen(k) -> bool:
    """Every motor told to freeze (MCF_FREEZE), and standing at where it was told."""
    return all(f == p.MCF_FREEZE for f in k.emulator.flags()) and all(
        abs(c - t) < 1 for c, t in zip(k.emulator.counters(), k.emulator.targets()))


def send(k, cmd) -> None:
    pub = k.user.publisher(keys.arm_command(R), ArmCommand)
    k.controller.put(pub, cmd)


def test_a_movj_reaches_its_joint_targets_in_the_emulator(katana):
    k = katana
    start = k.states.last().positions
    goal = [s + d for s, d in zip(start, [0.4, -0.3, 0.3, 0.3, 0.4])]
    send(k, ArmCommand(mode="position", values=goal))
    wait_until(lambda: at(k, goal), 10, message=lambda: f"the arm stands at {k.states.last().positions}")
    assert k.states.last().mode == "position" and k.states.last().fault == ""
    counters = k.emulator.counters()[:5]
    assert counters == pytest.approx(counts_of(goal), abs=2)
    status = k.user.call(keys.driver_rpc(R, "status"))
    assert status["names"] == SPEC.joint_names and status["holders"]["arm"] == k.controller.id


def test_the_gripper_opens_to_its_command(katana):
    k = katana
    pub = k.user.publisher(keys.gripper_command(R), GripperCommand)
    k.controller.put(pub, GripperCommand(opening=0.02))
    goal = gripper_counts(0.02, SPEC.gripper_max_opening)
    # The state published lags the motor by a control period: wait for both to arrive.
    wait_until(lambda: abs(k.grippers.last().opening - 0.02) < 1e-3 and abs(k.emulator.counters()[5] - goal) <= 1, 10,
               message=lambda: f"the gripper is open {k.grippers.last().opening} m, {k.emulator.counters()[5]} counts")


def test_the_estop_stops_motion_and_holds_until_released(katana):
    k = katana
    start = k.states.last().positions
    goal = [SPEC.upper[0] - 0.01, *start[1:]]         # 5.8 rad away: 2.6 s at top speed
    send(k, ArmCommand(mode="position", values=goal))
    wait_until(lambda: abs(k.states.last().positions[0] - start[0]) > 0.1, 5, message="the arm never moved")
    k.user.latch(keys.estop(R), EStop(engaged=True, reason="test"))
    wait_until(lambda: "estop" in k.codes(), 5)
    # Stopped: every motor told to freeze where it stood, and it stands still.
    wait_until(lambda: frozen(k), 3, message="the motors did not stop")
    held = k.emulator.counters()
    send(k, ArmCommand(mode="position", values=goal))       # ignored during the estop
    n = len(k.states)
    wait_until(lambda: len(k.states) >= n + 10, 5)
    assert k.emulator.counters() == pytest.approx(held, abs=1)
    assert abs(k.states.last().positions[0] - goal[0]) > 0.1
    release(k.user, R)
    wait_until(lambda: "estop_released" in k.codes(), 5)


def test_the_watchdog_stops_a_velocity_stream_that_ceases(katana):
    k = katana
    start = k.states.last().positions
    send(k, ArmCommand(mode="velocity", values=[0.3, 0.0, 0.0, 0.0, 0.0]))
    wait_until(lambda: "watchdog" in k.codes(), 5, message="the watchdog never fired")
    assert k.texts("watchdog") == ["No velocity command for 200 ms: the arm stopped and holds its position."]
    wait_until(lambda: frozen(k), 3, message="the motors did not stop")
    stopped = k.emulator.counters()[0]
    n = len(k.states)
    wait_until(lambda: len(k.states) >= n + 10, 5)
    assert k.emulator.counters()[0] == pytest.approx(stopped, abs=1)
    moved = k.states.last().positions[0] - start[0]
    assert moved < 0.3           # stopped before a second's worth of the stream


def test_a_silent_controller_is_a_fault_with_a_sentence_and_reset_brings_it_back(katana):
    k = katana
    k.user.call(keys.driver_rpc(R, "inject_fault"), {"fault": "silent"})
    wait_until(lambda: k.states.last().mode == "fault", 5, message="no fault on arm/state")
    fault = k.states.last().fault
    assert fault.startswith("The Katana's controller stopped answering (the Katana did not answer command ")
    assert fault.endswith("check its power and the serial cable, then call reset_fault.")
    # the event comes on its own key: it may arrive a moment after the state
    wait_until(lambda: k.texts("silent"), 5, message=lambda: f"no event said so; events: {k.codes()}")
    assert k.texts("silent") == [fault]
    with pytest.raises(RpcError) as refused:
        k.user.call(keys.driver_rpc(R, "reset_fault"), timeout=5)
    assert refused.value.code == "fault" and "stopped answering" in str(refused.value)
    k.user.call(keys.driver_rpc(R, "inject_fault"), {"fault": "clear"})
    k.user.call(keys.driver_rpc(R, "reset_fault"), timeout=5)
    wait_until(lambda: k.states.last().mode == "idle" and k.states.last().fault == "", 5)
    assert "fault_reset" in k.codes()


def test_a_collision_is_a_fault_and_reset_clears_it(katana):
    k = katana
    k.user.call(keys.driver_rpc(R, "inject_fault"), {"fault": "collision", "joint": "katana_motor3_lift_joint"})
    wait_until(lambda: k.states.last().mode == "fault", 5)
    assert k.states.last().fault == ("Motor 3 (joint katana_motor3_lift_joint) reports a collision (status 40, "
                                     "MSF_MOTCRASHED): the arm was stopped and holds where it is; free it, then "
                                     "call reset_fault.")
    k.user.call(keys.driver_rpc(R, "reset_fault"), timeout=5)
    wait_until(lambda: k.states.last().mode == "idle", 5)
    assert k.emulator.motors[2].crashed is False


@pytest.mark.parametrize("payload, says", [
    ({"mode": "position", "values": [0.0, 2.3, 0.0, 0.0, 0.0]},
     "joint katana_motor2_lift_joint position 2.3 rad is beyond its upper limit 2.17 rad"),
    ({"mode": "position", "values": [-3.1, 1.0, 0.0, 0.0, 0.0]},
     "joint katana_motor1_pan_joint position -3.1 rad is beyond its lower limit -3.03 rad"),
    ({"mode": "velocity", "values": [0.0, 0.0, 0.0, 0.0, 3.0]},
     "joint katana_motor5_wrist_roll_joint velocity 3 rad/s is beyond its max speed 2.21 rad/s"),
    ({"mode": "torque", "values": [0.0] * 5}, "must be 'position' or 'velocity', got 'torque'"),
    ({"mode": "position", "values": [0.0] * 3}, "the Katana has 5 joints"),
    ({"mode": "position", "values": [math.nan, 1.0, 0.0, 0.0, 0.0]}, "not finite"),
    # The message refuses it before the driver's limits (tests/common/test_joint_reference.py) would.
    ({"mode": "position", "values": [0.0, 1.0, 0.0, 0.0, 0.0], "velocities": [0.0, 0.0, 0.0, 0.0, math.nan]},
     "ArmCommand.velocities: contains a value that is not finite"),
])
def test_bad_input_is_refused_with_a_sentence_and_changes_nothing(katana, payload, says):
    k = katana
    before, targets = k.states.last().positions, k.emulator.targets()
    k.user.put_raw(keys.arm_command(R), signed_raw(k.controller, ArmCommand, payload))
    wait_until(lambda: k.texts("bad_command"), 5, message="no bad_command event")
    text = k.texts("bad_command")[0]
    assert text.startswith("Arm command refused, the arm keeps its previous motion: ") and says in text
    n = len(k.states)
    wait_until(lambda: len(k.states) >= n + 5, 5)
    assert k.states.last().positions == pytest.approx(before, abs=1e-9)
    assert k.states.last().mode == "idle"
    assert k.emulator.targets() == targets


def test_a_gripper_opening_beyond_its_range_is_refused(katana):
    k = katana
    pub = k.user.publisher(keys.gripper_command(R), GripperCommand)
    targets = k.emulator.targets()
    k.controller.put(pub, GripperCommand(opening=0.5))
    wait_until(lambda: k.texts("bad_command"), 5)
    assert "gripper opening 0.5 m is outside 0..0.07 m" in k.texts("bad_command")[0]
    assert k.emulator.targets() == targets


def test_the_driver_refuses_an_unknown_mode_itself(katana):
    """What the message check lets through (a driver called directly) is refused the same way."""
    targets = katana.emulator.targets()
    with pytest.raises(ValueError, match="mode must be 'position' or 'velocity', got 'torque'"):
        katana.svc.driver.command("torque", [0.0] * 5)
    assert katana.emulator.targets() == targets


def test_build_says_what_is_missing(memory_bus):
    import argparse

    from asibot.bus import Bus
    from asibot.katana_driver import service

    parser = argparse.ArgumentParser()
    service.add_arguments(parser)
    bus = Bus("katana_driver")
    try:
        args = parser.parse_args([])
        args.robot, args.instance = None, "main"
        with pytest.raises(ValueError, match="no serial port: pass --serial /dev/ttyUSB0"):
            service.build(bus, args)
        args = parser.parse_args(["--serial", "emulated"])
        args.robot, args.instance = "asibot", "main"
        with pytest.raises(ValueError, match="robot 'asibot' has no Katana arm"):
            service.build(bus, args)
        args = parser.parse_args(["--serial", "/dev/no-such-katana"])
        args.robot, args.instance = "pioneer", "main"
        with pytest.raises(ValueError, match="cannot open the Katana's serial port /dev/no-such-katana"):
            service.build(bus, args)
    finally:
        bus.close()


@pytest.mark.slow
def test_the_estop_interrupts_calibration_and_reset_fault_calibrates_again(memory_bus):
    from asibot.bus import Bus
    from asibot.katana_driver.emulator import KatanaEmulator
    from asibot.katana_driver.service import KatanaDriverService
    from asibot.messages import ArmState, Event
    from asibot.testing import Inbox

    near = [m.position_after + (400 if m.search_positive else -400) for m in KATANA_300_6M180]
    emu = KatanaEmulator(near, calibrated=False)
    svc_bus, user = Bus("katana_driver"), Bus("test")
    states, events = Inbox(), Inbox()
    user.subscribe(keys.arm_state(R), ArmState, states)
    user.subscribe(keys.events(R), Event, events)
    svc = KatanaDriverService(svc_bus, R, "emulated", emulator=emu)
    try:
        wait_until(lambda: emu.requests >= 15, 10, message="the calibration never began")   # searching
        user.latch(keys.estop(R), EStop(engaged=True, reason="test"))
        wait_until(lambda: any(e.code == "startup" for e in events.all()), 5, message="no startup fault")
        text = next(e.text for e in events.all() if e.code == "startup")
        assert text.startswith("The Katana's calibration was interrupted by the emergency stop")
        assert svc.driver.status()["mode"] == "fault"
        wait_until(lambda: emu.still() and all(abs(c - t) < 1 or f == p.MCF_OFF
                                               for c, t, f in zip(emu.counters(), emu.targets(), emu.flags())), 3,
                   message="a motor kept moving")
        with pytest.raises(RpcError, match="interrupted by the emergency stop"):
            user.call(keys.driver_rpc(R, "reset_fault"), timeout=15)
        release(user, R)
        wait_until(lambda: any(e.code == "estop_released" for e in events.all()), 5)
        user.call(keys.driver_rpc(R, "reset_fault"), timeout=15)
        wait_until(lambda: len(states) and states.last().mode == "idle", 5)
        assert emu.counters() == pytest.approx([m.position_after for m in KATANA_300_6M180], abs=100)
        assert [m.shift for m in emu.motors] == pytest.approx([0.0] * 6, abs=1)
    finally:
        user.close()
        svc.close()
        svc_bus.close()
