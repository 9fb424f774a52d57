"""The sim as a separate process on a real router: it speaks the driver contract."""

import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from asibot import keys
from asibot.safety import ownership
from asibot import messages as m
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.testing import wait_until, signed_raw

ROBOT = "pioneer-sim"


class Inbox:
    """Keeps every message received on a key, thread-safely."""

    def __init__(self) -> None:
        self.items: list = []
        self.lock = threading.Lock()

    def __call__(self, msg) -> None:
        with self.lock:
            self.items.append((time.monotonic(), msg))

    def last(self):
        with self.lock:
            return self.items[-1][1] if self.items else None

    def since(self, t0: float) -> list:
        with self.lock:
            return [msg for t, msg in self.items if t >= t0]


@pytest.fixture
def sim_process(router):
    env = dict(os.environ, MUJOCO_GL="osmesa")
    proc = subprocess.Popen([sys.executable, "-m", "asibot.sim", "--robot", ROBOT, "--camera-size", "80x60",
                             "--odom-noise", "0,0", "--log-level", "warning"], env=env)
    yield proc
    proc.terminate()
    try:
        assert proc.wait(timeout=5) == 0, "the sim should stop cleanly on SIGTERM"
    except subprocess.TimeoutExpired:
        proc.kill()
        raise


@pytest.mark.slow
def test_the_sim_process_speaks_the_driver_contract(sim_process):
    with Bus("test-sim") as bus:
        wait_until(lambda: bus.alive(keys.driver_alive(ROBOT)), timeout=30, message="the sim never came up")
        arm, odom, events, depth, info = Inbox(), Inbox(), Inbox(), Inbox(), Inbox()
        bus.subscribe(keys.arm_state(ROBOT), m.ArmState, arm)
        bus.subscribe(keys.base_odom(ROBOT), m.Odometry, odom)
        bus.subscribe(keys.events(ROBOT), m.Event, events)
        bus.subscribe(keys.camera_depth(ROBOT, "front"), m.DepthImage, depth)
        bus.subscribe(keys.camera_info(ROBOT, "front"), m.CameraInfo, info)
        wait_until(lambda: arm.last() is not None and depth.last() is not None, timeout=10)
        # The test holds the arm and the base (asibot.safety.ownership).
        arm_ctl, base_ctl = (ownership.announce(bus, ROBOT, part, "test") for part in ("arm", "base"))
        wait_until(lambda: bus.call(keys.driver_rpc(ROBOT, "status"), {})["holders"]["arm"] == arm_ctl.id, timeout=5)
        t1 = time.monotonic()
        time.sleep(1.0)
        assert len(arm.since(t1)) >= 50   # >= 50 Hz by contract; 100 Hz nominal
        assert depth.last().depth.shape == (60, 80) and info.last().width == 80

        status = bus.call(keys.driver_rpc(ROBOT, "status"), {})
        assert status["names"] == arm.last().names and len(status["lower"]) == 5

        # a position command is tracked
        goal = (np.array(status["upper"]) * 0 + np.array(arm.last().positions)).tolist()
        goal[0] += 0.2
        arm_ctl.put(bus.publisher(keys.arm_command(ROBOT), m.ArmCommand), m.ArmCommand(mode="position", values=goal))
        wait_until(lambda: abs(arm.last().positions[0] - goal[0]) < 0.01, timeout=10)

        # a malformed command is refused with an error event and moves nothing
        bus.put_raw(keys.arm_command(ROBOT), signed_raw(arm_ctl, m.ArmCommand, {"mode": "position", "values": [1.0, 2.0]}))
        wait_until(lambda: any(e.code == "bad_command" for e in events.since(0)), timeout=5)

        # a huge position is refused, not clipped: an event names the joint, the value and the
        # limit, and the arm keeps its previous goal
        wait_until(lambda: abs(arm.last().positions[0] - goal[0]) < 1e-3
                   and max(map(abs, arm.last().velocities)) < 1e-3, timeout=10)
        here = goal
        bus.put_raw(keys.arm_command(ROBOT), signed_raw(arm_ctl, m.ArmCommand, {"mode": "position", "values": [1e300] * 5}))
        wait_until(lambda: any("position 1e+300 rad is beyond its upper limit" in e.text
                               for e in events.since(0)), timeout=5)
        t2 = time.monotonic()
        wait_until(lambda: len(arm.since(t2)) >= 30, timeout=5)
        dev = max(float(np.max(np.abs(np.subtract(s.positions, here)))) for s in arm.since(t2))
        assert dev < 2e-3, (dev, here, arm.since(t2)[-1].positions)

        # the base drives, then the latched estop stops it and it ignores further commands
        drive = bus.publisher(keys.base_cmd_vel(ROBOT), m.Twist)
        for _ in range(25):
            base_ctl.put(drive, m.Twist(vx=0.3, wz=0.0))
            time.sleep(0.02)
        wait_until(lambda: odom.last().x > 0.05, timeout=5)
        bus.latch(keys.estop(ROBOT), m.EStop(engaged=True, reason="test"))
        wait_until(lambda: any(e.code == "estop" for e in events.since(0)), timeout=5)
        time.sleep(0.3)
        x_stopped = odom.last().x
        for _ in range(25):
            base_ctl.put(drive, m.Twist(vx=0.3, wz=0.0))
            time.sleep(0.02)
        time.sleep(0.3)
        assert odom.last().x == pytest.approx(x_stopped, abs=1e-3)

        with pytest.raises(RpcError) as err:
            bus.call(keys.driver_rpc(ROBOT, "set_object_pose"), {"name": "unicorn", "pos": [0, 0, 1]})
        assert err.value.code == "bad_request" and "no object" in err.value.message
