"""The bridge end to end: `asibot up` with the apartment sim, perception, nav, the Pioneer's
kinematics and the bridge; a NetConnection client, a text client and an HTTP client drive the
Pioneer and its arm, judged by the sim's ground truth and the gripper's own state."""

from __future__ import annotations

import http.client
import json
import math
import threading
from pathlib import Path

import pytest

from asibot import keys
from asibot import messages as m
from asibot.testing import Stack, free_port, wait_until

from asibot.asterics_bridge import netconnection as nc

from .harness import Client, command, say

ROOT = Path(__file__).resolve().parents[2]
ROBOT = "pioneer-sim"

pytestmark = pytest.mark.slow


class Truth:
    def __init__(self, bus) -> None:
        self._lock = threading.Lock()
        self.last: tuple[float, float, float] | None = None
        bus.subscribe(keys.sim_truth(ROBOT), m.Pose2D, self._on)

    def _on(self, p: m.Pose2D) -> None:
        with self._lock:
            self.last = (p.x, p.y, p.theta)

    def pose(self) -> tuple[float, float, float]:
        wait_until(lambda: self.last is not None, 10, message="no ground truth from the sim")
        with self._lock:
            return self.last


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    tcp, http_port = free_port(), free_port()
    mp.setenv("ASIBOT_ASTERICS_PORT", str(tcp))          # `asibot up` passes them on to the bridge
    mp.setenv("ASIBOT_ASTERICS_HTTP_PORT", str(http_port))
    folder = tmp_path_factory.mktemp("asterics")
    s = Stack(folder, "sim", ["asterics-bridge", "nav-pioneer-sim", "kinematics-pioneer-sim"], ROOT / "compose.yaml")
    s.tcp_port, s.http_port = tcp, http_port
    try:
        s.wait_alive("sim/pioneer-sim", "nav/pioneer-sim", "kinematics/pioneer-sim", "asterics_bridge/pioneer-sim",
                     timeout=120)
        s.truth = Truth(s.bus)
        # the HTTP port's token, made by the bridge in the stack's data folder (http_token)
        s.token = (s.data / "asterics" / "token").read_text().strip()
        wait_until(lambda: s.bus.call(keys.nav_rpc(ROBOT, "status"), timeout=5)["localised"], 30, interval=0.2,
                   message="nav never localised")
        yield s
    finally:
        s.stop()
        mp.undo()


def moved(a, b) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def post(stack, text: str) -> tuple[int, str]:
    conn = http.client.HTTPConnection("127.0.0.1", stack.http_port, timeout=30)
    try:
        conn.request("POST", "/command", body=text, headers={"Content-Type": "text/plain",
                                                             "Authorization": f"Bearer {stack.token}"})
        r = conn.getresponse()
        return r.status, r.read().decode()
    finally:
        conn.close()


def still(stack) -> bool:
    """Neither driving nor turning: two ground-truth samples a moment apart."""
    a = stack.truth.pose()
    wait_until(lambda: stack.truth.pose() != a, 2)   # a newer sample
    b = stack.truth.pose()
    return moved(a, b) < 0.003 and abs(math.remainder(b[2] - a[2], 2 * math.pi)) < 0.002


def test_netconnection_forward_then_stop_moves_the_pioneer(stack):
    c = Client(stack.tcp_port)
    try:
        start = stack.truth.pose()
        assert command(c, "forward").startswith("ok: forward")
        wait_until(lambda: moved(start, stack.truth.pose()) > 0.2, 15, message="forward did not move the Pioneer")
        assert command(c, "stop").startswith("ok: stopped")
        wait_until(lambda: still(stack), 5, message="stop did not stop the Pioneer")
    finally:
        c.close()


#: A place of the user's, a short drive from the start (the trips to the fridge are nav's own tests).
SOFA = "by the sofa"
SOFA_POSE = [2.4, 1.1, 0.0]
#: Another, a metre back towards the charging station (parked at the station itself, facing its
#: wall, the robot takes long to turn away).
HALL, HALL_POSE = "in the hall", [1.3, 1.0, 0.0]


