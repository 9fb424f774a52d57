"""The driver contract over Zenoh: `python -m asibot.arm_driver --can emulated` in its own process."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import pytest

from asibot import keys
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.messages import ArmCommand, ArmState, EStop, Event
from asibot.testing import wait_until, release, signed_raw

R = "asibot"


@pytest.fixture
def driver_process(router):
    proc = subprocess.Popen([sys.executable, "-m", "asibot.arm_driver", "--robot", R, "--can", "emulated"],
                            env={**os.environ, "ASIBOT_ROUTER": router})
    bus = Bus("arm-test", router, wait=5)
    yield proc, bus
    bus.close()
    proc.terminate()
    assert proc.wait(5) == 0


@pytest.mark.slow
def test_driver_contract_end_to_end(driver_process):
    proc, bus = driver_process
    states, events = [], []
    bus.subscribe(keys.arm_state(R), ArmState, states.append)
    bus.subscribe(keys.events(R), Event, events.append)
    assert bus.wait_for(keys.driver_rpc(R, "status"), 15)
    wait_until(lambda: states and states[-1].mode == "idle", 15)
    assert bus.alive(keys.driver_alive(R)) == [keys.driver_alive(R)]

    status = bus.call(keys.driver_rpc(R, "status"))
    assert status["names"] == ["q1", "q2", "q3", "q4", "q5"] and status["fault"] == ""

    # arm/state streams at 100 Hz: 25 more come (within 5 s, for a busy machine)
    n = len(states)
    wait_until(lambda: len(states) - n >= 25, 5, message=lambda: f"{len(states) - n} states")

    # Positions through Zenoh -> CAN -> emulated drives -> TPDO -> arm/state, from the
    # controller that holds the arm (asibot.safety.ownership).
    controller = Bus("fake-controller", wait=5)
    c = ownership.announce(controller, R, "arm", "test")
    wait_until(lambda: bus.call(keys.driver_rpc(R, "status"))["holders"]["arm"] == c.id, 5)
    cmd = bus.publisher(keys.arm_command(R), ArmCommand)
    assert cmd.wait_for_subscribers(5)
    goal = [0.03, -0.02, 0.01, 0.0, 0.02]
    c.put(cmd, ArmCommand(mode="position", values=goal))
    wait_until(lambda: all(abs(p - g) < 1e-4 for p, g in zip(states[-1].positions, goal)), 5)

    # A command with the wrong number of joints, or a NaN, is rejected with an Event.
    c.put(cmd, ArmCommand(mode="position", values=[0.5, 0.5]))
    bus.put_raw(keys.arm_command(R), signed_raw(c, ArmCommand, {"mode": "position", "values": [math.nan, 0, 0, 0, 0]}))
    wait_until(lambda: sum(e.code == "bad_command" for e in events) >= 2, 10)
    time.sleep(0.1)
    assert all(abs(p - g) < 1e-4 for p, g in zip(states[-1].positions, goal))

    # Estop (latched) holds and ignores commands; released, commands work again.
    bus.latch(keys.estop(R), EStop(engaged=True, reason="test"))
    wait_until(lambda: any(e.code == "estop" for e in events), 10)
    c.put(cmd, ArmCommand(mode="position", values=[0.2] * 5))
    time.sleep(0.2)
    assert all(abs(p - g) < 1e-4 for p, g in zip(states[-1].positions, goal))
    release(bus, R)
    wait_until(lambda: any(e.code == "estop_released" for e in events), 10)

    # Over-current through the emulated bus: fault on arm/state and an Event; reset by RPC.
    bus.call(keys.driver_rpc(R, "inject_fault"), {"fault": "over_current", "joint": "q2"})
    wait_until(lambda: states[-1].mode == "fault", 10)
    assert states[-1].fault.startswith("Drive 2 (joint q2) reports continuous over-current")
    wait_until(lambda: any(e.code == "emcy_2310" and e.level == "error" for e in events), 10)
    with pytest.raises(RpcError) as refused:
        bus.call(keys.driver_rpc(R, "inject_fault"), {"fault": "meteor", "joint": "q2"})
    assert refused.value.code == "bad_request"
    assert bus.call(keys.driver_rpc(R, "reset_fault"), timeout=10)["ok"]
    wait_until(lambda: states[-1].mode == "idle", 10)

    # q3 switched off and on while its absolute encoder is unplugged: a fault, and no reset
    # until the encoder answers again; then q3 knows where it stands although it restarted.
    here = states[-1].positions[2]
    with pytest.raises(RpcError, match="q1 has no absolute encoder; these do: q2, q3, q4"):
        bus.call(keys.driver_rpc(R, "inject_fault"), {"fault": "encoder_silent", "joint": "q1"})
    bus.call(keys.driver_rpc(R, "inject_fault"), {"fault": "encoder_silent", "joint": "q3"})
    bus.call(keys.driver_rpc(R, "inject_fault"), {"fault": "power_cycle", "joint": "q3"})
    wait_until(lambda: states[-1].mode == "fault", 10)
    assert "Drive 3 (joint q3) restarted" in states[-1].fault
    with pytest.raises(RpcError, match=r"The absolute encoder of joint q3 \(CAN id 103\) gave no position"):
        bus.call(keys.driver_rpc(R, "reset_fault"), timeout=10)
    bus.call(keys.driver_rpc(R, "inject_fault"), {"fault": "clear"})
    assert bus.call(keys.driver_rpc(R, "reset_fault"), timeout=10)["ok"]
    wait_until(lambda: states[-1].mode == "idle", 10)
    assert states[-1].positions[2] == pytest.approx(here, abs=math.radians(360 / 4096))

    # The controller's liveliness vanishing mid-motion stops the arm.
    c.put(cmd, ArmCommand(mode="position", values=[1.0, 0, 0, 0, 0]))
    wait_until(lambda: states[-1].velocities[0] > 0.1, 10)
    controller.close()
    wait_until(lambda: any(e.code == "controller_lost" for e in events), 10)
    wait_until(lambda: abs(states[-1].velocities[0]) < 1e-6, 10)
    assert states[-1].positions[0] < 0.5


def test_without_a_can_bus_the_service_says_what_to_pass(router):
    env = {k: v for k, v in os.environ.items() if k != "ASIBOT_ARM_CAN"}
    proc = subprocess.run([sys.executable, "-m", "asibot.arm_driver", "--robot", R, "--router", router],
                          env=env, capture_output=True, text=True, timeout=30)
    assert proc.returncode == 1
    assert "pass --can socketcan:can0" in proc.stderr
