"""`asibot estop`, `asibot release` and `asibot reset-fault`: a user-facing stop that works from
any terminal, whoever moved the robot, with the driver's word that it holds."""

import subprocess
import sys
import threading

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.errors import RpcError


def asibot(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "asibot.cli.main", *argv], capture_output=True, text=True, timeout=60)


class Driver:
    """A robot's driver as the CLI sees it: latched estop in, status and reset_fault out."""

    def __init__(self, robot: str, fault: str = "") -> None:
        self.robot, self.fault, self.estop = robot, fault, False
        self.reasons: list[str] = []
        self.lock = threading.Lock()
        self.bus = Bus(f"driver-{robot}")
        self.bus.subscribe(keys.estop(robot), m.EStop, self.on_estop, latest=True)
        self.bus.serve(keys.driver_rpc(robot, "status"), lambda req: {"estop": self.estop})
        self.bus.serve(keys.driver_rpc(robot, "reset_fault"), self.reset_fault)
        self.bus.announce(keys.driver_alive(robot))

    def on_estop(self, msg: m.EStop) -> None:
        with self.lock:
            self.estop = msg.engaged
            self.reasons.append(msg.reason)

    def reset_fault(self, req: dict) -> dict:
        if self.fault:
            raise RpcError("fault", f"Drive 3 still reports {self.fault}.")
        return {"reinitialised": ["q3"]}


def test_estop_stops_every_live_robot_and_release_needs_a_robot(router):
    a, b = Driver("arm-1"), Driver("base-1")
    try:
        r = asibot("estop")
        assert r.returncode == 0, r.stderr
        assert a.estop and b.estop
        assert "arm-1: stopped" in r.stdout and "base-1: stopped" in r.stdout
        assert a.reasons[-1].startswith("asibot estop by ")
        assert asibot("release").returncode == 2  # which robot: releasing is deliberate
        r = asibot("release", "arm-1")
        assert r.returncode == 0 and "released" in r.stdout
        assert not a.estop and b.estop
    finally:
        a.bus.close()
        b.bus.close()


def test_estop_with_no_live_robot_says_so(router):
    r = asibot("estop")
    assert r.returncode == 1 and "nothing to stop" in r.stderr


def test_reset_fault_passes_the_driver_sentence(router):
    ok, stuck = Driver("arm-2"), Driver("arm-3", fault="over-current")
    try:
        r = asibot("reset-fault", "arm-2")
        assert r.returncode == 0 and "fault cleared" in r.stdout and "q3" in r.stdout
        r = asibot("reset-fault", "arm-3")
        assert r.returncode == 2 and "over-current" in r.stderr
        r = asibot("reset-fault", "nobody")
        assert r.returncode == 2 and "Nobody answers" in r.stderr
    finally:
        ok.bus.close()
        stuck.bus.close()


def test_reset_world_reaches_the_simulated_robot(router):
    calls = []
    with Bus("sim") as sim:
        sim.serve(keys.driver_rpc("sim-9", "reset_world"), lambda req: calls.append(req) or {})
        r = asibot("reset-world", "sim-9")
        assert r.returncode == 0 and "world reset" in r.stdout and calls == [{}]