@pytest.mark.timeout(300)
def test_goto_a_place_arrives_and_goal_reached_comes_back_as_a_frame(stack):
    stack.bus.call(keys.nav_rpc(ROBOT, "save_place"), {"name": SOFA, "pose": SOFA_POSE, "replace": True}, timeout=5)
    c = Client(stack.tcp_port)
    try:
        assert command(c, f"goto {SOFA}", timeout=15).startswith("ok")
        wait_until(lambda: "goal reached" in c.strings(1), 120, interval=0.5,
                   message=lambda: f"no 'goal reached' frame; got {c.strings(1)}")
        assert moved(stack.truth.pose(), SOFA_POSE) < 0.3
        assert nc.encode_string(1, "goal reached") in c.bytes()
    finally:
        c.close()


def test_grab_closes_the_gripper(stack):
    c = Client(stack.tcp_port)
    grip = []
    stack.bus.subscribe(keys.gripper_state(ROBOT), m.GripperState, grip.append)
    try:
        assert command(c, "release", timeout=15).startswith("ok")
        assert command(c, "grab", timeout=15).startswith("ok")
        wait_until(lambda: grip and grip[-1].opening < 0.01, 10, message="the gripper did not close")
    finally:
        c.close()


def http_status(stack) -> dict:
    conn = http.client.HTTPConnection("127.0.0.1", stack.http_port, timeout=10)
    try:
        conn.request("GET", "/status", headers={"Authorization": f"Bearer {stack.token}"})
        return json.loads(conn.getresponse().read())
    finally:
        conn.close()


@pytest.mark.timeout(400)
def test_an_http_client_and_a_text_client_send_it_places_and_hear_goal_reached(stack):
    """A curl-style POST sends it to one place of the user's, then a netcat-style line to
    another; each hears it arrived (/status's state and text; a line). Short trips: the long
    ones across the home are nav's own tests (tests/e2e/test_nav_sim.py)."""
    for name, pose in ((HALL, HALL_POSE), (SOFA, SOFA_POSE)):
        stack.bus.call(keys.nav_rpc(ROBOT, "save_place"), {"name": name, "pose": pose, "replace": True}, timeout=5)
    status, body = post(stack, f"goto {HALL}")
    assert status == 200 and body.startswith("ok"), body
    wait_until(lambda: http_status(stack)["moving"], 15, interval=0.2, message="the POST did not start a trip")
    # The goal's state, not the last event: parked facing the wall, perception's "obstacle
    # ahead" (info) may follow "goal reached" within a scan, and be the last event then.
    wait_until(lambda: (lambda st: st["state"] == "succeeded" and st["place"] == HALL
                        and "arrived" in st["text"])(http_status(stack)), 120, interval=0.5,
               message=lambda: f"/status never said it arrived: {http_status(stack)}")
    assert moved(stack.truth.pose(), HALL_POSE) < 0.3
    st = http_status(stack)
    assert st["robot"] == ROBOT and st["pose"] is not None and st["place"] == HALL
    t = Client(stack.tcp_port)
    try:
        assert say(t, f"goto {SOFA}", timeout=15).startswith("ok")
        wait_until(lambda: any("goal reached" in ln for ln in t.lines()), 120, interval=0.5,
                   message=lambda: f"no 'goal reached' line; got {t.lines()}")
        assert moved(stack.truth.pose(), SOFA_POSE) < 0.3
    finally:
        t.close()


def test_a_client_that_disconnects_mid_motion_stops_the_pioneer(stack):
    c = Client(stack.tcp_port)
    start = stack.truth.pose()
    assert command(c, "turn left").startswith("ok")
    wait_until(lambda: abs(math.remainder(stack.truth.pose()[2] - start[2], 2 * math.pi)) > 0.2, 15)
    c.close()
    wait_until(lambda: still(stack), 5, message="the Pioneer kept turning after its client left")
